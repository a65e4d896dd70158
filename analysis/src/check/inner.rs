//! Inner loops near z = 0 and the time-scale separation of the cascade.
//!
//! BLF attitude law (34): with x = pi z^T z / (2 C²), sin x cos x -> x, so
//! -K1α z/(z^T z) (C²/pi) sin x cos x -> -K1α z / 2, and -K1α²/2 ν -> -K1α²/2 z (ν -> z): the
//! proportional gain is K1α/2 + K1α²/2 + K1C with K1C = sqrt(eps1_c) for a constant constraint. The
//! rate law (45) gives K2Φ/2 + K2Φ²/2 + sqrt(eps2_c) the same way. The `unconstrained` variant uses
//! its gains directly.
//!
//! Linear model of the cascade (small signals, hover, ideal rate loop — with the α' feed-forward of
//! (45) the rate error z2 decays on its own and Ω follows the filtered α exactly):
//! A = T_att A_C with T_att = F2 (s + K_att) / (s + F2 K_att), F2 the rate command filter; the
//! consensus mode lambda closes through L(s) = lambda (k_V s + k_P) / s² e^{-s tau_M} F1(s) T_att(s),
//! F1 the attitude command filter (U_iP -> tilt -> acceleration has unit gain near hover).

use super::freq::{filter_complex, filter_response, phase_margin, Margin};
use nalgebra::Complex;
use serde::Serialize;

/// A second-order command filter's (omega_B, xi_B).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Filter {
    /// Natural frequency, rad/s.
    pub w: f64,
    /// Damping.
    pub xi: f64,
}

/// Attitude-loop proportional gain of the BLF law (34) near z1 = 0, 1/s.
pub fn blf_attitude_gain(k1_alpha: f64, eps1_c: f64) -> f64 {
    k1_alpha / 2.0 + k1_alpha * k1_alpha / 2.0 + eps1_c.sqrt()
}

/// Rate-loop proportional gain of the BLF law (45) near z2 = 0, 1/s.
pub fn blf_rate_gain(k2_phi: f64, eps2_c: f64) -> f64 {
    k2_phi / 2.0 + k2_phi * k2_phi / 2.0 + eps2_c.sqrt()
}

/// Attitude open loop K_att F2(s) / s: (magnitude, phase).
pub fn attitude_loop(k_att: f64, f2: Filter, w: f64) -> (f64, f64) {
    let (m, p) = filter_response(f2.w, f2.xi, w);
    (k_att * m / w, p - std::f64::consts::FRAC_PI_2)
}

/// Closed attitude loop T_att(jω) = F2 (jω + K) / (jω + F2 K).
pub fn attitude_closed(k_att: f64, f2: Filter, w: f64) -> Complex<f64> {
    let f = filter_complex(f2.w, f2.xi, w);
    let s = Complex::new(0.0, w);
    f * (s + k_att) / (s + f * k_att)
}

/// Consensus mode lambda through the delay only: (magnitude, phase).
pub fn outer_loop_delay_only(lambda: f64, k_p: f64, k_v: f64, tau: f64, w: f64) -> (f64, f64) {
    let mag = lambda * (k_v * w).hypot(k_p) / (w * w);
    let phase = (k_v * w).atan2(k_p) - std::f64::consts::PI - w * tau;
    (mag, phase)
}

/// Consensus mode lambda through delay, command filter 1 and the closed attitude loop.
pub fn outer_loop_cascade(
    lambda: f64,
    (k_p, k_v, tau): (f64, f64, f64),
    f1: Filter,
    f2: Filter,
    k_att: f64,
    w: f64,
) -> (f64, f64) {
    let (m0, p0) = outer_loop_delay_only(lambda, k_p, k_v, tau, w);
    let (m1, p1) = filter_response(f1.w, f1.xi, w);
    let t = attitude_closed(k_att, f2, w);
    (m0 * m1 * t.norm(), p0 + p1 + t.arg())
}

