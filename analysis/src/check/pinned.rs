//! Leader information structure (docs/deviations.md D17): with `leader_broadcast = "pinned"` only agents
//! with b_i > 0 add the leader-relative damping k_L and stiffness k_LP (D11). The consensus loop is then
//! x'' = -(k_P (L+B) + k_LP P) x - (k_V (L+B) + k_L P) x' with P = diag(1 where the agent receives the
//! leader's data), and the least damping any collective motion gets is lambda_min(k_V (L+B) + k_L P),
//! which must exceed the negative damping of the uncertainty (61). Raising k_V raises it, but also the
//! fastest mode lambda_max k_V, which the delay tau_M bounds: the window of k_V between the two is what
//! decides whether a gain set of the form (14) can work on this graph.

use super::freq::Margin;
use formation_config::scenario::graph::Topology;
use formation_config::scenario::LeaderBroadcast;
use nalgebra::DMatrix;
use serde::Serialize;

/// Upper end of the k_V search, 1/s.
const K_V_SEARCH_MAX: f64 = 1e3;
/// Bisection steps of the k_V search.
const BISECTION_STEPS: usize = 60;

/// What the information structure leaves to the slowest collective motion.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct InformationStructure {
    /// `all` or `pinned`.
    pub leader_broadcast: LeaderBroadcast,
    /// Agents that receive the leader's data (1-based).
    pub agents_with_leader_data: Vec<usize>,
    /// lambda_min(k_V (L+B) + k_L P): least damping of any collective motion, 1/s.
    pub slowest_damping_rate: f64,
    /// lambda_min(k_P (L+B) + k_LP P): least stiffness, 1/s².
    pub slowest_stiffness: f64,
    /// Smallest k_V whose least damping exceeds the uncertainty's negative damping (None: none up to
    /// 1e3), 1/s.
    pub k_v_needed: Option<f64>,
    /// Largest k_V for which the fastest mode keeps a positive phase margin in the loop model the caller
    /// gives (`formation check`: the linear cascade of `inner`, delay, command filter 1 and the attitude
    /// loop), 1/s.
    pub k_v_delay_limit: Option<f64>,
    /// k_v_needed < k_v_delay_limit: some k_V can give both.
    pub window_exists: bool,
}

/// P = diag(1 where the agent receives the leader's data).
fn reach(topo: &Topology, mode: LeaderBroadcast) -> Vec<f64> {
    topo.leader_weights
        .iter()
        .map(|&b| if mode.reaches(b) { 1.0 } else { 0.0 })
        .collect()
}

fn min_eig(lb: &DMatrix<f64>, gain: f64, p: &[f64], extra: f64) -> f64 {
    let mut m = lb * gain;
    for (i, pi) in p.iter().enumerate() {
        m[(i, i)] += extra * pi;
    }
    m.symmetric_eigen()
        .eigenvalues
        .iter()
        .copied()
        .fold(f64::INFINITY, f64::min)
}

