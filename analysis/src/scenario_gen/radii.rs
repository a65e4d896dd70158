//! Formation radii for N quadrotors: the cover radius R_c(N), the enclose radius R_e(N) and the spin
//! rate of the enclosing phase, from N, a minimum neighbour spacing s_min and the coverage geometry.
//!
//! Both phases fly one ring (the formation function Lambda_i of the paper), so ring neighbours are
//! 2 R sin(pi/N) apart. With s_min the smallest distance allowed between two slots:
//!
//! * spacing radius: R_s(N) = s_min / (2 sin(pi/N)), the tightest ring that keeps s_min;
//! * footprint radius at the cruise altitude h: r_f = h tan(theta_S / 2) (2.33 m in the paper case);
//! * coverage interval: N footprints of radius r_f on a ring of radius R cover the target disk of
//!   radius R_T iff R <= r_f (the centre) and the outer intersection of neighbouring footprints,
//!   R cos(pi/N) + sqrt(r_f² - R² sin²(pi/N)), reaches R_T, i.e.
//!   R >= R_lo(N) = R_T cos(pi/N) - sqrt(r_f² - R_T² sin²(pi/N)).
//!   The interval [R_lo, r_f] is not empty iff 2 r_f cos(pi/N) >= R_T (N >= 5 in the paper case:
//!   [1.74, 2.33] m at N = 5); when it is empty, R_lo = r_f (the ring that reaches farthest while
//!   still covering the centre);
//! * enclose radius: R_e(N) = R_s(N): enclosing is as tight as the spacing allows;
//! * cover radius: R_c(N) = max(R_s(N), clamp(R_c^tpl, R_lo(N), r_f)): the template's cover radius
//!   moved into the coverage interval, then widened to the spacing radius when that is larger
//!   (spacing wins over coverage: beyond N = 12 in the paper case the ring cannot cover the centre
//!   of the disk at 5 m, and `coverage_fraction` in `summary.json` says how much is lost);
//! * spin rate: w_0(N) = w_0^tpl min(1, R_e^tpl / R_e(N)): the tangential speed of the enclosing
//!   spin stays the template's (0.8 m/s), so its centripetal acceleration w_0² R_e falls with N
//!   instead of exceeding the acceleration limit (at N = 50 the template's rate would need 6 m/s²).
//!
//! The default s_min is the spacing of the template's enclosing ring, 2 R_e^tpl sin(pi/N_tpl)
//! (1.176 m for the paper scenario), so that N = 5 gives exactly the paper scenario's radii
//! (R_c = 2.0 m, R_e = 1.0 m) and spin rate. Radii are rounded to the millimetre.

use std::f64::consts::PI;

/// What the formula needs from the template scenario and the user.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RadiiInputs {
    /// Number of quadrotors N (>= 2).
    pub n: usize,
    /// Minimum distance between two formation slots s_min, m.
    pub min_spacing_m: f64,
    /// Radius R_T of the target disk to cover, m.
    pub target_radius_m: f64,
    /// Footprint radius r_f at the cruise altitude, m.
    pub footprint_radius_m: f64,
    /// The template's cover radius R_c^tpl, m.
    pub template_cover_m: f64,
    /// The template's enclose radius R_e^tpl, m.
    pub template_enclose_m: f64,
    /// The template's enclosing spin rate w_0^tpl, rad/s.
    pub template_spin_rad_s: f64,
}

/// The result of the formula.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Radii {
    /// R_c(N), m.
    pub cover_m: f64,
    /// R_e(N), m.
    pub enclose_m: f64,
    /// w_0(N), rad/s.
    pub spin_rad_s: f64,
    /// R_s(N), m.
    pub spacing_m: f64,
    /// Coverage interval [R_lo(N), r_f], m.
    pub coverage_interval_m: (f64, f64),
}

/// The spacing of a ring of `n` slots of radius `r`: 2 r sin(pi/n), m.
pub fn ring_spacing(n: usize, r: f64) -> f64 {
    2.0 * r * (PI / n as f64).sin()
}

