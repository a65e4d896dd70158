//! Checks of an injection against the run's scenario, shared by `formation inject` (before sending)
//! and the orchestrator (before applying). Errors name the offending option.

use formation_config::Scenario;

/// A delay profile tau(t) = base + amplitude sin(rate t), s.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DelayProfile {
    /// Base, s.
    pub base_s: f64,
    /// Amplitude, s.
    pub amplitude_s: f64,
    /// Angular rate, rad/s.
    pub angular_rate_rad_s: f64,
}

/// Why an injection is refused: the option and what it must be.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum InjectError {
    /// `--agent` (1-based) outside the run's agents.
    #[error("--agent {agent}: the run has {n} agents; ids are 1-based (1..={n})")]
    Agent {
        /// The id given.
        agent: usize,
        /// The run's agents.
        n: usize,
    },
    /// A Gamma component (1-based) outside (0, 1].
    #[error("--gamma: component {component} is {value}; each Gamma must be in (0, 1]")]
    Gamma {
        /// The component, 1-based.
        component: usize,
        /// Its value.
        value: f64,
    },
    /// A delta component (1-based) beyond half the torque range.
    #[error("--delta: component {component} is {value} N m; |delta| must be at most half the torque range ({half} N m)")]
    Delta {
        /// The component, 1-based.
        component: usize,
        /// Its value, N m.
        value: f64,
        /// Half the torque range of that axis, N m.
        half: f64,
    },
    /// `--down` is no finite time > 0.
    #[error("--down {0}: must be a finite time > 0 s")]
    Down(f64),
    /// tau(t) goes below zero (its least value, s).
    #[error("--tau: tau(t) reaches {0} s; it must never be negative")]
    NegativeTau(f64),
    /// tau(t) goes above tau_M.
    #[error("--tau: tau(t) reaches {hi} s, above tau_M = {tau_m} s of the run's scenario")]
    AboveTauM {
        /// Its largest value, s.
        hi: f64,
        /// The scenario's tau_M, s.
        tau_m: f64,
    },
    /// `--at` is no time >= 0.
    #[error("--at {0}: must be a finite simulation time >= 0 s")]
    AtSign(f64),
    /// `--at` after the run's end.
    #[error("--at {t}: must be a time in [0, {duration}] s")]
    At {
        /// The time given, s.
        t: f64,
        /// The run's duration, s.
        duration: f64,
    },
    /// `--tau` is empty.
    #[error("--tau is empty; expected {FORMS}")]
    TauEmpty,
    /// A number of `--tau` that is none (which one and its text).
    #[error("--tau '{expr}': bad {what} '{text}'; expected {FORMS}")]
    TauNumber {
        /// The expression.
        expr: String,
        /// Which number: constant, base, amplitude, angular rate.
        what: &'static str,
        /// Its text.
        text: String,
    },
    /// `--tau` of neither form.
    #[error("--tau '{0}': expected {FORMS}")]
    TauForm(String),
    /// The sine's argument of `--tau` is not `w*t`.
    #[error("--tau '{0}': the sine's argument must be w*t")]
    TauArgument(String),
}

/// Agent id `agent` (1-based) must exist in a run of `n` agents.
pub fn agent(agent: usize, n: usize) -> Result<(), InjectError> {
    if agent == 0 || agent > n {
        return Err(InjectError::Agent { agent, n });
    }
    Ok(())
}

/// Gamma in (0, 1] per axis; |delta| at most half the torque range per axis.
pub fn fault(s: &Scenario, gamma: [f64; 3], delta: [f64; 3]) -> Result<(), InjectError> {
    for (k, g) in gamma.iter().enumerate() {
        if !(g.is_finite() && *g > 0.0 && *g <= 1.0) {
            return Err(InjectError::Gamma {
                component: k + 1,
                value: *g,
            });
        }
    }
    for (k, d) in delta.iter().enumerate() {
        let half = formation_config::scenario::validate::max_fault_delta_nm(s, k);
        if !(d.is_finite() && d.abs() <= half) {
            return Err(InjectError::Delta {
                component: k + 1,
                value: *d,
                half,
            });
        }
    }
    Ok(())
}

/// `--down D` must be a finite time > 0 (the run bounds it further: at least one step, at most
/// the run's remaining time).
pub fn down(d: f64) -> Result<(), InjectError> {
    if !(d.is_finite() && d > 0.0) {
        return Err(InjectError::Down(d));
    }
    Ok(())
}

/// tau(t) must stay within [0, tau_M] for every t.
pub fn delay(s: &Scenario, d: &DelayProfile) -> Result<(), InjectError> {
    let tau_m = s.simulation.max_delay_s;
    let lo = d.base_s - d.amplitude_s.abs();
    let hi = d.base_s + d.amplitude_s.abs();
    if lo < 0.0 {
        return Err(InjectError::NegativeTau(lo));
    }
    if hi > tau_m {
        return Err(InjectError::AboveTauM { hi, tau_m });
    }
    Ok(())
}

/// `--at T` must be a time (finite, not negative), whatever the run.
pub fn at_sign(t: f64) -> Result<(), InjectError> {
    if !(t.is_finite() && t >= 0.0) {
        return Err(InjectError::AtSign(t));
    }
    Ok(())
}

