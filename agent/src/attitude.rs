//! AFTAC: the attitude loop of Section 3.3.
//!
//! Step 1 (attitude): z_i1 = A_i - A_iC with the BLF (31) of width C_i1 = C-bar_i1 - C_id (= the
//! attitude margin, since C-bar_i1 = ||A_iC|| + margin), virtual control alpha_iC (34), command filter
//! (Fig. 3) giving alpha_i and alpha_i', auxiliary system E_i1 (35).
//! Step 2 (rate): z_i2 = Omega_i - alpha_i with the BLF (40) of width C_i2 = C-bar_i2 - alpha-bar_i,
//! control Phi_i (45), U_iAC = Gamma-hat^-1 Phi_i (43), adaptive laws (46)-(49) with projection,
//! auxiliary system E_i2 (50).
//!
//! Our readings of the ambiguous laws (docs/deviations.md): the per-channel Gamma-hat law (48), the
//! transpose of (46) (Delta F-hat' = gamma nu_2 F_Aᵀ - beta (Delta F-hat - I)), and the auxiliary
//! systems (35), (50), which as printed are frozen at E = 0 (D10).
//!
//! The `unconstrained` variant uses the same structure with C -> infinity (Remark 4): nu = z and the
//! barrier terms become linear, with its own gains.

use crate::blf::Barrier;
use crate::command_filter::CommandFilter;
use crate::fault_id::{FaultIdentifier, NominalBody, SATURATION_GUARD};
use crate::params::AgentParams;
use formation_config::kinematics::{rotational_drift, AttitudeTrig};
use formation_config::scenario::{AuxiliaryGains, Controller};
use formation_config::Variant;
use nalgebra::{Matrix3, Vector3};

/// Internal states of the attitude loop.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct AttitudeLoop {
    rate_filter: CommandFilter,
    /// Auxiliary state E_i1 (35).
    pub e1: Vector3<f64>,
    /// Auxiliary state E_i2 (50).
    pub e2: Vector3<f64>,
    /// Gamma-hat_i (diagonal) (48).
    pub gamma_hat: Vector3<f64>,
    /// delta-hat_i (47), N m.
    pub delta_hat: Vector3<f64>,
    /// D-hat_iA (49), rad/s².
    pub d_hat: f64,
    /// Delta F-hat_i (46).
    pub model_hat: Matrix3<f64>,
    /// Probe and identification of Gamma, delta (D16).
    pub identifier: FaultIdentifier,
    alpha_bar: f64,
}

/// What one evaluation of the attitude loop produced.
#[derive(Debug, Clone, Copy)]
pub struct AttitudeOutput {
    /// Torque command U_iAC (43), N m.
    pub torque: Vector3<f64>,
    /// z_i1.
    pub z1: Vector3<f64>,
    /// z_i2.
    pub z2: Vector3<f64>,
    /// Filtered alpha_i.
    pub alpha: Vector3<f64>,
    /// V_i1B.
    pub blf1: f64,
    /// V_i2B.
    pub blf2: f64,
    /// C_i1.
    pub c1: f64,
    /// C_i2.
    pub c2: f64,
}

impl AttitudeLoop {
    /// Initial states of agent `p` (Gamma-hat = gamma_hat_initial, delta-hat = delta_hat_initial,
    /// Delta F-hat = I, E = 0, alpha filter at rest).
    pub fn new(p: &AgentParams) -> AttitudeLoop {
        let ad = &p.gains.adaptive;
        let f = &p.gains.rate_command_filter;
        let m = f.magnitude_limit;
        AttitudeLoop {
            rate_filter: CommandFilter::new(f, [0.0; 3]),
            e1: Vector3::zeros(),
            e2: Vector3::zeros(),
            gamma_hat: Vector3::repeat(ad.gamma_hat_initial),
            delta_hat: Vector3::repeat(ad.delta_hat_initial),
            d_hat: ad.disturbance_hat_initial,
            model_hat: Matrix3::identity(),
            identifier: FaultIdentifier::new(&p.gains.fault_identification, p.dt),
            alpha_bar: (m[0] * m[0] + m[1] * m[1] + m[2] * m[2]).sqrt(),
        }
    }

    /// Re-synchronises the loop to a vehicle flying at body rate `w` (a controller taking over from
    /// the failsafe): the rate command filter at rest at `w`, the auxiliary systems E_i1, E_i2 at 0
    /// (they integrate the saturation excess of commands this controller did not fly). The
    /// adaptive estimates and the fault identifier are kept.
    pub fn resync(&mut self, w: &Vector3<f64>) {
        self.rate_filter.reset((*w).into());
        self.e1 = Vector3::zeros();
        self.e2 = Vector3::zeros();
    }