/// The analysis for gains (k_P, k_V, k_LP, k_L) and the uncertainty's worst negative damping `slope`
/// (1/s); `margin(k_V)` is the fastest mode's phase margin in the caller's loop model.
pub fn analyse(
    topo: &Topology,
    mode: LeaderBroadcast,
    (k_p, k_v, k_lp, k_l): (f64, f64, f64, f64),
    margin: &dyn Fn(f64) -> Option<Margin>,
    slope: f64,
) -> InformationStructure {
    let lb = topo.laplacian_plus_leader();
    let p = reach(topo, mode);
    let damping = |kv: f64| min_eig(&lb, kv, &p, k_l);
    let stable = |kv: f64| margin(kv).is_some_and(|m| m.phase_margin_deg > 0.0);
    let bisect = |lo: f64, hi: f64, up: &dyn Fn(f64) -> bool| {
        // `up(x)` is false at lo and true at hi; returns the switching point.
        let (mut a, mut b) = (lo, hi);
        for _ in 0..BISECTION_STEPS {
            let m = 0.5 * (a + b);
            if up(m) {
                b = m;
            } else {
                a = m;
            }
        }
        b
    };
    let k_v_needed = if damping(0.0) > slope {
        Some(0.0)
    } else if damping(K_V_SEARCH_MAX) > slope {
        Some(bisect(0.0, K_V_SEARCH_MAX, &|kv| damping(kv) > slope))
    } else {
        None
    };
    let k_v_delay_limit = if !stable(0.0) {
        None
    } else if stable(K_V_SEARCH_MAX) {
        Some(K_V_SEARCH_MAX)
    } else {
        Some(bisect(0.0, K_V_SEARCH_MAX, &|kv| !stable(kv)))
    };
    InformationStructure {
        leader_broadcast: mode,
        agents_with_leader_data: p
            .iter()
            .enumerate()
            .filter(|(_, x)| **x > 0.0)
            .map(|(i, _)| i + 1)
            .collect(),
        slowest_damping_rate: damping(k_v),
        slowest_stiffness: min_eig(&lb, k_p, &p, k_lp),
        window_exists: matches!((k_v_needed, k_v_delay_limit), (Some(a), Some(b)) if a < b),
        k_v_needed,
        k_v_delay_limit,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::check::freq::phase_margin;
    use crate::check::inner::outer_loop_delay_only;

    /// The fastest consensus mode lambda_max with the delay only (ideal inner loop), for effective gains
    /// (k_P + k_LP/lambda_max, k_V + k_L/lambda_max): the optimistic loop model.
    fn delay_only_margin(
        lambda_max: f64,
        (k_p, k_lp, k_l): (f64, f64, f64),
        tau: f64,
    ) -> impl Fn(f64) -> Option<Margin> {
        move |k_v| {
            phase_margin(|w| {
                outer_loop_delay_only(
                    lambda_max,
                    k_p + k_lp / lambda_max,
                    k_v + k_l / lambda_max,
                    tau,
                    w,
                )
            })
        }
    }

    fn ring(n: usize, b: Vec<f64>) -> Topology {
        let mut neighbours = vec![Vec::new(); n];
        for i in 0..n {
            let j = (i + 1) % n;
            neighbours[i].push((j, 1.0));
            neighbours[j].push((i, 1.0));
        }
        for l in &mut neighbours {
            l.sort_by_key(|(j, _)| *j);
        }
        Topology {
            neighbours,
            leader_weights: b,
        }
    }

    /// Under `all` every agent adds k_L: the least damping is lambda_min k_V + k_L exactly.
    #[test]
    fn broadcast_to_all_shifts_every_mode_by_k_l() {
        let t = ring(7, vec![1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
        let lmin = t.eigenvalues()[0];
        let lmax = t.eigenvalues()[6];
        let m = delay_only_margin(lmax, (1.8, 1.0, 1.6), 0.05);
        let r = analyse(&t, LeaderBroadcast::All, (1.8, 3.0, 1.0, 1.6), &m, 1.0);
        assert!((r.slowest_damping_rate - (lmin * 3.0 + 1.6)).abs() < 1e-9);
        assert_eq!(r.agents_with_leader_data.len(), 7);
        assert!(r.window_exists);
    }

    /// A 7-ring pinned at one agent: lambda_min = 0.088, so damping the uncertainty's 1/s needs
    /// k_V > 1/0.088 minus what k_L at one agent adds, far beyond what tau_M = 50 ms allows the fastest
    /// mode (lambda_max = 4.2) even with an ideal inner loop: no k_V works.
    #[test]
    fn seven_ring_pinned_at_one_agent_has_no_k_v_window() {
        let t = ring(7, vec![1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
        let lmax = t.eigenvalues()[6];
        let m = delay_only_margin(lmax, (1.8, 1.0, 1.6), 0.05);
        let r = analyse(&t, LeaderBroadcast::Pinned, (1.8, 3.0, 1.0, 1.6), &m, 1.0);
        assert_eq!(r.agents_with_leader_data, vec![1]);
        assert!(r.slowest_damping_rate < 1.0);
        let needed = r.k_v_needed.unwrap();
        let limit = r.k_v_delay_limit.unwrap();
        assert!(needed > limit, "needed {needed}, limit {limit}");
        assert!(!r.window_exists);
    }
}
