//! Spectrum of L + B (Lemma 1, Assumption 1) and the derived norms Theorem 1 uses.

use formation_config::scenario::graph::Topology;
use serde::Serialize;

/// Eigenvalues of L + B and the quantities of Theorem 1 that depend only on the graph.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Spectrum {
    /// Eigenvalues of L + B, ascending.
    pub eigenvalues: Vec<f64>,
    /// True when every eigenvalue is > 0 (Lemma 1: G = (L + B) ⊗ I3 is positive definite).
    pub positive_definite: bool,
    /// Smallest eigenvalue lambda_min (sets the slowest consensus mode).
    pub lambda_min: f64,
    /// Largest eigenvalue lambda_max (sets the fastest consensus mode).
    pub lambda_max: f64,
    /// sigma_max(G^-1) = 1 / lambda_min (G symmetric positive definite); `null` when G is singular.
    pub sigma_max_g_inv: Option<f64>,
    /// sigma_min(B^-1) with B = G^T G: 1 / lambda_max^2; `null` when G is singular.
    pub sigma_min_b_inv: Option<f64>,
}

/// Computes the spectrum of L + B of a topology.
pub fn spectrum(topo: &Topology) -> Spectrum {
    spectrum_of(topo.eigenvalues())
}

/// Builds the spectrum summary from the eigenvalues of the symmetric L + B (any order).
pub fn spectrum_of(mut eigenvalues: Vec<f64>) -> Spectrum {
    eigenvalues.sort_by(|a, b| a.total_cmp(b));
    let lambda_min = eigenvalues.first().copied().unwrap_or(0.0);
    let lambda_max = eigenvalues.last().copied().unwrap_or(0.0);
    let positive_definite = !eigenvalues.is_empty() && lambda_min > 1e-12;
    let (sigma_max_g_inv, sigma_min_b_inv) = if positive_definite {
        (
            Some(1.0 / lambda_min),
            Some(1.0 / (lambda_max * lambda_max)),
        )
    } else {
        (None, None)
    };
    Spectrum {
        eigenvalues,
        positive_definite,
        lambda_min,
        lambda_max,
        sigma_max_g_inv,
        sigma_min_b_inv,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use formation_config::Scenario;

    #[test]
    fn paper_path_graph_has_eigenvalues_two_minus_two_cos_k_pi_over_six() {
        let s = Scenario::paper();
        let sp = spectrum(&Topology::from_scenario(&s));
        assert_eq!(sp.eigenvalues.len(), 5);
        for (k, ev) in sp.eigenvalues.iter().enumerate() {
            let expected = 2.0 - 2.0 * ((k as f64 + 1.0) * std::f64::consts::PI / 6.0).cos();
            assert!(
                (ev - expected).abs() < 1e-9,
                "eigenvalue {k}: {ev} vs {expected}"
            );
        }
        assert!(sp.positive_definite);
        let lmin = 2.0 - 3f64.sqrt();
        assert!((sp.sigma_max_g_inv.unwrap() - 1.0 / lmin).abs() < 1e-9);
        let lmax = 2.0 + 3f64.sqrt();
        assert!((sp.sigma_min_b_inv.unwrap() - 1.0 / (lmax * lmax)).abs() < 1e-9);
    }

    #[test]
    fn a_singular_matrix_is_not_positive_definite() {
        let sp = spectrum_of(vec![1.0, 0.0, 3.0]);
        assert_eq!(sp.eigenvalues, vec![0.0, 1.0, 3.0]);
        assert!(!sp.positive_definite);
        assert_eq!(sp.sigma_max_g_inv, None);
    }
}