/// Inner-loop numbers of one gain set.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct InnerLoop {
    /// `constrained` (BLF-AFTAC) or `unconstrained`.
    pub gain_set: &'static str,
    /// How the gains were obtained.
    pub rule: &'static str,
    /// Attitude-loop proportional gain, 1/s.
    pub attitude_gain: f64,
    /// Rate-loop proportional gain, 1/s.
    pub rate_gain: f64,
    /// attitude_gain / fastest outer mode.
    pub attitude_over_fastest_outer: f64,
    /// rate_gain / attitude_gain.
    pub rate_over_attitude: f64,
    /// Rate filter's slowest pole / rate_gain.
    pub rate_filter_over_rate: f64,
    /// Rate filter's slowest pole / attitude_gain (the rate filter sits inside the attitude loop).
    pub rate_filter_over_attitude: f64,
    /// Margin of the attitude loop K_att F2(s)/s; `null` if it never crosses unity gain.
    pub attitude_loop: Option<Margin>,
    /// Margin of the fastest consensus mode through delay, filter 1 and the attitude loop.
    pub cascade: Option<Margin>,
}

/// Shared inputs of the inner-loop analysis.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CascadeInputs {
    /// Largest eigenvalue of L + B.
    pub lambda_max: f64,
    /// Fastest outer root, rad/s.
    pub fastest_outer_rad_s: f64,
    /// (k_P, k_V, tau_M).
    pub outer: (f64, f64, f64),
    /// Command filter 1 (attitude command).
    pub f1: Filter,
    /// Rate command filter.
    pub f2: Filter,
    /// Slowest pole of the rate filter, rad/s.
    pub rate_filter_slowest_rad_s: f64,
}

/// The linear model behind the margins (printed in the report).
pub const CASCADE_MODEL: &str = "small signals near hover, BLF gains linearised at z = 0, ideal rate loop (alpha' feed-forward), \
the AFTAC tracks the output of command filter 1; L(s) = lambda_max (k_V s + k_P)/s^2 e^{-s tau_M} F1(s) T_att(s), \
T_att = F2 (s + K_att)/(s + F2 K_att); saturation, barrier, RBFNN and tilt limits ignored";

/// Rule printed for the constrained gains.
pub const BLF_RULE: &str = "K_att = K1a/2 + K1a^2/2 + sqrt(eps1_c), K_rate = K2Phi/2 + K2Phi^2/2 + sqrt(eps2_c) (BLF laws (34), (45) near z = 0)";
/// Rule printed for the unconstrained gains.
pub const UNCONSTRAINED_RULE: &str =
    "controller.unconstrained.attitude_gain and rate_gain as given";

/// Analyses one gain set.
pub fn analyse(
    gain_set: &'static str,
    rule: &'static str,
    attitude_gain: f64,
    rate_gain: f64,
    c: &CascadeInputs,
) -> InnerLoop {
    InnerLoop {
        gain_set,
        rule,
        attitude_gain,
        rate_gain,
        attitude_over_fastest_outer: attitude_gain / c.fastest_outer_rad_s,
        rate_over_attitude: rate_gain / attitude_gain,
        rate_filter_over_rate: c.rate_filter_slowest_rad_s / rate_gain,
        rate_filter_over_attitude: c.rate_filter_slowest_rad_s / attitude_gain,
        attitude_loop: phase_margin(|w| attitude_loop(attitude_gain, c.f2, w)),
        cascade: phase_margin(|w| {
            outer_loop_cascade(c.lambda_max, c.outer, c.f1, c.f2, attitude_gain, w)
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn printed_blf_gains_are_about_9_7_per_second() {
        let k = blf_attitude_gain(3.9, 0.01);
        assert!((k - (1.95 + 7.605 + 0.1)).abs() < 1e-12);
        assert_eq!(blf_rate_gain(3.9, 0.01), k);
    }

    #[test]
    fn an_ideal_rate_filter_gives_perfect_attitude_tracking() {
        let f2 = Filter { w: 1e6, xi: 1.0 };
        let t = attitude_closed(5.0, f2, 3.0);
        assert!((t - Complex::new(1.0, 0.0)).norm() < 1e-4);
    }

    #[test]
    fn delay_only_margin_matches_the_closed_form() {
        // Crossover of lambda (k_V s + k_P)/s² solves w^4 = lambda² (k_V² w² + k_P²).
        let (l, kp, kv, tau) = (2.0, 1.0, 2.0, 0.05);
        let m = phase_margin(|w| outer_loop_delay_only(l, kp, kv, tau, w)).unwrap();
        let b = (l * kv).powi(2);
        let w2 = (b + (b * b + 4.0 * (l * kp).powi(2)).sqrt()) / 2.0;
        let wc = w2.sqrt();
        assert!((m.crossover_rad_s - wc).abs() < 1e-6);
        let pm = ((kv * wc).atan2(kp) - wc * tau).to_degrees();
        assert!((m.phase_margin_deg - pm).abs() < 1e-4);
    }
}
