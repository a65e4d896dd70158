//! Theorem 1: the matrix M of eq. (18), a search over the free constants (M1, M2), the printed ties
//! K_P = 4 M2 tau_M² k_V, K_V = 4 M2 tau_M² k_P, and necessary conditions that explain a failure.
//!
//! Reading of eq. (18): the paper prints M upper-triangular (the first row even lacks its fifth
//! entry) but calls it symmetric; we read it as the symmetric 5x5 matrix whose upper triangle is the
//! printed one, i.e. M43 = M34, M53 = M35, M54 = M45 are the mirrored off-diagonal terms. It acts on
//! e = [||e_P||, ||e_V||, ||Δe_P||, ||Δe_V||, ||W~||_F] of eq. (26).

use nalgebra::Matrix5;
use serde::Serialize;

/// Everything M depends on except the free constants M1, M2.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Theorem1Inputs {
    /// k_P of eq. (14) (`controller.position.k_p`).
    pub k_p: f64,
    /// k_V of eq. (14) (`controller.position.k_v`).
    pub k_v: f64,
    /// K_P of eq. (15) (`controller.position.nn_k_p`).
    pub nn_k_p: f64,
    /// K_V of eq. (15) (`controller.position.nn_k_v`).
    pub nn_k_v: f64,
    /// K_W of eq. (15) (`controller.position.nn_leakage`).
    pub k_w: f64,
    /// tau_M of Assumption 2 (`simulation.max_delay_s`).
    pub tau_m: f64,
    /// Psi_M of Remark 1: bound of the RBFNN regressor norm.
    pub psi_m: f64,
    /// sigma_max(G^-1).
    pub sigma_max_g_inv: f64,
    /// sigma_min(B^-1), B = G^T G.
    pub sigma_min_b_inv: f64,
}

/// Psi_M for l Gaussians per axis: every Gaussian is <= 1, so ||Psi_i|| <= sqrt(3 l) for the three
/// axes of one agent (the bound we use; the per-axis block alone is <= sqrt(l)).
pub fn psi_bound(neurons_per_axis: usize) -> f64 {
    (3.0 * neurons_per_axis as f64).sqrt()
}

/// The symmetric M of eq. (18) for given (M1, M2).
pub fn matrix_m(g: &Theorem1Inputs, m1: f64, m2: f64) -> Matrix5<f64> {
    let t2 = g.tau_m * g.tau_m;
    let mut m = Matrix5::zeros();
    m[(0, 0)] = g.k_p * g.nn_k_v - 2.0 * m2 * t2 * g.k_p * g.k_p;
    m[(1, 1)] =
        g.k_v * g.nn_k_p - m1 * t2 - g.nn_k_v * g.sigma_max_g_inv - 2.0 * m2 * t2 * g.k_v * g.k_v;
    m[(2, 2)] = m1 - 2.0 * m2 * t2 * g.k_p * g.k_p;
    m[(3, 3)] = m2 * (g.sigma_min_b_inv - 2.0 * t2 * g.k_v * g.k_v);
    m[(4, 4)] = g.k_w - 2.0 * m2 * t2 * g.psi_m * g.psi_m;
    let sym = |m: &mut Matrix5<f64>, i: usize, j: usize, v: f64| {
        m[(i, j)] = v;
        m[(j, i)] = v;
    };
    sym(&mut m, 2, 3, -2.0 * m2 * t2 * g.k_p * g.k_v);
    sym(&mut m, 2, 4, -0.5 * g.nn_k_v * g.psi_m);
    sym(&mut m, 3, 4, -0.5 * g.nn_k_p * g.psi_m);
    m
}

/// Smallest eigenvalue of a symmetric 5x5 matrix (NaN if it has non-finite entries).
pub fn min_eigenvalue(m: &Matrix5<f64>) -> f64 {
    if m.iter().any(|v| !v.is_finite()) {
        return f64::NAN;
    }
    m.symmetric_eigenvalues()
        .iter()
        .copied()
        .fold(f64::INFINITY, f64::min)
}