    /// Computes U_iAC of step `step` for the attitude `a`, rate `w`, filtered attitude command `a_c` and
    /// its derivative `a_c_dot`, then advances every internal state by `dt`.
    pub fn step(
        &mut self,
        p: &AgentParams,
        step: u64,
        a: &Vector3<f64>,
        w: &Vector3<f64>,
        a_c: &Vector3<f64>,
        a_c_dot: &Vector3<f64>,
    ) -> AttitudeOutput {
        let g = &p.gains;
        let dt = p.dt;
        let unconstrained = p.variant == Variant::Unconstrained;
        let j = Vector3::from(p.inertia);
        let j_inv = j.map(|x| 1.0 / x);
        let trig = AttitudeTrig::of(a);
        let r_r = trig.euler_rate_matrix();
        let r_r_inv = trig.euler_rate_matrix_inverse();

        // ---- Step 1: attitude error and virtual control alpha_iC (34).
        let z1 = a - a_c;
        let c1 = g.attitude.attitude_margin_rad;
        let k1c = g.attitude.eps1_c.sqrt(); // C_i1 constant: K_i1C = sqrt((C'/C)² + eps) = sqrt(eps)
        let b1 = Barrier::at(&z1, if unconstrained { f64::INFINITY } else { c1 });
        let k1 = g.attitude.k1_alpha;
        let inner1 = if unconstrained {
            -g.unconstrained.attitude_gain * z1 + k1 * self.e1 + a_c_dot
        } else {
            -k1 * b1.sincos_term + k1 * self.e1 - k1c * z1 + a_c_dot - (0.5 * k1 * k1) * b1.nu
        };
        let alpha_c = r_r_inv * inner1;

        // ---- Step 2: rate error against the filtered alpha_i and control Phi_i (45).
        let alpha = Vector3::from(self.rate_filter.value());
        let alpha_dot = Vector3::from(self.rate_filter.derivative());
        let z2 = w - alpha;
        let c2 = g.attitude.rate_limit_rad_s - self.alpha_bar;
        let k2c = g.attitude.eps2_c.sqrt();
        let b2 = Barrier::at(&z2, if unconstrained { f64::INFINITY } else { c2 });
        let k2 = g.attitude.k2_phi;
        let drift = rotational_drift(&j, &Vector3::from(p.drag), w);
        let mu2 = g.attitude.mu2;
        let tanh_nu2 = b2.nu.map(|x| (x / mu2).tanh());
        let inner2 = if unconstrained {
            -g.unconstrained.rate_gain * z2 - r_r.transpose() * b1.nu + alpha_dot
                - self.model_hat * drift
                + k2 * self.e2
                - self.d_hat * tanh_nu2
        } else {
            -k2c * z2 - b2.cos_sq * (r_r.transpose() * b1.nu) + alpha_dot
                - self.model_hat * drift
                - (0.5 * k2 * k2) * b2.nu
                + k2 * self.e2
                - self.d_hat * tanh_nu2
                - k2 * b2.sincos_term
        };
        let phi = -self.delta_hat + j.component_mul(&inner2);
        // (43), plus the known probe of D16 (zero when identification is off).
        let unit_probe = self.identifier.unit_probe(step);
        let torque = phi.component_div(&self.gamma_hat) + self.identifier.probe_of(unit_probe);
        let lo = Vector3::from(p.torque_min);
        let hi = Vector3::from(p.torque_max);
        let expected = self.gamma_hat.component_mul(&torque) + self.delta_hat;
        let near_limit = (0..3).any(|k| {
            let mid = 0.5 * (hi[k] + lo[k]);
            (expected[k] - mid).abs() > SATURATION_GUARD * 0.5 * (hi[k] - lo[k])
        });
        let body = NominalBody {
            inertia: j,
            drag: Vector3::from(p.drag),
        };
        self.identifier
            .observe(w, &torque, unit_probe, near_limit, &body, dt);
        let s = Signals {
            j_inv,
            drift,
            nu1: b1.nu,
            nu2: b2.nu,
            tanh_nu2,
            torque,
            r_r,
            d_alpha: alpha - alpha_c,
            lo,
            hi,
        };
        self.adapt(g, &s, dt);
        self.advance_auxiliary(&g.auxiliary, &s, dt);

        // ---- Command filter of alpha_iC.
        self.rate_filter.advance(alpha_c.into(), dt);

        AttitudeOutput {
            torque,
            z1,
            z2,
            alpha,
            blf1: b1.value,
            blf2: b2.value,
            c1: if unconstrained { f64::INFINITY } else { c1 },
            c2: if unconstrained { f64::INFINITY } else { c2 },
        }
    }

