//! Identification of the actuator faults Gamma_i, delta_i of (4) from a probing signal (ours,
//! docs/deviations.md D16).
//!
//! Per channel the vehicle receives y_k = Gamma_k U_k + delta_k (+ J D_k and model error, small) while
//! the torque is not saturated. The agent measures y from the rate increment over one step,
//! y_k = J ((Omega_{k+1} - Omega_k) / dt - F_A(Omega_k)), with the nominal F_A of (2). Near a constant
//! operating point U_k is almost constant and (Gamma, delta) cannot be told apart: every pair on the line
//! Gamma U + delta = y fits. A known sinusoid s_k = sin(2 pi k / P) scaled by a_k is therefore added to
//! U_iAC, and
//!
//! - Gamma_id = <s y> / <s U> (instrumental variable: s is independent of delta, the disturbance and the
//!   loop's low-frequency reactions, so the ratio is unbiased even though U is fed back),
//! - delta_id = <y> - Gamma_id <U>,
//!
//! where every product is first averaged over exactly one probe period (a boxcar of P samples, which
//! removes the constant and slowly varying parts of U and y from the correlations exactly) and then
//! low-pass filtered with time constants T_Gamma, T_delta. The estimates are valid while the
//! correlation <s U> reaches rho a/2 (the probe arrived: the excitation condition) and no sample of the
//! current period may have been saturated.
//!
//! Fixed-size buffers only (one period, at most [`MAX_PROBE_PERIOD_STEPS`] samples): no allocation per
//! step.

use formation_config::kinematics::rotational_drift;
use formation_config::scenario::{FaultIdentificationSpec, MAX_PROBE_PERIOD_STEPS};
use nalgebra::Vector3;

/// Fraction of the half torque range beyond which the expected delivered torque Gamma-hat U + delta-hat
/// counts as possibly saturated (the estimate can be off by the probe amplitude and the estimation
/// error, so the guard sits inside the limit): such samples keep the averages frozen for one period.
pub const SATURATION_GUARD: f64 = 0.9;

/// What the identifier holds about one step whose outcome (the next rate) is not yet known.
#[derive(Debug, Clone, Copy, serde::Serialize, serde::Deserialize)]
struct Pending {
    u: Vector3<f64>,
    w: Vector3<f64>,
    s: f64,
    saturated: bool,
}

/// Probe generator and per-channel identifier.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct FaultIdentifier {
    period: usize,
    amplitude: Vector3<f64>,
    alpha_gamma: f64,
    alpha_delta: f64,
    excitation: Vector3<f64>,
    #[serde(with = "crate::checkpoint::array")]
    ring_s: [f64; MAX_PROBE_PERIOD_STEPS],
    #[serde(with = "crate::checkpoint::array")]
    ring_u: [[f64; 3]; MAX_PROBE_PERIOD_STEPS],
    #[serde(with = "crate::checkpoint::array")]
    ring_y: [[f64; 3]; MAX_PROBE_PERIOD_STEPS],
    head: usize,
    filled: usize,
    hold: usize,
    pending: Option<Pending>,
    m_su: Vector3<f64>,
    m_sy: Vector3<f64>,
    m_u: Vector3<f64>,
    m_y: Vector3<f64>,
}

/// The identified values of one step (per channel; `valid[k]` false means "not excited").
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Identified {
    /// Gamma_id.
    pub gamma: Vector3<f64>,
    /// delta_id, N m.
    pub delta: Vector3<f64>,
    /// The excitation condition holds on this channel.
    pub valid: [bool; 3],
}

/// The nominal rigid body the identifier measures the delivered torque against.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NominalBody {
    /// J_i, the diagonal of the nominal inertia, kg m².
    pub inertia: Vector3<f64>,
    /// K_iD, the diagonal of the nominal aerodynamic damping, N m s/rad.
    pub drag: Vector3<f64>,
}

