//! Concentric rings: the formation of N quadrotors when one ring cannot be both spaced and covering.
//!
//! One ring of N slots needs the radius R_s(N) = s_min / (2 sin(pi/N)) to keep neighbours s_min
//! apart, and N footprints of radius r_f cover the target's centre only for R <= r_f; beyond
//! N = 12 (paper geometry: s_min = 1.176 m, r_f = 2.33 m) both cannot hold. The generator then flies
//! concentric rings (`[[mission.formation.rings]]`, D22):
//!
//! * ring 0 is the template's ring: its N_0 (5) agents at the template's radii R_c,0 and R_e,0 (2.0 m
//!   and 1.0 m), which cover the target disk as in the paper;
//! * ring j >= 1 lies a gap g = s_min (rounded up to the millimetre) outside ring j - 1 in both
//!   phases: R_c,j = R_c,j-1 + g, R_e,j = R_e,j-1 + g;
//! * ring j holds up to its capacity n_max(R) = floor(pi / asin(s_min / (2 R))) at its smaller radius
//!   R = min(R_c,j, R_e,j), filled from the inside out; a last ring is never left with a single
//!   agent (one is moved out from the ring before it), so every ring is balanced about the centre;
//! * every ring's radius moves from R_c,j to R_e,j with the one transition of A_t, so two rings stay
//!   exactly g apart throughout, and all slots spin with the one w_t: no two slots come closer than
//!   s_min at any time;
//! * spin rate: w_0(N) = w_0^tpl min(1, R_e^tpl / R_e,outer), the tangential speed of the outer ring
//!   is the template's (0.8 m/s).
//!
//! For the default s_min, N = 20 flies 5 + 11 + 4 agents (outer ring 4.352 m covering, 3.352 m
//! enclosing) and N = 100 six rings of 5, 11, 17, 24, 30 and 13 (outer ring 7.880 / 6.880 m).

use formation_config::scenario::FormationRing;
use std::f64::consts::PI;

/// The largest number of slots a ring of radius `radius` holds with neighbours at least `s_min`
/// apart (at least 1).
pub fn ring_capacity(radius: f64, s_min: f64) -> usize {
    // Written so that a NaN radius also gives 1.
    if radius.is_nan() || radius <= 0.0 || 2.0 * radius < s_min {
        return 1;
    }
    let n = (PI / (s_min / (2.0 * radius)).asin()).floor();
    // floor(pi / asin(x)) can land one above the true capacity when pi / asin(x) is an integer
    // up to rounding: check it.
    let mut n = n.max(1.0) as usize;
    while n > 1 && 2.0 * radius * (PI / n as f64).sin() < s_min {
        n -= 1;
    }
    n
}

/// Whether one ring of the radii `r` leaves the target's centre uncovered: its spacing radius
/// R_s(N) lies beyond the footprint radius r_f (the upper end of the coverage interval).
pub fn one_ring_cannot_cover(r: &super::radii::Radii) -> bool {
    r.spacing_m > r.coverage_interval_m.1
}

/// `x` rounded up to the millimetre.
fn ceil_mm(x: f64) -> f64 {
    (x * 1000.0).ceil() / 1000.0
}

/// The rings of `n` agents: the inner ring of `inner` agents at `inner_cover_m` / `inner_enclose_m`,
/// then rings a gap of `s_min` (rounded up to the millimetre) apart, each filled to its capacity
/// (module documentation). Every ring starts at phase `phase_rad`.
pub fn concentric(
    n: usize,
    inner: usize,
    inner_cover_m: f64,
    inner_enclose_m: f64,
    s_min: f64,
    phase_rad: f64,
) -> Vec<FormationRing> {
    let gap = ceil_mm(s_min);
    let first = inner.min(n).max(1);
    let mut rings = vec![FormationRing {
        agents: first,
        cover_radius_m: inner_cover_m,
        enclose_radius_m: inner_enclose_m,
        phase_rad,
    }];
    let mut left = n - first;
    while left > 0 {
        let prev = &rings[rings.len() - 1];
        let (c, e) = (prev.cover_radius_m + gap, prev.enclose_radius_m + gap);
        let mut take = ring_capacity(c.min(e), s_min).min(left);
        if left - take == 1 && take > 2 {
            take -= 1; // the next (last) ring gets two agents, not one
        }
        rings.push(FormationRing {
            agents: take,
            cover_radius_m: (c * 1000.0).round() / 1000.0,
            enclose_radius_m: (e * 1000.0).round() / 1000.0,
            phase_rad,
        });
        left -= take;
    }
    rings
}