/// Result of the search for the (M1, M2) that maximise the smallest eigenvalue of M.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Search {
    /// True when the best M is positive definite (Theorem 1's condition can be met).
    pub positive_definite: bool,
    /// Largest smallest eigenvalue found.
    pub best_min_eigenvalue: f64,
    /// M1 at the best point.
    pub m1: f64,
    /// M2 at the best point.
    pub m2: f64,
    /// Diagonal of M at the best point.
    pub diagonal: [f64; 5],
    /// True when the best point lies at the edge of the searched range (the supremum is approached
    /// as M1 or M2 go to 0 or infinity).
    pub at_search_boundary: bool,
    /// Searched range of M1 and M2 (both), [lo, hi].
    pub range: [f64; 2],
}

/// Log10 range searched for both M1 and M2.
const LOG_LO: f64 = -9.0;
const LOG_HI: f64 = 6.0;
/// Grid points per decade.
const PER_DECADE: usize = 8;

/// Maximises the smallest eigenvalue of M over (M1, M2) > 0: a log grid over [1e-9, 1e6]², then a
/// pattern search in log space around the best grid point.
pub fn search(g: &Theorem1Inputs) -> Search {
    let eval = |l1: f64, l2: f64| {
        let v = min_eigenvalue(&matrix_m(g, 10f64.powf(l1), 10f64.powf(l2)));
        if v.is_nan() {
            f64::NEG_INFINITY
        } else {
            v
        }
    };
    let n = ((LOG_HI - LOG_LO) as usize) * PER_DECADE + 1;
    let step = 1.0 / PER_DECADE as f64;
    let (mut b1, mut b2, mut best) = (LOG_LO, LOG_LO, f64::NEG_INFINITY);
    for i in 0..n {
        for j in 0..n {
            let (l1, l2) = (LOG_LO + i as f64 * step, LOG_LO + j as f64 * step);
            let v = eval(l1, l2);
            if v > best {
                (b1, b2, best) = (l1, l2, v);
            }
        }
    }
    let mut h = step;
    while h > 1e-5 {
        let mut moved = false;
        for (d1, d2) in [
            (h, 0.0),
            (-h, 0.0),
            (0.0, h),
            (0.0, -h),
            (h, h),
            (-h, -h),
            (h, -h),
            (-h, h),
        ] {
            let (l1, l2) = (
                (b1 + d1).clamp(LOG_LO, LOG_HI),
                (b2 + d2).clamp(LOG_LO, LOG_HI),
            );
            let v = eval(l1, l2);
            if v > best {
                (b1, b2, best) = (l1, l2, v);
                moved = true;
            }
        }
        if !moved {
            h *= 0.5;
        }
    }
    let edge = |l: f64| (l - LOG_LO).abs() < 1e-3 || (l - LOG_HI).abs() < 1e-3;
    let (m1, m2) = (10f64.powf(b1), 10f64.powf(b2));
    let m = matrix_m(g, m1, m2);
    Search {
        positive_definite: best > 0.0,
        best_min_eigenvalue: best,
        m1,
        m2,
        diagonal: [m[(0, 0)], m[(1, 1)], m[(2, 2)], m[(3, 3)], m[(4, 4)]],
        at_search_boundary: edge(b1) || edge(b2),
        range: [10f64.powf(LOG_LO), 10f64.powf(LOG_HI)],
    }
}

/// The ties of Theorem 1: K_P = 4 M2 tau_M² k_V and K_V = 4 M2 tau_M² k_P.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Ties {
    /// K_P / K_V of the scenario.
    pub nn_ratio: f64,
    /// k_V / k_P, which the ties require K_P / K_V to equal.
    pub required_ratio: f64,
    /// M2 implied by K_P = 4 M2 tau_M² k_V.
    pub m2_from_nn_k_p: f64,
    /// M2 implied by K_V = 4 M2 tau_M² k_P.
    pub m2_from_nn_k_v: f64,
    /// True when both ties hold with one M2 (relative tolerance 1e-6).
    pub hold: bool,
}

/// Checks the printed ties.
pub fn ties(g: &Theorem1Inputs) -> Ties {
    let t2 = g.tau_m * g.tau_m;
    let m2_p = g.nn_k_p / (4.0 * t2 * g.k_v);
    let m2_v = g.nn_k_v / (4.0 * t2 * g.k_p);
    Ties {
        nn_ratio: g.nn_k_p / g.nn_k_v,
        required_ratio: g.k_v / g.k_p,
        m2_from_nn_k_p: m2_p,
        m2_from_nn_k_v: m2_v,
        hold: ((m2_p - m2_v) / m2_p.abs().max(m2_v.abs())).abs() < 1e-6,
    }
}

