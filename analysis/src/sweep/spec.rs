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
    pub fn num(&self, name: &str) -> Result<f64, String> {
        match self {
            Value::Num(x) => Ok(*x),
            Value::Word(w) => Err(format!("{name}={w}: expected a number")),
        }
    }
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

fn number(name: &str, s: &str) -> Result<f64, String> {
    let x: f64 = s
        .trim()
        .parse()
        .map_err(|_| format!("--vary {name}: '{s}' is not a number"))?;
    if !x.is_finite() {
        return Err(format!("--vary {name}: '{s}' is not finite"));
    }
    Ok(x)
}

/// Parses one `NAME=SPEC`; `integer` says whether the parameter takes integers only.
pub fn parse(arg: &str, integer: impl Fn(&str) -> bool) -> Result<Vary, String> {
    let (name, spec) = arg
        .split_once('=')
        .ok_or_else(|| format!("--vary '{arg}': expected NAME=SPEC, e.g. delay.max=0..0.05"))?;
    let (name, spec) = (name.trim().to_string(), spec.trim());
    if name.is_empty() || spec.is_empty() {
        return Err(format!("--vary '{arg}': expected NAME=SPEC"));
    }
    let int = integer(&name);
    let set = if let Some((lo, rest)) = spec.split_once("..") {
        let (hi, count) = match rest.split_once('/') {
            Some((h, c)) => {
                let c: usize = c.trim().parse().map_err(|_| {
                    format!("--vary {name}: count '{c}' after '/' is not a whole number")
                })?;
                if c < 2 {
                    return Err(format!("--vary {name}: a count needs at least 2 values"));
                }
                (h, Some(c))
            }
            None => (rest, None),
        };
        let (lo, hi) = (number(&name, lo)?, number(&name, hi)?);
        if lo > hi {
            return Err(format!("--vary {name}: {lo}..{hi} is empty (LO > HI)"));
        }
        if int && (lo.fract() != 0.0 || hi.fract() != 0.0) {
            return Err(format!("--vary {name}: takes whole numbers, got {spec}"));
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
                            Err(format!("--vary {name}: takes whole numbers, got {v}"))
                        } else {
                            Ok(Value::Num(x))
                        }
                    }
                    Ok(_) => Err(format!("--vary {name}: '{v}' is not finite")),
                    Err(_) if v.is_empty() => {
                        Err(format!("--vary {name}: empty value in '{spec}'"))
                    }
                    Err(_) => Ok(Value::Word(v.to_string())),
                }
            })
            .collect::<Result<Vec<_>, _>>()?;
        Set::List(vals)
    };
    Ok(Vary { name, set })
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
pub fn grid(vary: &[Vary]) -> Result<Vec<Sample>, String> {
    let sets: Vec<Vec<Value>> = vary
        .iter()
        .map(|v| {
            v.set.values().ok_or_else(|| {
                format!(
                    "--grid: {} is a continuous range; give a count (LO..HI/COUNT) or a list",
                    v.name
                )
            })
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
        parse(s, |n| n == "n")
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
        assert!(grid(&[p("c=0..1").unwrap()]).unwrap_err().contains("count"));
    }
}