    /// The adaptive laws (46)-(49) of one step of `dt`, explicit Euler, on the `s`ignals of the
    /// step, with the composite terms of D16 towards the fault identifier's values.
    fn adapt(&mut self, g: &Controller, s: &Signals, dt: f64) {
        let id = self.identifier.identified();
        let k_c = g.fault_identification.composite_rate;
        let ad = &g.adaptive;
        let (nu2, drift, j_inv, torque) = (s.nu2, s.drift, s.j_inv, s.torque);
        // (46), our transpose reading, leakage towards the nominal Delta F = I.
        self.model_hat += (ad.model_rate * nu2 * drift.transpose()
            - ad.model_leakage * (self.model_hat - Matrix3::identity()))
            * dt;
        // (47): J^-T nu_2 with J diagonal; + the composite term of D16 while the channel is excited.
        let pull = |valid: bool, target: f64, now: f64| {
            if valid {
                k_c * (target - now)
            } else {
                0.0
            }
        };
        let delta_pull = Vector3::from_fn(|k, _| pull(id.valid[k], id.delta[k], self.delta_hat[k]));
        self.delta_hat += (ad.delta_rate * j_inv.component_mul(&nu2)
            - ad.delta_leakage * self.delta_hat
            + delta_pull)
            * dt;
        // (48), per channel, with projection onto [Gamma_min, Gamma_max]; + the composite term of D16.
        for k in 0..3 {
            let chi = ad.gamma_rate * nu2[k] * j_inv[k] * torque[k]
                - ad.gamma_leakage * (self.gamma_hat[k] - ad.gamma_leakage_target)
                + pull(id.valid[k], id.gamma[k], self.gamma_hat[k]);
            let at_floor = self.gamma_hat[k] <= ad.gamma_min && chi < 0.0;
            let at_ceiling = self.gamma_hat[k] >= ad.gamma_max && chi > 0.0;
            if !(at_floor || at_ceiling) {
                self.gamma_hat[k] =
                    (self.gamma_hat[k] + chi * dt).clamp(ad.gamma_min, ad.gamma_max);
            }
        }
        // (49), D-hat kept non-negative (it estimates a bound).
        let d_drive = nu2.dot(&s.tanh_nu2);
        self.d_hat = (self.d_hat
            + ad.disturbance_rate * (d_drive - ad.disturbance_leakage * self.d_hat) * dt)
            .max(0.0);
    }

    /// The auxiliary systems (35), (50) of one step of `dt` in our reading (D10), on the `s`ignals
    /// of the step and the adaptive estimates already advanced.
    fn advance_auxiliary(&mut self, aux: &AuxiliaryGains, s: &Signals, dt: f64) {
        let (j_inv, nu2, torque, lo, hi) = (s.j_inv, s.nu2, s.torque, s.lo, s.hi);
        let d_alpha = s.d_alpha;
        let coupling1 = (s.nu1.transpose() * s.r_r * d_alpha)[0].abs();
        self.e1 = aux_step(
            self.e1,
            aux.k1_e,
            aux.gamma1_e,
            aux.e1_threshold,
            d_alpha,
            coupling1,
            dt,
        );
        let expected = self.gamma_hat.component_mul(&torque) + self.delta_hat;
        let residual = expected.zip_zip_map(&lo, &hi, |x, l, h| x.clamp(l, h)) - expected;
        let d_u = j_inv.component_mul(&residual);
        let coupling2 = nu2.dot(&d_u).abs();
        self.e2 = aux_step(
            self.e2,
            aux.k2_e,
            aux.gamma2_e,
            aux.e2_threshold,
            d_u,
            coupling2,
            dt,
        );
    }
}

/// The signals of one step of the attitude loop that its adaptive laws and auxiliary systems
/// integrate.
struct Signals {
    /// J_i^-1 (diagonal), 1/(kg m²).
    j_inv: Vector3<f64>,
    /// F_iA of the nominal model at the current rate, rad/s².
    drift: Vector3<f64>,
    /// nu_1 of the attitude barrier (31).
    nu1: Vector3<f64>,
    /// nu_2 of the rate barrier (40).
    nu2: Vector3<f64>,
    /// tanh(nu_2 / mu_2), per channel.
    tanh_nu2: Vector3<f64>,
    /// U_iAC, N m.
    torque: Vector3<f64>,
    /// R_r, the Euler rate matrix at the current attitude.
    r_r: Matrix3<f64>,
    /// alpha_i - alpha_iC, the command filter's lag, rad/s.
    d_alpha: Vector3<f64>,
    /// The lower torque limits, N m.
    lo: Vector3<f64>,
    /// The upper torque limits, N m.
    hi: Vector3<f64>,
}

/// One step of an auxiliary system (35)/(50) in our reading (D10): above the threshold
/// E' = -K_E E - kappa E + gamma_E d with kappa = (|coupling| + gamma_E² ||d||² / 2) / ||E||²; at or below
/// it the kappa term (singular at E = 0) is dropped, so that E can leave 0 when saturation occurs
/// (Remark 6). The decay is integrated exactly (exp), which keeps the step stable for any kappa.
fn aux_step(
    e: Vector3<f64>,
    k_e: f64,
    gamma_e: f64,
    threshold: f64,
    drive: Vector3<f64>,
    coupling: f64,
    dt: f64,
) -> Vector3<f64> {
    let n2 = e.norm_squared();
    let kappa = if n2.sqrt() > threshold {
        (coupling + 0.5 * gamma_e * gamma_e * drive.norm_squared()) / n2
    } else {
        0.0
    };
    e * (-(k_e + kappa) * dt).exp() + drive * (gamma_e * dt)
}