/// A condition M can only be positive definite under, independent of (M1, M2).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Necessary {
    /// Stable name.
    pub name: &'static str,
    /// The condition, written out.
    pub condition: &'static str,
    /// Left-hand side.
    pub lhs: f64,
    /// Right-hand side (the condition is lhs > rhs).
    pub rhs: f64,
    /// lhs > rhs.
    pub holds: bool,
}

/// Necessary conditions for M > 0 that do not depend on (M1, M2); each names an entry or principal
/// minor of M:
/// * `m44`: M44 = M2 (sigma_min(B^-1) - 2 tau_M² k_V²) > 0 needs sigma_min(B^-1) > 2 tau_M² k_V², i.e.
///   k_V < 1 / (sqrt(2) tau_M lambda_max);
/// * `m22`: M22 > 0 needs k_V K_P > K_V sigma_max(G^-1) (its best case M1, M2 -> 0);
/// * `minor45`: M44 M55 > (K_P Psi_M / 2)², maximised over M2 at M2 = K_W / (4 tau_M² Psi_M²), needs
///   (sigma_min(B^-1) - 2 tau_M² k_V²) K_W² > 2 tau_M² Psi_M⁴ K_P²;
/// * `m1_window`: M22 > 0 caps M1 below (k_V K_P - K_V sigma_max(G^-1)) / tau_M², and
///   M33 M55 > (K_V Psi_M / 2)² needs M1 > K_V² Psi_M² / (4 K_W) (both at their best, M2 -> 0).
pub fn necessary_conditions(g: &Theorem1Inputs) -> Vec<Necessary> {
    let t2 = g.tau_m * g.tau_m;
    let a = g.sigma_min_b_inv - 2.0 * t2 * g.k_v * g.k_v;
    let psi2 = g.psi_m * g.psi_m;
    let m22_best = g.k_v * g.nn_k_p - g.nn_k_v * g.sigma_max_g_inv;
    let mk = |name, condition, lhs: f64, rhs: f64| Necessary {
        name,
        condition,
        lhs,
        rhs,
        holds: lhs > rhs,
    };
    vec![
        mk(
            "m44",
            "sigma_min(B^-1) > 2 tau_M^2 k_V^2",
            g.sigma_min_b_inv,
            2.0 * t2 * g.k_v * g.k_v,
        ),
        mk(
            "m22",
            "k_V K_P > K_V sigma_max(G^-1)",
            g.k_v * g.nn_k_p,
            g.nn_k_v * g.sigma_max_g_inv,
        ),
        mk(
            "minor45",
            "(sigma_min(B^-1) - 2 tau_M^2 k_V^2) K_W^2 > 2 tau_M^2 Psi_M^4 K_P^2",
            a * g.k_w * g.k_w,
            2.0 * t2 * psi2 * psi2 * g.nn_k_p * g.nn_k_p,
        ),
        mk(
            "m1_window",
            "(k_V K_P - K_V sigma_max(G^-1)) / tau_M^2 > K_V^2 Psi_M^2 / (4 K_W)",
            m22_best / t2,
            g.nn_k_v * g.nn_k_v * psi2 / (4.0 * g.k_w),
        ),
    ]
}

/// Everything the report says about Theorem 1.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Theorem1 {
    /// The inputs (gains, tau_M, Psi_M, graph norms).
    pub inputs: Theorem1Inputs,
    /// How Psi_M was bounded.
    pub psi_m_bound: &'static str,
    /// How eq. (18) was read.
    pub reading: &'static str,
    /// Best (M1, M2).
    pub search: Search,
    /// The printed ties.
    pub ties: Ties,
    /// Necessary conditions independent of (M1, M2).
    pub necessary: Vec<Necessary>,
}

/// How Psi_M is bounded (printed in the report).
pub const PSI_M_BOUND: &str =
    "Psi_M = sqrt(3 l): each Gaussian is <= 1 and an agent's regressor Psi_i stacks 3 axes of l";
/// How M is read (printed in the report).
pub const READING: &str =
    "eq. (18) is printed upper-triangular; read as the symmetric matrix with M43 = M34, M53 = M35, M54 = M45";

