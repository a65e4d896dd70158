//! Outer (consensus) loop: for each eigenvalue lambda of L + B the closed loop
//! s² + lambda k_V s + lambda k_P of eq. (16) without delay, the negative damping and stiffness of
//! the uncertainty (61), the phase the delay costs, and what the RBFNN (15) does with its leakage.

use super::freq::{pair, quadratic_roots, Pair};
use formation_config::scenario::AgentSpec;
use serde::Serialize;

/// One consensus mode.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct OuterMode {
    /// Eigenvalue lambda of L + B.
    pub lambda: f64,
    /// Roots of s² + lambda k_V s + lambda k_P as [re, im], slower first.
    pub roots: [Pair; 2],
    /// Natural frequency sqrt(lambda k_P), rad/s.
    pub natural_frequency_rad_s: f64,
    /// Damping ratio lambda k_V / (2 sqrt(lambda k_P)).
    pub damping_ratio: f64,
}

/// The closed-loop modes of every eigenvalue.
pub fn outer_modes(eigenvalues: &[f64], k_p: f64, k_v: f64, k_lp: f64, k_l: f64) -> Vec<OuterMode> {
    eigenvalues
        .iter()
        .map(|&l| {
            let r = quadratic_roots(l * k_v + k_l, l * k_p + k_lp);
            let wn = (l * k_p + k_lp).max(0.0).sqrt();
            OuterMode {
                lambda: l,
                roots: [pair(r[0]), pair(r[1])],
                natural_frequency_rad_s: wn,
                damping_ratio: (l * k_v + k_l) / (2.0 * wn),
            }
        })
        .collect()
}

/// Magnitude of the fastest root over all modes, rad/s.
pub fn fastest_root(modes: &[OuterMode]) -> f64 {
    modes
        .iter()
        .flat_map(|m| m.roots.iter())
        .map(|r| r[0].hypot(r[1]))
        .fold(0.0, f64::max)
}

/// Decay rate of the slowest root over all modes (smallest -Re), 1/s.
pub fn slowest_decay(modes: &[OuterMode]) -> f64 {
    modes
        .iter()
        .flat_map(|m| m.roots.iter())
        .map(|r| -r[0])
        .fold(f64::INFINITY, f64::min)
}

/// Where the uncertainty (61) f_ik = gain sin(c P_ik + V_ik^p) pushes hardest.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct UncertaintySlopes {
    /// Largest |∂f/∂V| over agents and axes with velocity power 1 (= |gain|): negative damping, 1/s.
    pub worst_velocity_gain: f64,
    /// Agent (1-based) and axis (1-based) where it occurs.
    pub worst_velocity_at: [usize; 2],
    /// Largest 2 |gain| over axes with velocity power 2: there |∂f/∂V| = 2 |gain| |V| grows with the
    /// speed, 1/m.
    pub quadratic_slope_per_m_s: f64,
    /// Agent and axis of the largest quadratic slope (`[0, 0]` when there is none).
    pub quadratic_at: [usize; 2],
    /// Largest |∂f/∂P| = |gain c| over agents and axes: negative stiffness, 1/s².
    pub worst_position_gain: f64,
    /// Agent and axis where it occurs.
    pub worst_position_at: [usize; 2],
}

/// The slopes of the uncertainty of every agent.
pub fn uncertainty_slopes(agents: &[AgentSpec]) -> UncertaintySlopes {
    let mut u = UncertaintySlopes {
        worst_velocity_gain: 0.0,
        worst_velocity_at: [0, 0],
        quadratic_slope_per_m_s: 0.0,
        quadratic_at: [0, 0],
        worst_position_gain: 0.0,
        worst_position_at: [0, 0],
    };
    for (i, a) in agents.iter().enumerate() {
        for k in 0..3 {
            let g = a.uncertainty.gain[k].abs();
            let at = [i + 1, k + 1];
            if a.uncertainty.velocity_power[k] == 1 {
                if g > u.worst_velocity_gain {
                    (u.worst_velocity_gain, u.worst_velocity_at) = (g, at);
                }
            } else if 2.0 * g > u.quadratic_slope_per_m_s {
                (u.quadratic_slope_per_m_s, u.quadratic_at) = (2.0 * g, at);
            }
            let p = (a.uncertainty.gain[k] * a.uncertainty.position_coeff[k]).abs();
            if p > u.worst_position_gain {
                (u.worst_position_gain, u.worst_position_at) = (p, at);
            }
        }
    }
    u
}

/// What the RBFNN update (15) does with its leakage: W' = kappa (Psi (K_P e_P + K_V e_V) - K_W W).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RbfnnRole {
    /// Forgetting rate kappa K_W, 1/s (time constant 1 / (kappa K_W)).
    pub forgetting_rate: f64,
    /// Upper bound of the static position gain the network adds, l K_P / K_W (Psi^T Psi <= l per axis).
    pub static_p_gain_bound: f64,
    /// Upper bound of the static velocity gain, l K_V / K_W, 1/s.
    pub static_d_gain_bound: f64,
}

/// The RBFNN's forgetting rate and equivalent static gains.
pub fn rbfnn_role(
    kappa: f64,
    nn_k_p: f64,
    nn_k_v: f64,
    k_w: f64,
    neurons_per_axis: usize,
) -> RbfnnRole {
    let l = neurons_per_axis as f64;
    RbfnnRole {
        forgetting_rate: kappa * k_w,
        static_p_gain_bound: l * nn_k_p / k_w,
        static_d_gain_bound: l * nn_k_v / k_w,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use formation_config::Scenario;

    #[test]
    fn printed_gains_on_the_path_graph_have_a_fastest_mode_near_25_rad_s() {
        let lmax = 2.0 + 3f64.sqrt();
        let modes = outer_modes(&[2.0 - 3f64.sqrt(), lmax], 4.9, 6.85, 0.0, 0.0);
        let b = lmax * 6.85;
        let c = lmax * 4.9;
        let fast = (b + (b * b - 4.0 * c).sqrt()) / 2.0;
        assert!((fastest_root(&modes) - fast).abs() < 1e-9);
        assert!((fast - 24.8).abs() < 0.1);
        // The slowest eigenvalue gives a complex pair decaying at lambda_min k_V / 2 ...
        let lmin = 2.0 - 3f64.sqrt();
        assert!(modes[0].roots[0][1] > 0.0);
        assert!((modes[0].roots[0][0] + lmin * 6.85 / 2.0).abs() < 1e-9);
        // ... but the slowest root overall is the slow real root of the overdamped fastest mode.
        let slow = (b - (b * b - 4.0 * c).sqrt()) / 2.0;
        assert!((slowest_decay(&modes) - slow).abs() < 1e-9);
    }

    #[test]
    fn paper_uncertainty_has_unit_negative_damping_and_agent_4_y_stiffness() {
        let u = uncertainty_slopes(&Scenario::paper_exact().agents);
        assert!((u.worst_velocity_gain - 1.0).abs() < 1e-12);
        assert!((u.quadratic_slope_per_m_s - 2.0).abs() < 1e-12);
        assert!((u.worst_position_gain - 1.6).abs() < 1e-12);
        assert_eq!(u.worst_position_at, [4, 2]);
    }

    #[test]
    fn printed_rbfnn_forgets_in_a_third_of_a_second() {
        let r = rbfnn_role(1824.0, 0.0024, 0.0036, 0.001725, 10);
        assert!((r.forgetting_rate - 3.1464).abs() < 1e-3);
        assert!((r.static_p_gain_bound - 10.0 * 0.0024 / 0.001725).abs() < 1e-9);
    }
}