/// R_s(N) = s_min / (2 sin(pi/N)), m.
pub fn spacing_radius(n: usize, s_min: f64) -> f64 {
    s_min / (2.0 * (PI / n as f64).sin())
}

/// Lower end R_lo(N) of the coverage interval (r_f when the interval is empty), m.
pub fn coverage_lower(n: usize, r_t: f64, r_f: f64) -> f64 {
    let (s, c) = (PI / n as f64).sin_cos();
    if 2.0 * r_f * c < r_t {
        return r_f;
    }
    let disc = r_f * r_f - r_t * r_t * s * s;
    (r_t * c - disc.max(0.0).sqrt()).clamp(0.0, r_f)
}

fn mm(x: f64) -> f64 {
    (x * 1000.0).round() / 1000.0
}

/// Applies the formula (module documentation).
pub fn radii(i: &RadiiInputs) -> Radii {
    let spacing = spacing_radius(i.n, i.min_spacing_m);
    let lo = coverage_lower(i.n, i.target_radius_m, i.footprint_radius_m);
    let hi = i.footprint_radius_m;
    let enclose = mm(spacing);
    let cover = mm(spacing.max(i.template_cover_m.clamp(lo, hi.max(lo))));
    let spin = if enclose > i.template_enclose_m {
        i.template_spin_rad_s * i.template_enclose_m / enclose
    } else {
        i.template_spin_rad_s
    };
    Radii {
        cover_m: cover,
        enclose_m: enclose,
        spin_rad_s: spin,
        spacing_m: spacing,
        coverage_interval_m: (lo, hi),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn paper_inputs(n: usize) -> RadiiInputs {
        RadiiInputs {
            n,
            min_spacing_m: ring_spacing(5, 1.0),
            target_radius_m: 3.5,
            footprint_radius_m: 5.0 * 25f64.to_radians().tan(),
            template_cover_m: 2.0,
            template_enclose_m: 1.0,
            template_spin_rad_s: 0.8,
        }
    }

    #[test]
    fn five_agents_give_exactly_the_paper_radii_and_spin() {
        let r = radii(&paper_inputs(5));
        assert_eq!(r.cover_m, 2.0);
        assert_eq!(r.enclose_m, 1.0);
        assert_eq!(r.spin_rad_s, 0.8);
        // The documented coverage interval of the paper case (docs/deviations.md, D2).
        assert!((r.coverage_interval_m.0 - 1.734).abs() < 1e-3, "{r:?}");
        assert!((r.coverage_interval_m.1 - 2.331).abs() < 1e-3, "{r:?}");
    }

    #[test]
    fn footprints_on_a_ring_at_the_coverage_lower_end_just_reach_the_target_edge() {
        for n in [5, 7, 12] {
            let (r_t, r_f) = (3.5, 2.3315);
            let lo = coverage_lower(n, r_t, r_f);
            let (s, c) = (PI / n as f64).sin_cos();
            let reach = lo * c + (r_f * r_f - lo * lo * s * s).sqrt();
            assert!((reach - r_t).abs() < 1e-9, "n = {n}: reach {reach}");
        }
        // Four footprints of 2.33 m cannot cover a 3.5 m disk: the interval is empty.
        assert_eq!(coverage_lower(4, 3.5, 2.3315), 2.3315);
    }

    #[test]
    fn radii_keep_neighbours_at_least_the_minimum_spacing_apart_for_every_n() {
        for n in 2..=128 {
            let i = paper_inputs(n);
            let r = radii(&i);
            let tol = 1e-3; // millimetre rounding
            assert!(
                ring_spacing(n, r.enclose_m) >= i.min_spacing_m - tol,
                "n = {n}"
            );
            assert!(
                ring_spacing(n, r.cover_m) >= i.min_spacing_m - tol,
                "n = {n}"
            );
            assert!(r.cover_m >= r.enclose_m, "n = {n}");
            // Tangential speed of the spin never exceeds the template's.
            assert!(r.spin_rad_s * r.enclose_m <= 0.8 * 1.0 + 1e-12, "n = {n}");
        }
    }
}
