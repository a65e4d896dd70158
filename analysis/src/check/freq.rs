//! Small linear-systems helpers: roots of s² + b s + c, poles and frequency response of the
//! second-order command filter, and the phase margin of a loop given by its frequency response.

use nalgebra::Complex;
use serde::Serialize;

/// A complex number as `[re, im]` (how roots are written to JSON).
pub type Pair = [f64; 2];

/// Roots of s² + b s + c, the one with the larger real part (the slower, for b > 0) first.
pub fn quadratic_roots(b: f64, c: f64) -> [Complex<f64>; 2] {
    let disc = b * b - 4.0 * c;
    if disc >= 0.0 {
        let r = disc.sqrt();
        [
            Complex::new((-b + r) / 2.0, 0.0),
            Complex::new((-b - r) / 2.0, 0.0),
        ]
    } else {
        let i = (-disc).sqrt() / 2.0;
        [Complex::new(-b / 2.0, i), Complex::new(-b / 2.0, -i)]
    }
}

/// `[re, im]` of a complex number.
pub fn pair(z: Complex<f64>) -> Pair {
    [z.re, z.im]
}

/// Poles of the command filter q1'' + 2 xi w q1' + w² q1 = w² u (Fig. 3, linear part).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FilterPoles {
    /// Natural frequency omega_B, rad/s.
    pub natural_frequency_rad_s: f64,
    /// Damping xi_B.
    pub damping: f64,
    /// Poles w (-xi ± sqrt(xi² - 1)) as [re, im], slowest first.
    pub poles: [Pair; 2],
    /// True when xi < 1 (complex pair; its speed is the natural frequency).
    pub complex: bool,
    /// Speed that limits the filter, rad/s: the slowest real pole's magnitude w (xi - sqrt(xi² - 1)),
    /// or the natural frequency w for a complex pair.
    pub slowest_rad_s: f64,
}

/// Poles of a command filter with natural frequency `w` and damping `xi`.
pub fn filter_poles(w: f64, xi: f64) -> FilterPoles {
    let roots = quadratic_roots(2.0 * xi * w, w * w);
    let complex = roots[0].im != 0.0;
    FilterPoles {
        natural_frequency_rad_s: w,
        damping: xi,
        poles: [pair(roots[0]), pair(roots[1])],
        complex,
        slowest_rad_s: if complex { w } else { roots[0].norm() },
    }
}

/// Frequency response w² / ((jω)² + 2 xi w jω + w²) of the command filter: (magnitude, phase in
/// radians, continuous in [-pi, 0]).
pub fn filter_response(w: f64, xi: f64, omega: f64) -> (f64, f64) {
    let re = w * w - omega * omega;
    let im = 2.0 * xi * w * omega;
    (w * w / re.hypot(im), -im.atan2(re))
}

/// The filter's response as a complex number.
pub fn filter_complex(w: f64, xi: f64, omega: f64) -> Complex<f64> {
    let (m, p) = filter_response(w, xi, omega);
    Complex::from_polar(m, p)
}

/// Crossover and phase margin of a loop.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Margin {
    /// Highest frequency where the loop gain crosses 1 downwards, rad/s.
    pub crossover_rad_s: f64,
    /// 180° + phase of the loop at the crossover, degrees (negative: unstable closed loop).
    pub phase_margin_deg: f64,
}

/// Phase margin of a loop whose response at ω is `(magnitude, unwrapped phase in radians)`:
/// scans ω over [1e-3, 1e4] rad/s, takes the highest downward crossing of |L| = 1 and refines it by
/// bisection. `None` when the gain never crosses 1 in that range.
pub fn phase_margin(loop_at: impl Fn(f64) -> (f64, f64)) -> Option<Margin> {
    const N: usize = 4000;
    let (lo, hi) = (-3.0f64, 4.0f64);
    let w = |k: usize| 10f64.powf(lo + (hi - lo) * k as f64 / N as f64);
    let mut found = None;
    for k in 0..N {
        let (m0, _) = loop_at(w(k));
        let (m1, _) = loop_at(w(k + 1));
        if m0 >= 1.0 && m1 < 1.0 {
            found = Some((w(k), w(k + 1)));
        }
    }
    let (mut a, mut b) = found?;
    for _ in 0..60 {
        let mid = (a * b).sqrt();
        if loop_at(mid).0 >= 1.0 {
            a = mid;
        } else {
            b = mid;
        }
    }
    let wc = (a * b).sqrt();
    Some(Margin {
        crossover_rad_s: wc,
        phase_margin_deg: 180.0 + loop_at(wc).1.to_degrees(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn roots_of_known_polynomials() {
        // s² + 3 s + 2 = (s + 1)(s + 2).
        let r = quadratic_roots(3.0, 2.0);
        assert!((r[0].re + 1.0).abs() < 1e-12 && r[0].im == 0.0);
        assert!((r[1].re + 2.0).abs() < 1e-12);
        // s² + 2 s + 5: -1 ± 2j.
        let r = quadratic_roots(2.0, 5.0);
        assert!((r[0] - Complex::new(-1.0, 2.0)).norm() < 1e-12);
        assert!((r[1] - Complex::new(-1.0, -2.0)).norm() < 1e-12);
    }

    #[test]
    fn paper_filter_has_a_slow_pole_near_7_7_rad_s() {
        let f = filter_poles(22.0, 1.6);
        assert!(!f.complex);
        let slow = 22.0 * (1.6 - (1.6f64 * 1.6 - 1.0).sqrt());
        assert!((f.slowest_rad_s - slow).abs() < 1e-9);
        assert!((f.slowest_rad_s - 7.72).abs() < 0.01);
    }

    #[test]
    fn underdamped_filter_reports_its_natural_frequency() {
        let f = filter_poles(10.0, 0.5);
        assert!(f.complex);
        assert_eq!(f.slowest_rad_s, 10.0);
        assert!((f.poles[0][0] + 5.0).abs() < 1e-12);
    }

    #[test]
    fn filter_response_at_its_natural_frequency_lags_ninety_degrees() {
        let (m, p) = filter_response(10.0, 0.7, 10.0);
        assert!((m - 1.0 / 1.4).abs() < 1e-12);
        assert!((p.to_degrees() + 90.0).abs() < 1e-9);
    }

    #[test]
    fn integrator_with_delay_has_the_textbook_margin() {
        // L = K e^{-s tau} / s: crossover K, margin 90° - K tau.
        let (k, tau) = (5.0, 0.1);
        let m = phase_margin(|w| (k / w, -std::f64::consts::FRAC_PI_2 - w * tau)).unwrap();
        assert!((m.crossover_rad_s - k).abs() < 1e-6);
        assert!((m.phase_margin_deg - (90.0 - (k * tau).to_degrees())).abs() < 1e-4);
    }

    #[test]
    fn a_loop_below_unity_gain_has_no_margin() {
        assert!(phase_margin(|_| (0.5, 0.0)).is_none());
    }
}
