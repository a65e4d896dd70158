//! `--vary NAME=SPEC`: the parameters of a sweep, their value sets, and how samples are drawn.
//!
//! ```text
//! SPEC  := LO..HI          every value in [LO, HI] (integer parameters: every integer)
//!        | LO..HI/COUNT    COUNT evenly spaced values from LO to HI, both included (COUNT >= 2)
//!        | V1,V2,...       the listed values (numbers, or words for `graph`)
//!        | V               one value
//! ```
//!
//! Monte Carlo (`--samples K --seed S`) draws every parameter of sample k independently and
//! uniformly from its set, from a generator seeded with (S, k) only: sample k is the same whatever
//! the number of jobs or samples. A grid (`--grid`) takes the Cartesian product of the sets in the
//! order the `--vary` options are given (the first varies slowest); every set must be finite there.

use formation_runtime::rng::SplitMix64;

/// One value of a parameter.
#[derive(Debug, Clone, PartialEq)]
pub enum Value {
    /// A number.
    Num(f64),
    /// A word (`graph=ring,path`).
    Word(String),
}

impl std::fmt::Display for Value {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Value::Num(x) => write!(f, "{x}"),
            Value::Word(w) => f.write_str(w),
        }
    }
}

impl Value {
    /// The number, or an error naming the parameter.
    pub fn num(&self, name: &str) -> Result<f64, SpecError> {
        match self {
            Value::Num(x) => Ok(*x),
            Value::Word(w) => Err(SpecError::NotANumber {
                name: name.to_string(),
                word: w.clone(),
            }),
        }
    }
}

/// Why a `--vary NAME=SPEC` (or a value drawn from it) is refused: the parameter and what failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SpecError {
    /// A word where the parameter takes a number.
    #[error("{name}={word}: expected a number")]
    NotANumber {
        /// The parameter.
        name: String,
        /// The word given.
        word: String,
    },
    /// No `=`, or nothing on one side of it.
    #[error("--vary '{arg}': expected NAME=SPEC{}", if *.example { ", e.g. delay.max=0..0.05" } else { "" })]
    Form {
        /// The option as given.
        arg: String,
        /// Whether the message shows an example (when there is no `=` at all).
        example: bool,
    },
    /// A bound or value that does not parse as a number.
    #[error("--vary {name}: '{text}' is not a number")]
    Number {
        /// The parameter.
        name: String,
        /// The text refused.
        text: String,
    },
    /// A bound or value that is infinite or NaN.
    #[error("--vary {name}: '{text}' is not finite")]
    NotFinite {
        /// The parameter.
        name: String,
        /// The text refused.
        text: String,
    },
    /// The COUNT after `/` is not a whole number.
    #[error("--vary {name}: count '{count}' after '/' is not a whole number")]
    Count {
        /// The parameter.
        name: String,
        /// The text refused.
        count: String,
    },
    /// A COUNT below 2.
    #[error("--vary {name}: a count needs at least 2 values")]
    CountTooSmall {
        /// The parameter.
        name: String,
    },
    /// LO > HI.
    #[error("--vary {name}: {lo}..{hi} is empty (LO > HI)")]
    Empty {
        /// The parameter.
        name: String,
        /// LO.
        lo: f64,
        /// HI.
        hi: f64,
    },
    /// A fractional value of a whole-number parameter.
    #[error("--vary {name}: takes whole numbers, got {got}")]
    NotWhole {
        /// The parameter.
        name: String,
        /// The spec or value refused.
        got: String,
    },
    /// An empty entry of a list.
    #[error("--vary {name}: empty value in '{spec}'")]
    EmptyValue {
        /// The parameter.
        name: String,
        /// The spec.
        spec: String,
    },
    /// A continuous range in a grid.
    #[error("--grid: {0} is a continuous range; give a count (LO..HI/COUNT) or a list")]
    Continuous(String),
}

/// The set of values of one parameter.
#[derive(Debug, Clone, PartialEq)]
pub enum Set {
    /// Every value in [lo, hi].
    Range(f64, f64),
    /// Every integer in [lo, hi].
    IntRange(i64, i64),
    /// A finite list.
    List(Vec<Value>),
}

/// One `--vary` option.
#[derive(Debug, Clone, PartialEq)]
pub struct Vary {
    /// Parameter name (see [`super::apply`]).
    pub name: String,
    /// Its values.
    pub set: Set,
}

fn number(name: &str, s: &str) -> Result<f64, SpecError> {
    let (name, text) = (name.to_string(), s.to_string());
    let x: f64 = match s.trim().parse() {
        Ok(x) => x,
        Err(_) => return Err(SpecError::Number { name, text }),
    };
    if !x.is_finite() {
        return Err(SpecError::NotFinite { name, text });
    }
    Ok(x)
}