/// Runs every Theorem 1 computation.
pub fn analyse(inputs: Theorem1Inputs) -> Theorem1 {
    Theorem1 {
        inputs,
        psi_m_bound: PSI_M_BOUND,
        reading: READING,
        search: search(&inputs),
        ties: ties(&inputs),
        necessary: necessary_conditions(&inputs),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The printed gains on the paper's path graph with tau_M = 0.05 s and l = 10.
    fn printed() -> Theorem1Inputs {
        let lmin = 2.0 - 3f64.sqrt();
        let lmax = 2.0 + 3f64.sqrt();
        Theorem1Inputs {
            k_p: 4.9,
            k_v: 6.85,
            nn_k_p: 0.0024,
            nn_k_v: 0.0036,
            k_w: 0.001725,
            tau_m: 0.05,
            psi_m: psi_bound(10),
            sigma_max_g_inv: 1.0 / lmin,
            sigma_min_b_inv: 1.0 / (lmax * lmax),
        }
    }

    #[test]
    fn m_is_symmetric_with_the_printed_entries() {
        let g = printed();
        let m = matrix_m(&g, 0.3, 0.02);
        assert_eq!(m, m.transpose());
        let t2 = 0.0025;
        assert!((m[(0, 0)] - (4.9 * 0.0036 - 2.0 * 0.02 * t2 * 4.9 * 4.9)).abs() < 1e-15);
        assert!((m[(3, 2)] + 2.0 * 0.02 * t2 * 4.9 * 6.85).abs() < 1e-15);
        assert!((m[(4, 2)] + 0.5 * 0.0036 * 30f64.sqrt()).abs() < 1e-15);
        assert_eq!(m[(0, 1)], 0.0);
    }

    #[test]
    fn printed_gains_cannot_make_m_positive_definite() {
        let g = printed();
        let s = search(&g);
        assert!(
            !s.positive_definite,
            "best min eigenvalue {}",
            s.best_min_eigenvalue
        );
        assert!(s.best_min_eigenvalue < 0.0);
        // The reason: M44 = M2 (sigma_min(B^-1) - 2 tau_M² k_V²) is negative for every M2 > 0.
        let nec = necessary_conditions(&g);
        assert!(!nec.iter().find(|c| c.name == "m44").unwrap().holds);
    }

    #[test]
    fn small_k_v_with_large_leakage_makes_m_positive_definite() {
        // A gain set chosen to satisfy every necessary condition: M becomes positive definite.
        let mut g = printed();
        g.k_p = 1.0;
        g.k_v = 1.0;
        g.nn_k_p = 0.01;
        g.nn_k_v = 0.001;
        g.k_w = 1.0;
        assert!(necessary_conditions(&g).iter().all(|c| c.holds));
        let s = search(&g);
        assert!(
            s.positive_definite,
            "best min eigenvalue {}",
            s.best_min_eigenvalue
        );
        assert!(min_eigenvalue(&matrix_m(&g, s.m1, s.m2)) > 0.0);
    }

    #[test]
    fn printed_ties_do_not_hold() {
        let t = ties(&printed());
        assert!(!t.hold);
        assert!((t.nn_ratio - 0.0024 / 0.0036).abs() < 1e-12);
        assert!((t.required_ratio - 6.85 / 4.9).abs() < 1e-12);
    }

    #[test]
    fn consistent_ties_hold() {
        let mut g = printed();
        g.nn_k_p = 4.0 * 0.1 * 0.0025 * g.k_v;
        g.nn_k_v = 4.0 * 0.1 * 0.0025 * g.k_p;
        let t = ties(&g);
        assert!(t.hold);
        assert!((t.m2_from_nn_k_p - 0.1).abs() < 1e-12);
    }

    #[test]
    fn min_eigenvalue_of_a_diagonal_matrix_is_its_smallest_entry() {
        let m = Matrix5::from_diagonal(&nalgebra::Vector5::new(3.0, -1.0, 2.0, 5.0, 4.0));
        assert!((min_eigenvalue(&m) + 1.0).abs() < 1e-12);
        let mut bad = m;
        bad[(0, 0)] = f64::NAN;
        assert!(min_eigenvalue(&bad).is_nan());
    }
}