/// `--at T` must lie within the run.
pub fn at(s: &Scenario, t: f64) -> Result<(), InjectError> {
    if !(t.is_finite() && t >= 0.0 && t <= s.simulation.duration_s) {
        return Err(InjectError::At {
            t,
            duration: s.simulation.duration_s,
        });
    }
    Ok(())
}

fn number(text: &str, what: &'static str, expr: &str) -> Result<f64, InjectError> {
    text.parse::<f64>()
        .ok()
        .filter(|v| v.is_finite())
        .ok_or_else(|| InjectError::TauNumber {
            expr: expr.to_string(),
            what,
            text: text.to_string(),
        })
}

const FORMS: &str = "a constant (0.03) or base+amp*sin(w*t) (0.02+0.01*sin(0.5*t))";

/// Parses `--tau`: a constant `C`, or `B+A*sin(W*t)` / `B-A*sin(W*t)` / `A*sin(W*t)` (spaces allowed).
pub fn parse_tau(expr: &str) -> Result<DelayProfile, InjectError> {
    let s: String = expr.chars().filter(|c| !c.is_whitespace()).collect();
    let s = s.to_ascii_lowercase();
    if s.is_empty() {
        return Err(InjectError::TauEmpty);
    }
    if !s.contains("sin(") {
        let base_s = number(&s, "constant", expr)?;
        return Ok(DelayProfile {
            base_s,
            amplitude_s: 0.0,
            angular_rate_rad_s: 0.0,
        });
    }
    let (left, inner) = s
        .strip_suffix(')')
        .and_then(|x| x.split_once("*sin("))
        .ok_or_else(|| InjectError::TauForm(expr.to_string()))?;
    let w = inner
        .strip_suffix("*t")
        .ok_or_else(|| InjectError::TauArgument(expr.to_string()))?;
    let angular_rate_rad_s = number(w, "angular rate", expr)?;
    // The sign between base and amplitude: the last + or - that is not leading and not an exponent's.
    let bytes = left.as_bytes();
    let split = (1..bytes.len())
        .rev()
        .find(|&p| matches!(bytes[p], b'+' | b'-') && !matches!(bytes[p - 1], b'e'));
    let (base_s, amplitude_s) = match split {
        Some(p) => (
            number(&left[..p], "base", expr)?,
            number(&left[p..], "amplitude", expr)?,
        ),
        None => (0.0, number(left, "amplitude", expr)?),
    };
    Ok(DelayProfile {
        base_s,
        amplitude_s,
        angular_rate_rad_s,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p(b: f64, a: f64, w: f64) -> DelayProfile {
        DelayProfile {
            base_s: b,
            amplitude_s: a,
            angular_rate_rad_s: w,
        }
    }

    #[test]
    fn tau_expressions_parse() {
        assert_eq!(parse_tau("0.03").unwrap(), p(0.03, 0.0, 0.0));
        assert_eq!(
            parse_tau("0.02+0.01*sin(0.5*t)").unwrap(),
            p(0.02, 0.01, 0.5)
        );
        assert_eq!(
            parse_tau(" 0.02 - 0.01 * sin( 2 * t ) ").unwrap(),
            p(0.02, -0.01, 2.0)
        );
        assert_eq!(
            parse_tau("1e-2+5e-3*sin(1*t)").unwrap(),
            p(0.01, 0.005, 1.0)
        );
        assert_eq!(parse_tau("0.01*sin(3*t)").unwrap(), p(0.0, 0.01, 3.0));
    }

    #[test]
    fn bad_tau_expressions_are_rejected_with_the_field() {
        for bad in [
            "",
            "abc",
            "nan",
            "0.02+0.01*cos(0.5*t)",
            "0.02+0.01*sin(0.5)",
            "0.02+x*sin(t*2)",
        ] {
            let e = parse_tau(bad).unwrap_err().to_string();
            assert!(e.contains("--tau"), "{bad}: {e}");
        }
    }

    #[test]
    fn limits_of_the_scenario_are_enforced() {
        let s = Scenario::paper();
        assert!(agent(2, 5).is_ok());
        assert!(agent(0, 5).unwrap_err().to_string().contains("--agent"));
        assert!(agent(6, 5).unwrap_err().to_string().contains("--agent"));
        assert!(fault(&s, [0.5; 3], [0.0; 3]).is_ok());
        assert!(fault(&s, [1.5, 1.0, 1.0], [0.0; 3])
            .unwrap_err()
            .to_string()
            .contains("--gamma"));
        assert!(fault(&s, [0.0, 1.0, 1.0], [0.0; 3])
            .unwrap_err()
            .to_string()
            .contains("--gamma"));
        for d in [f64::INFINITY, f64::NAN, -1.0, 0.0] {
            assert!(down(d).unwrap_err().to_string().contains("--down"), "{d}");
        }
        assert!(fault(&s, [1.0; 3], [1e6, 0.0, 0.0])
            .unwrap_err()
            .to_string()
            .contains("--delta"));
        let tau_m = s.simulation.max_delay_s;
        assert!(delay(&s, &p(tau_m / 2.0, 0.0, 0.0)).is_ok());
        assert!(delay(&s, &p(tau_m * 2.0, 0.0, 0.0))
            .unwrap_err()
            .to_string()
            .contains("tau_M"));
        assert!(delay(&s, &p(0.001, 0.01, 1.0))
            .unwrap_err()
            .to_string()
            .contains("negative"));
    }
}