/// Parses one `NAME=SPEC`; `integer` says whether the parameter takes integers only.
pub fn parse(arg: &str, integer: impl Fn(&str) -> bool) -> Result<Vary, SpecError> {
    let form = |example| SpecError::Form {
        arg: arg.to_string(),
        example,
    };
    let (name, spec) = arg.split_once('=').ok_or_else(|| form(true))?;
    let (name, spec) = (name.trim().to_string(), spec.trim());
    if name.is_empty() || spec.is_empty() {
        return Err(form(false));
    }
    let set = parse_set(&name, spec, integer(&name))?;
    Ok(Vary { name, set })
}

/// The set of `SPEC` for parameter `name`; `int` when it takes whole numbers only.
fn parse_set(name: &str, spec: &str, int: bool) -> Result<Set, SpecError> {
    let named = || name.to_string();
    Ok(if let Some((lo, rest)) = spec.split_once("..") {
        let (hi, count) = match rest.split_once('/') {
            Some((h, c)) => {
                let c: usize = c.trim().parse().map_err(|_| SpecError::Count {
                    name: named(),
                    count: c.to_string(),
                })?;
                if c < 2 {
                    return Err(SpecError::CountTooSmall { name: named() });
                }
                (h, Some(c))
            }
            None => (rest, None),
        };
        let (lo, hi) = (number(name, lo)?, number(name, hi)?);
        if lo > hi {
            return Err(SpecError::Empty {
                name: named(),
                lo,
                hi,
            });
        }
        if int && (lo.fract() != 0.0 || hi.fract() != 0.0) {
            return Err(SpecError::NotWhole {
                name: named(),
                got: spec.to_string(),
            });
        }
        match (count, int) {
            (Some(c), _) => {
                let vals: Vec<Value> = (0..c)
                    .map(|k| lo + (hi - lo) * k as f64 / (c - 1) as f64)
                    .map(|x| Value::Num(if int { x.round() } else { x }))
                    .collect();
                Set::List(vals)
            }
            (None, true) => Set::IntRange(lo as i64, hi as i64),
            (None, false) => Set::Range(lo, hi),
        }
    } else {
        let vals = spec
            .split(',')
            .map(|v| {
                let v = v.trim();
                match v.parse::<f64>() {
                    Ok(x) if x.is_finite() => {
                        if int && x.fract() != 0.0 {
                            Err(SpecError::NotWhole {
                                name: named(),
                                got: v.to_string(),
                            })
                        } else {
                            Ok(Value::Num(x))
                        }
                    }
                    Ok(_) => Err(SpecError::NotFinite {
                        name: named(),
                        text: v.to_string(),
                    }),
                    Err(_) if v.is_empty() => Err(SpecError::EmptyValue {
                        name: named(),
                        spec: spec.to_string(),
                    }),
                    Err(_) => Ok(Value::Word(v.to_string())),
                }
            })
            .collect::<Result<Vec<_>, _>>()?;
        Set::List(vals)
    })
}

impl Set {
    /// A uniform draw.
    pub fn draw(&self, rng: &mut SplitMix64) -> Value {
        match self {
            Set::Range(lo, hi) => Value::Num(lo + (hi - lo) * rng.unit()),
            Set::IntRange(lo, hi) => {
                Value::Num((lo + rng.below((hi - lo + 1) as usize) as i64) as f64)
            }
            Set::List(v) => v[rng.below(v.len())].clone(),
        }
    }

    /// Every value, when the set is finite.
    pub fn values(&self) -> Option<Vec<Value>> {
        match self {
            Set::Range(lo, hi) if lo == hi => Some(vec![Value::Num(*lo)]),
            Set::Range(..) => None,
            Set::IntRange(lo, hi) => Some((*lo..=*hi).map(|x| Value::Num(x as f64)).collect()),
            Set::List(v) => Some(v.clone()),
        }
    }
}

/// One sample: its index and a value per `--vary`, in their order.
#[derive(Debug, Clone, PartialEq)]
pub struct Sample {
    /// 0-based index.
    pub index: usize,
    /// (name, value) per parameter.
    pub values: Vec<(String, Value)>,
}

/// The generator of Monte Carlo sample `k` of a sweep seeded with `seed`.
fn sample_rng(seed: u64, k: usize) -> SplitMix64 {
    // Two SplitMix64 outputs decorrelate neighbouring seeds and indices.
    let mut mix = SplitMix64::new(seed);
    let base = mix.next_u64();
    SplitMix64::new(base ^ (k as u64).wrapping_mul(0xD605_0B4E_A6C4_8D35))
}