impl FaultIdentifier {
    /// The identifier of `spec` at step `dt` (off when the amplitude or the period is zero).
    pub fn new(spec: &FaultIdentificationSpec, dt: f64) -> FaultIdentifier {
        let period = if spec.probe_period_s > 0.0 {
            ((spec.probe_period_s / dt).round() as usize).min(MAX_PROBE_PERIOD_STEPS)
        } else {
            0
        };
        let rate = |t: f64| if t > 0.0 { (dt / t).min(1.0) } else { 0.0 };
        let amplitude = Vector3::from(spec.probe_amplitude_nm);
        FaultIdentifier {
            period,
            amplitude,
            alpha_gamma: rate(spec.gamma_averaging_s),
            alpha_delta: rate(spec.delta_averaging_s),
            excitation: amplitude.map(|a| 0.5 * spec.excitation_ratio * a.abs()),
            ring_s: [0.0; MAX_PROBE_PERIOD_STEPS],
            ring_u: [[0.0; 3]; MAX_PROBE_PERIOD_STEPS],
            ring_y: [[0.0; 3]; MAX_PROBE_PERIOD_STEPS],
            head: 0,
            filled: 0,
            hold: 0,
            pending: None,
            m_su: Vector3::zeros(),
            m_sy: Vector3::zeros(),
            m_u: Vector3::zeros(),
            m_y: Vector3::zeros(),
        }
    }

    /// True when a probe is injected.
    pub fn active(&self) -> bool {
        self.period >= 2 && self.amplitude.iter().any(|a| *a != 0.0)
    }

    /// Unit probe s_k = sin(2 pi k / P) at step k (0 when off).
    pub fn unit_probe(&self, step: u64) -> f64 {
        if !self.active() {
            return 0.0;
        }
        let phase = (step % self.period as u64) as f64 / self.period as f64;
        (std::f64::consts::TAU * phase).sin()
    }

    /// The probe a s_k added to U_iAC at step k, N m.
    pub fn probe(&self, step: u64) -> Vector3<f64> {
        self.probe_of(self.unit_probe(step))
    }

    /// The probe a s for the unit probe `s` of [`FaultIdentifier::unit_probe`] (computed once per
    /// step), N m.
    pub fn probe_of(&self, s: f64) -> Vector3<f64> {
        self.amplitude * s
    }

    /// Closes the pending sample with the rate `w` now measured (Omega_{k+1}), then holds the command `u`
    /// of this step (probe included), the rate `w` it starts from, its unit probe `s` and whether the
    /// expected delivered torque may be saturated. `body`: the nominal inertia and damping.
    pub fn observe(
        &mut self,
        w: &Vector3<f64>,
        u: &Vector3<f64>,
        s: f64,
        saturated: bool,
        body: &NominalBody,
        dt: f64,
    ) {
        if !self.active() {
            return;
        }
        if let Some(prev) = self.pending {
            let accel = (w - prev.w) / dt - rotational_drift(&body.inertia, &body.drag, &prev.w);
            let y = body.inertia.component_mul(&accel);
            self.push(prev, y);
        }
        self.pending = Some(Pending {
            u: *u,
            w: *w,
            s,
            saturated,
        });
    }

    fn push(&mut self, sample: Pending, y: Vector3<f64>) {
        let p = self.period;
        self.ring_s[self.head] = sample.s;
        self.ring_u[self.head] = sample.u.into();
        self.ring_y[self.head] = y.into();
        self.head = (self.head + 1) % p;
        self.filled = (self.filled + 1).min(p);
        if sample.saturated {
            self.hold = p;
        } else if self.hold > 0 {
            self.hold -= 1;
        }
        if self.filled < p || self.hold > 0 {
            return;
        }
        let mut su = Vector3::zeros();
        let mut sy = Vector3::zeros();
        let mut mu = Vector3::zeros();
        let mut my = Vector3::zeros();
        for n in 0..p {
            let s = self.ring_s[n];
            let u = Vector3::from(self.ring_u[n]);
            let y = Vector3::from(self.ring_y[n]);
            su += u * s;
            sy += y * s;
            mu += u;
            my += y;
        }
        let inv = 1.0 / p as f64;
        self.m_su += (su * inv - self.m_su) * self.alpha_gamma;
        self.m_sy += (sy * inv - self.m_sy) * self.alpha_gamma;
        self.m_u += (mu * inv - self.m_u) * self.alpha_delta;
        self.m_y += (my * inv - self.m_y) * self.alpha_delta;
    }

