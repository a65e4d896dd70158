//! Sweep parameters: what each name does to the base scenario (docs/sweep.md).
//!
//! | name | unit | effect |
//! |---|---|---|
//! | `n` | - | N: the base scenario scaled by `formation scenario`'s generator (radii, graph, leaders) |
//! | `graph` | - | ring, path, k-nearest, complete, random-connected (generated; default path) |
//! | `k` | - | k of k-nearest (generated; default 4) |
//! | `seed` | - | RBFNN seed `controller.rbfnn.seed` and the random-connected graph's seed |
//! | `delay.max` | s | every agent's delay profile scaled so that base + amplitude = value; tau_M raised to it if lower |
//! | `fault.gamma` | - | final Gamma of every channel of every agent (Gamma(0) = 1 kept) |
//! | `fault.delta` | - | factor on every additive fault term (ramp, oscillation, bias); 1 = the base's |
//! | `start_offset` | m | every quadrotor starts this far radially outside its cover slot |
//! | `target_speed` | x | factor on the target's angular rate (1 = the base's) |
//! | any other | | a scenario path as for `--set`, e.g. `controller.position.k_p` (numbers) |
//!
//! Structural parameters (`n`, `graph`, `k`) go first whatever their order on the command line;
//! `seed` next, then the rest in the order given.

use super::spec::{SpecError, Value};
use crate::scenario_gen::{self, graphs::GraphKind, GenError, GenOptions};
use formation_config::scenario::validate::ValidationErrors;
use formation_config::Scenario;