/// `count` Monte Carlo samples.
pub fn monte_carlo(vary: &[Vary], count: usize, seed: u64) -> Vec<Sample> {
    (0..count)
        .map(|k| {
            let mut rng = sample_rng(seed, k);
            Sample {
                index: k,
                values: vary
                    .iter()
                    .map(|v| (v.name.clone(), v.set.draw(&mut rng)))
                    .collect(),
            }
        })
        .collect()
}

/// The Cartesian product of the sets (the first `--vary` varies slowest).
pub fn grid(vary: &[Vary]) -> Result<Vec<Sample>, SpecError> {
    let sets: Vec<Vec<Value>> = vary
        .iter()
        .map(|v| {
            v.set
                .values()
                .ok_or_else(|| SpecError::Continuous(v.name.clone()))
        })
        .collect::<Result<_, _>>()?;
    let total: usize = sets.iter().map(Vec::len).product();
    Ok((0..total)
        .map(|k| {
            let mut rest = k;
            let mut values = vec![(String::new(), Value::Num(0.0)); sets.len()];
            for (i, set) in sets.iter().enumerate().rev() {
                values[i] = (vary[i].name.clone(), set[rest % set.len()].clone());
                rest /= set.len();
            }
            Sample { index: k, values }
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p(s: &str) -> Result<Vary, String> {
        parse(s, |n| n == "n").map_err(|e| e.to_string())
    }

    #[test]
    fn spec_parser_reads_ranges_counts_lists_and_single_values() {
        assert_eq!(p("delay.max=0..0.05").unwrap().set, Set::Range(0.0, 0.05));
        assert_eq!(
            p("fault.gamma=0.4..1/4").unwrap().set,
            Set::List(vec![
                Value::Num(0.4),
                Value::Num(0.6),
                Value::Num(0.8),
                Value::Num(1.0)
            ])
        );
        assert_eq!(p("n=5..50").unwrap().set, Set::IntRange(5, 50));
        assert_eq!(
            p("graph=ring,path").unwrap().set,
            Set::List(vec![Value::Word("ring".into()), Value::Word("path".into())])
        );
        assert_eq!(p(" target_speed = 2 ").unwrap().name, "target_speed");
        assert_eq!(
            p("target_speed=2").unwrap().set,
            Set::List(vec![Value::Num(2.0)])
        );
    }

    #[test]
    fn spec_parser_refuses_malformed_specs_with_the_parameter_named() {
        for bad in [
            "delay.max",
            "=1..2",
            "x=",
            "x=2..1",
            "x=0..1/1",
            "x=0..1/two",
            "x=a..1",
            "n=1.5..3",
            "n=2.5",
            "x=1,,2",
            "x=inf..1",
        ] {
            let e = p(bad).expect_err(bad);
            assert!(e.contains("--vary"), "{bad}: {e}");
        }
        assert!(p("n=1.5..3").unwrap_err().contains("n"));
    }

    #[test]
    fn monte_carlo_samples_are_deterministic_for_a_seed_and_stay_in_their_sets() {
        let vary = vec![
            p("delay.max=0..0.05").unwrap(),
            p("n=5..7").unwrap(),
            p("graph=ring,path").unwrap(),
        ];
        let a = monte_carlo(&vary, 200, 9);
        assert_eq!(a, monte_carlo(&vary, 200, 9));
        // Sample k does not depend on how many are drawn.
        assert_eq!(a[..10], monte_carlo(&vary, 10, 9)[..]);
        assert_ne!(a, monte_carlo(&vary, 200, 10));
        let mut seen_n = [false; 3];
        for s in &a {
            let d = s.values[0].1.num("d").unwrap();
            assert!((0.0..0.05).contains(&d));
            let n = s.values[1].1.num("n").unwrap();
            assert_eq!(n.fract(), 0.0);
            seen_n[n as usize - 5] = true;
            assert!(matches!(&s.values[2].1, Value::Word(w) if w == "ring" || w == "path"));
        }
        assert_eq!(
            seen_n, [true; 3],
            "every integer of 5..7 is drawn in 200 samples"
        );
    }

    #[test]
    fn grid_is_the_cartesian_product_with_the_first_parameter_slowest() {
        let vary = vec![p("a=1,2").unwrap(), p("b=0..1/3").unwrap()];
        let g = grid(&vary).unwrap();
        let flat: Vec<(f64, f64)> = g
            .iter()
            .map(|s| {
                (
                    s.values[0].1.num("a").unwrap(),
                    s.values[1].1.num("b").unwrap(),
                )
            })
            .collect();
        assert_eq!(
            flat,
            vec![
                (1.0, 0.0),
                (1.0, 0.5),
                (1.0, 1.0),
                (2.0, 0.0),
                (2.0, 0.5),
                (2.0, 1.0)
            ]
        );
        assert!(grid(&[p("c=0..1").unwrap()])
            .unwrap_err()
            .to_string()
            .contains("count"));
    }
}