    /// The identified Gamma and delta per channel, with the excitation condition.
    pub fn identified(&self) -> Identified {
        let mut out = Identified {
            gamma: Vector3::zeros(),
            delta: Vector3::zeros(),
            valid: [false; 3],
        };
        if !self.active() {
            return out;
        }
        for k in 0..3 {
            let den = self.m_su[k] * self.amplitude[k].signum();
            if self.amplitude[k] != 0.0 && den >= self.excitation[k] && den > 0.0 {
                let g = self.m_sy[k] / self.m_su[k];
                out.gamma[k] = g;
                out.delta[k] = self.m_y[k] - g * self.m_u[k];
                out.valid[k] = true;
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spec() -> FaultIdentificationSpec {
        FaultIdentificationSpec {
            probe_amplitude_nm: [0.02, 0.02, 0.04],
            probe_period_s: 0.025,
            gamma_averaging_s: 1.0,
            delta_averaging_s: 0.5,
            composite_rate: 2.0,
            excitation_ratio: 0.5,
        }
    }

    /// A rigid body with the torque Gamma U + delta and a slowly varying command that would make
    /// (Gamma, delta) unidentifiable without the probe: the identifier recovers both.
    #[test]
    fn probe_separates_gamma_and_delta_under_a_near_constant_command() {
        let dt = 0.001;
        let j = Vector3::new(0.02351, 0.02351, 0.04701);
        let drag = Vector3::new(0.003, 0.003, 0.003);
        let body = NominalBody { inertia: j, drag };
        let gamma = Vector3::new(0.7, 0.45, 0.77);
        let delta = Vector3::new(0.1, -0.05, -0.8);
        let mut id = FaultIdentifier::new(&spec(), dt);
        let mut w = Vector3::<f64>::zeros();
        for k in 0..5000u64 {
            // A rate loop that cancels delta on average (what the controller does at a steady point).
            let t = k as f64 * dt;
            let base = -delta.component_div(&gamma) * (1.0 + 0.05 * (0.3 * t).sin()) - w * 0.5;
            let s = id.unit_probe(k);
            let u = base + id.probe(k);
            id.observe(&w, &u, s, false, &body, dt);
            let wd = rotational_drift(&j, &drag, &w)
                + (gamma.component_mul(&u) + delta).component_div(&j);
            w += wd * dt;
        }
        let est = id.identified();
        for k in 0..3 {
            assert!(est.valid[k]);
            assert!(
                (est.gamma[k] - gamma[k]).abs() < 0.02 * gamma[k],
                "{k}: {est:?}"
            );
            assert!((est.delta[k] - delta[k]).abs() < 0.01, "{k}: {est:?}");
        }
    }

    #[test]
    fn without_probe_nothing_is_identified_and_no_probe_is_added() {
        let id = FaultIdentifier::new(&FaultIdentificationSpec::default(), 0.001);
        assert!(!id.active());
        assert_eq!(id.probe(7), Vector3::zeros());
        assert_eq!(id.identified().valid, [false; 3]);
    }

    #[test]
    fn saturated_samples_freeze_the_averages_for_one_period() {
        let dt = 0.001;
        let j = Vector3::new(0.02351, 0.02351, 0.04701);
        let drag = Vector3::zeros();
        let body = NominalBody { inertia: j, drag };
        let mut id = FaultIdentifier::new(&spec(), dt);
        let w = Vector3::zeros();
        for k in 0..40u64 {
            let u = id.probe(k);
            id.observe(&w, &u, id.unit_probe(k), k >= 30, &body, dt);
        }
        let frozen = id.m_su;
        for k in 40..50u64 {
            let u = id.probe(k);
            id.observe(&w, &u, id.unit_probe(k), false, &body, dt);
        }
        assert_eq!(id.m_su, frozen);
    }
}