/// Why a sample's values cannot make a valid scenario: the parameter and what failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ApplyError {
    /// A value of the wrong kind.
    #[error(transparent)]
    Spec(#[from] SpecError),
    /// `n`, `k` or `seed` not a whole number at or above its least value.
    #[error("{name}={x}: expected a whole number >= {lo}")]
    Count {
        /// The parameter.
        name: String,
        /// The value.
        x: f64,
        /// Its least value.
        lo: f64,
    },
    /// `graph` given a number.
    #[error("graph={0}: expected a graph name")]
    GraphName(Value),
    /// The generator refused `n`, `graph` or `k`.
    #[error(transparent)]
    Generate(#[from] GenError),
    /// A negative `delay.max`.
    #[error("delay.max={0}: expected >= 0 s")]
    DelayMax(f64),
    /// A scenario path the runtime's `--set` parser refused.
    #[error("{0}")]
    Set(formation_runtime::cli::OverrideError),
    /// The scenario built is invalid: every reason, `; `-separated.
    #[error("{}", .0.0.iter().map(|e| e.to_string()).collect::<Vec<_>>().join("; "))]
    Invalid(ValidationErrors),
}

/// Parameters that take whole numbers (an event's agent, `events[0].agent`, included).
pub fn is_integer(name: &str) -> bool {
    matches!(name, "n" | "k" | "seed") || (name.starts_with("events[") && name.ends_with("].agent"))
}

fn count(name: &str, v: &Value, lo: f64) -> Result<usize, ApplyError> {
    let x = v.num(name)?;
    if x < lo || x.fract() != 0.0 {
        return Err(ApplyError::Count {
            name: name.to_string(),
            x,
            lo,
        });
    }
    Ok(x as usize)
}

/// The scenario of one sample: `base` with `values` applied.
pub fn apply(base: &Scenario, values: &[(String, Value)]) -> Result<Scenario, ApplyError> {
    let get = |n: &str| values.iter().find(|(k, _)| k == n).map(|(_, v)| v);
    let seed = get("seed").map(|v| count("seed", v, 0.0)).transpose()?;
    let mut s = if get("n").is_some() || get("graph").is_some() || get("k").is_some() {
        let n = match get("n") {
            Some(v) => count("n", v, 2.0)?,
            None => base.n_agents(),
        };
        let graph = match get("graph") {
            Some(Value::Word(w)) => GraphKind::parse(w)?,
            Some(v) => return Err(ApplyError::GraphName(v.clone())),
            None => GraphKind::Path,
        };
        let mut o = GenOptions::new(n, graph);
        if let Some(v) = get("k") {
            o.k = count("k", v, 1.0)?;
        }
        if let Some(sd) = seed {
            o.seed = sd as u64;
        }
        scenario_gen::generate_from(base, &o)?
    } else {
        base.clone()
    };
    if let Some(sd) = seed {
        s.controller.rbfnn.seed = sd as u64;
    }
    let mut overrides = Vec::new();
    for (name, v) in values {
        match name.as_str() {
            "n" | "graph" | "k" | "seed" => {}
            "delay.max" => {
                let d = v.num(name)?;
                if d < 0.0 {
                    return Err(ApplyError::DelayMax(d));
                }
                for a in &mut s.agents {
                    let top = a.delay.base_s + a.delay.amplitude_s;
                    if top > 0.0 {
                        a.delay.base_s *= d / top;
                        a.delay.amplitude_s *= d / top;
                    } else {
                        a.delay.base_s = d;
                    }
                }
                s.simulation.max_delay_s = s.simulation.max_delay_s.max(d);
            }
            "fault.gamma" => {
                let g = v.num(name)?;
                for a in &mut s.agents {
                    a.fault.gamma_final = [g; 3];
                    a.fault.gamma_initial_excess = [1.0 - g; 3];
                }
            }
            "fault.delta" => {
                let f = v.num(name)?;
                for a in &mut s.agents {
                    let fl = &mut a.fault;
                    for k in 0..3 {
                        fl.delta_ramp_nm[k] *= f;
                        fl.delta_osc_amplitude_nm[k] *= f;
                        fl.delta_bias_nm[k] *= f;
                    }
                }
            }
            "start_offset" => scenario_gen::place_starts(&mut s, v.num(name)?),
            "target_speed" => s.mission.target.angular_rate_rad_s *= v.num(name)?,
            path => overrides.push(format!("{path}={v}")),
        }
    }
    let s = formation_runtime::cli::apply_overrides(s, &overrides).map_err(ApplyError::Set)?;
    formation_config::scenario::validate::validate(&s).map_err(ApplyError::Invalid)?;
    Ok(s)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn v(pairs: &[(&str, Value)]) -> Vec<(String, Value)> {
        pairs
            .iter()
            .map(|(k, v)| (k.to_string(), v.clone()))
            .collect()
    }

    #[test]
    fn delay_max_scales_every_profile_to_peak_at_the_value() {
        let s = apply(&Scenario::paper(), &v(&[("delay.max", Value::Num(0.02))])).unwrap();
        for a in &s.agents {
            assert!((a.delay.base_s + a.delay.amplitude_s - 0.02).abs() < 1e-12);
        }
        let s = apply(&Scenario::paper(), &v(&[("delay.max", Value::Num(0.08))])).unwrap();
        assert_eq!(s.simulation.max_delay_s, 0.08);
    }

    #[test]
    fn named_parameters_change_what_they_document() {
        let base = Scenario::paper();
        let s = apply(
            &base,
            &v(&[
                ("fault.gamma", Value::Num(0.5)),
                ("fault.delta", Value::Num(0.0)),
                ("target_speed", Value::Num(3.0)),
                ("start_offset", Value::Num(4.0)),
                ("controller.position.k_p", Value::Num(2.5)),
            ]),
        )
        .unwrap();
        let a = &s.agents[0];
        assert_eq!(a.fault.gamma_final, [0.5; 3]);
        assert_eq!(a.fault.delta_ramp_nm, [0.0; 3]);
        assert_eq!(
            s.mission.target.angular_rate_rad_s,
            3.0 * base.mission.target.angular_rate_rad_s
        );
        assert_eq!(s.controller.position.k_p, 2.5);
        // Agent 1's slot is straight "north" of T_g(0) = (0, 15): it starts 2 + 4 m away.
        let p = a.initial_position_m;
        assert!((p[0].hypot(p[1] - 15.0) - 6.0).abs() < 1e-9);
    }

    #[test]
    fn structural_parameters_generate_a_scaled_scenario_and_bad_values_are_refused() {
        let s = apply(
            &Scenario::paper(),
            &v(&[
                ("graph", Value::Word("ring".into())),
                ("n", Value::Num(12.0)),
                ("seed", Value::Num(3.0)),
            ]),
        )
        .unwrap();
        assert_eq!(s.n_agents(), 12);
        assert_eq!(s.graph.edges.len(), 12);
        assert_eq!(s.controller.rbfnn.seed, 3);
        assert!(apply(&Scenario::paper(), &v(&[("n", Value::Num(1.0))])).is_err());
        assert!(apply(
            &Scenario::paper(),
            &v(&[("graph", Value::Word("star".into()))])
        )
        .is_err());
        // Gamma below the known lower bound of Assumption 5 is refused by validation.
        let e = apply(&Scenario::paper(), &v(&[("fault.gamma", Value::Num(0.1))])).unwrap_err();
        assert!(e.to_string().contains("Assumption 5"), "{e}");
    }
}
