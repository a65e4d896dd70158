//! Reference shaping (ours, docs/deviations.md D26): the formation's transitions capped to what
//! the vehicles can fly.
//!
//! Each transition of the mission is a smooth step atan(k (t - T)) / pi + 1/2 of sharpness k: the
//! radius change at T1 (amplitude dR = |R_c - R_e|), the spin onset at T2 (ring radius R, spin
//! rate w) and the descent at T3 (amplitude h). With q = k (t - T), the slot's acceleration and
//! jerk from each are at most
//!
//! ```text
//! radius, descent:  |A''| <= 9 / (8 sqrt(3) pi) k² dR = 0.2067 k² dR     (at q = 1/sqrt(3))
//!                   |A'''| <= 2 / pi k³ dR = 0.6366 k³ dR                  (at q = 0)
//! spin (R theta):   |R theta''| <= 2 / pi R w k                             (at q = 0)
//!                   |R theta'''| + |2 R theta' theta''| <= R w (0.6591 k² + 1.477 w k)
//! ```
//!
//! (theta = w f(t) (t - T2); theta''' peaks at q² = 1/5; theta' <= 1.16 w.) Sharpness 5 on a 1 m
//! radius change asks 5.2 m/s² and 80 m/s³, where the attitude command filter's rate limit lets
//! a quadrotor change its acceleration by about g x 0.47 rad/s = 4.6 m/s³: it keeps accelerating
//! the old way for most of a second, overshoots by a metre and crosses its neighbours' paths.
//! The leader therefore flies each transition with the largest sharpness whose bounds are within
//! a_R and j_R (`mission.shaping`); one that already is keeps its own, bit for bit. The cap is
//! the same for every slot, so the formation keeps its geometry through the change (every
//! quadrotor on the same ring, equally spaced), and it is a function of the scenario alone, so
//! every process of a run computes the same mission.

use std::f64::consts::PI;

/// Peak acceleration and jerk of a slot along a smooth step of sharpness `k` (1/s) and amplitude
/// `amplitude` (m): the radius change and the descent.
pub fn step_bounds(k: f64, amplitude: f64) -> (f64, f64) {
    let a = 9.0 / (8.0 * 3f64.sqrt() * PI) * k * k * amplitude.abs();
    let j = 2.0 / PI * k * k * k * amplitude.abs();
    (a, j)
}

/// Peak tangential acceleration and jerk of a slot on a ring of radius `radius` (m) whose spin
/// rate `rate` (rad/s) sets in along a smooth step of sharpness `k` (1/s).
pub fn spin_bounds(k: f64, radius: f64, rate: f64) -> (f64, f64) {
    let rw = (radius * rate).abs();
    let a = 2.0 / PI * rw * k;
    let j = rw * (0.6591 * k * k + 1.477 * rate.abs() * k);
    (a, j)
}

/// The largest sharpness in [0, `k`] whose peak acceleration and jerk (`bounds`, increasing in
/// the sharpness) stay within `accel` and `jerk`: `k` itself when it already does.
pub fn cap(k: f64, bounds: impl Fn(f64) -> (f64, f64), accel: f64, jerk: f64) -> f64 {
    let within = |k: f64| {
        let (a, j) = bounds(k);
        a <= accel && j <= jerk
    };
    if within(k) {
        return k;
    }
    let (mut lo, mut hi) = (0.0, k);
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if within(mid) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    lo
}

/// One transition of the mission: the sharpness it is written with, the one it is flown with,
/// and what each asks of a slot.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Transition {
    /// Its name: `radius`, `spin` or `descent`.
    pub name: &'static str,
    /// The scenario's sharpness, 1/s.
    pub written: f64,
    /// The sharpness flown, 1/s (the written one when shaping is off or it is within the limits).
    pub flown: f64,
    /// Peak acceleration and jerk of a slot at the written sharpness, m/s² and m/s³.
    pub asked: (f64, f64),
    /// The same at the flown sharpness.
    pub flies: (f64, f64),
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The closed-form peaks equal the sampled ones of the atan step and of the spin angle.
    #[test]
    fn the_bounds_are_the_peaks_of_the_transitions() {
        let (k, amp) = (5.0, 1.0);
        let (a, j) = step_bounds(k, amp);
        let (mut pa, mut pj) = (0.0_f64, 0.0_f64);
        for i in -200_000..200_000 {
            let q = i as f64 * 1e-4;
            let den = 1.0 + q * q;
            pa = pa.max((2.0 * k * k * q / (PI * den * den)).abs());
            pj = pj.max((2.0 * k.powi(3) * (3.0 * q * q - 1.0) / (PI * den.powi(3))).abs());
        }
        assert!(
            (a - pa).abs() < 1e-6 * pa && (j - pj).abs() < 1e-6 * pj,
            "{a} {pa} {j} {pj}"
        );
        // The issue's figures: sharpness 5 on a 1 m change asks 5.2 m/s² and 80 m/s³.
        assert!((a - 5.17).abs() < 0.01 && (j - 79.6).abs() < 0.1);
        // Spin: theta'' peak 2 w k / pi, theta''' peak 0.6591 w k².
        let (k, w) = (50.0, 0.8);
        let (mut p2, mut p3) = (0.0_f64, 0.0_f64);
        for i in -100_000..100_000 {
            let q = i as f64 * 1e-4;
            let den = 1.0 + q * q;
            p2 = p2.max(2.0 * w * k / (PI * den * den));
            p3 = p3.max((2.0 * w * k * k / PI * 4.0 * q / den.powi(3)).abs());
        }
        let (sa, _) = spin_bounds(k, 1.0, w);
        assert!((sa - p2).abs() < 1e-9 * p2);
        assert!((0.6591 * w * k * k - p3).abs() < 1e-3 * p3, "{p3}");
    }

    #[test]
    fn a_transition_within_the_limits_keeps_its_sharpness_and_a_sharp_one_is_capped() {
        let b = |k| step_bounds(k, 1.0);
        assert_eq!(cap(1.0, b, 2.0, 2.5), 1.0);
        let k = cap(5.0, b, 2.0, 2.5);
        let (a, j) = b(k);
        assert!(
            k < 5.0 && a <= 2.0 && j <= 2.5 && j > 2.5 * 0.999_999,
            "{k} {a} {j}"
        );
    }
}