/// The enclosing spin rate for an outer enclose radius `outer_enclose_m`: the template's rate
/// `template_spin_rad_s`, slowed so that the outer ring's tangential speed stays the template's.
pub fn spin_rate(template_spin_rad_s: f64, template_enclose_m: f64, outer_enclose_m: f64) -> f64 {
    if outer_enclose_m > template_enclose_m {
        template_spin_rad_s * template_enclose_m / outer_enclose_m
    } else {
        template_spin_rad_s
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenario_gen::tests::min_distance;
    use formation_runtime::record::coverage::CoverageGrid;

    const S_MIN: f64 = 1.1755705045849463; // 2 sin(pi/5): the paper's enclosing spacing

    /// Slots of every agent at transition level `s` (1: covering, 0: enclosing) and spin `angle`.
    fn slots(rings: &[FormationRing], s: f64, angle: f64) -> Vec<[f64; 2]> {
        let mut out = Vec::new();
        for r in rings {
            let a = r.enclose_radius_m + (r.cover_radius_m - r.enclose_radius_m) * s;
            for k in 0..r.agents {
                let phi = r.phase_rad + angle + 2.0 * PI * k as f64 / r.agents as f64;
                out.push([a * phi.cos(), a * phi.sin()]);
            }
        }
        out
    }

    #[test]
    fn capacity_is_the_largest_ring_that_keeps_the_spacing() {
        for r in [0.3, 0.6, 1.0, 2.176, 3.352, 6.88, 18.7] {
            let n = ring_capacity(r, S_MIN);
            if n > 1 {
                assert!(2.0 * r * (PI / n as f64).sin() >= S_MIN, "r = {r}, n = {n}");
            }
            assert!(
                2.0 * r * (PI / (n + 1) as f64).sin() < S_MIN,
                "r = {r}, n = {n}"
            );
        }
        assert_eq!(ring_capacity(1.0, S_MIN), 5); // the paper's enclosing ring, exactly full
    }

    #[test]
    fn rings_hold_every_agent_and_keep_the_minimum_spacing_throughout_the_transition() {
        // From N = 13 on, one ring cannot both keep s_min and cover (the generator's rule).
        for n in 13..=128 {
            let rings = concentric(n, 5, 2.0, 1.0, S_MIN, 0.5 * PI);
            assert_eq!(rings.iter().map(|r| r.agents).sum::<usize>(), n, "n = {n}");
            assert!(rings.iter().all(|r| r.agents >= 2), "n = {n}: {rings:?}");
            for s in [1.0, 0.9, 0.5, 0.1, 0.0] {
                for angle in [0.0, 0.7] {
                    let d = min_distance(&slots(&rings, s, angle));
                    assert!(d >= S_MIN - 1e-9, "n = {n}, s = {s}: slots {d} m apart");
                }
            }
        }
    }

    #[test]
    fn the_inner_ring_alone_covers_the_target_disk_at_the_cruise_altitude() {
        // Paper geometry: 3.5 m disk, 50 degree camera at 5 m (footprint radius 2.33 m).
        let mut grid = CoverageGrid::new(3.5, 50.0);
        for n in [20, 50, 100, 128] {
            let rings = concentric(n, 5, 2.0, 1.0, S_MIN, 0.5 * PI);
            let inner: Vec<[f64; 3]> = slots(&rings[..1], 1.0, 0.3)
                .into_iter()
                .map(|p| [p[0], p[1], 5.0])
                .collect();
            let f = grid.covered_fraction([0.0, 0.0], inner.iter().copied());
            assert!(f > 0.999, "n = {n}: inner ring covers {f}");
        }
    }

    #[test]
    fn a_hundred_agents_fly_six_rings_with_the_outer_ring_at_6_88_m_enclosing() {
        let rings = concentric(100, 5, 2.0, 1.0, S_MIN, 0.0);
        let counts: Vec<usize> = rings.iter().map(|r| r.agents).collect();
        assert_eq!(counts, vec![5, 11, 17, 24, 30, 13]);
        let outer = rings.last().unwrap();
        assert!((outer.enclose_radius_m - 6.88).abs() < 1e-9, "{outer:?}");
        assert!((outer.cover_radius_m - 7.88).abs() < 1e-9, "{outer:?}");
        let w = spin_rate(0.8, 1.0, outer.enclose_radius_m);
        assert!((w * outer.enclose_radius_m - 0.8).abs() < 1e-12);
    }
}
