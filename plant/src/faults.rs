//! Actuator faults (4): U_iAF = Gamma_i(t) U_iAC + delta_i(t), with the profiles of (63)-(64), and the
//! input saturation (3).

use crate::memo::{Direct, Math};
use formation_config::scenario::FaultSpec;
use nalgebra::Vector3;

/// Time profile of the actuator faults of one quadrotor, or a constant override injected at runtime.
#[derive(Debug, Clone, PartialEq)]
pub struct FaultModel {
    spec: FaultSpec,
    /// Constant (Gamma, delta) injected from a given step on; `None` follows the profile.
    pub override_from: Option<(u64, Vector3<f64>, Vector3<f64>)>,
}

impl FaultModel {
    /// The profile of a scenario.
    pub fn new(spec: &FaultSpec) -> FaultModel {
        FaultModel {
            spec: spec.clone(),
            override_from: None,
        }
    }

    /// Gamma_i(t) (diagonal) and delta_i(t) at step `step`, time `t`.
    pub fn at(&self, step: u64, t: f64) -> (Vector3<f64>, Vector3<f64>) {
        self.at_with(step, t, &mut Direct)
    }

    /// [`FaultModel::at`] with exp and sin from `m` (a plant's [`crate::memo::Memo`]).
    pub fn at_with(&self, step: u64, t: f64, m: &mut impl Math) -> (Vector3<f64>, Vector3<f64>) {
        if let Some((from, g, d)) = self.override_from {
            if step >= from {
                return (g, d);
            }
        }
        let f = &self.spec;
        let decay = m.exp(-f.gamma_decay_rate * t);
        let ramp = 1.0 - m.exp(-f.delta_ramp_rate * t);
        let mut gamma = Vector3::zeros();
        let mut delta = Vector3::zeros();
        for k in 0..3 {
            gamma[k] = f.gamma_final[k] + f.gamma_initial_excess[k] * decay;
            let grow = if f.delta_osc_grow[k] > 0.0 {
                1.0 - m.exp(-f.delta_osc_grow[k] * t)
            } else {
                1.0
            };
            delta[k] = f.delta_ramp_nm[k] * ramp * m.exp(-f.delta_ramp_decay[k] * t)
                + f.delta_osc_amplitude_nm[k]
                    * m.sin(f.delta_osc_rate_rad_s[k] * t + f.delta_osc_phase_rad[k])
                    * grow
                    * m.exp(-f.delta_osc_decay[k] * t)
                + f.delta_bias_nm[k] * m.exp(-f.delta_bias_decay[k] * t);
        }
        (gamma, delta)
    }
}

/// Eq. (4) then (3): the torque the actuators deliver for the command `u_ac`.
pub fn actuate(
    u_ac: &Vector3<f64>,
    gamma: &Vector3<f64>,
    delta: &Vector3<f64>,
    lo: &Vector3<f64>,
    hi: &Vector3<f64>,
) -> Vector3<f64> {
    let mut u = Vector3::zeros();
    for k in 0..3 {
        let faulty = gamma[k] * u_ac[k] + delta[k];
        u[k] = saturate(faulty, lo[k], hi[k]);
    }
    u
}

/// Eq. (3): clamps to [lo, hi]; a NaN command gives NaN (it is reported as a divergence, not hidden).
pub fn saturate(x: f64, lo: f64, hi: f64) -> f64 {
    if x > hi {
        hi
    } else if x < lo {
        lo
    } else {
        x
    }
}
