//! NTDPC: the local consensus errors (8)-(9) and the position control law (14), followed by the
//! acceleration and tilt limits we add (docs/deviations.md D5).

use formation_config::scenario::PositionGains;

/// Delayed information of one member of the consensus sum: position, velocity, and its formation
/// offset Delta_0 with first and second derivatives.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Member {
    /// Position, m.
    pub p: [f64; 3],
    /// Velocity, m/s.
    pub v: [f64; 3],
    /// Offset Delta_j0, m.
    pub off: [f64; 3],
    /// Offset derivative, m/s.
    pub off_v: [f64; 3],
    /// Offset second derivative, m/s².
    pub off_a: [f64; 3],
}

/// Delayed leader information: P_d and its derivatives.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LeaderInfo {
    /// P_d, m.
    pub p: [f64; 3],
    /// P_d', m/s.
    pub v: [f64; 3],
    /// P_d'', m/s².
    pub a: [f64; 3],
}

/// Eq. (8)-(9): e_iP and e_iV from the agent's own (delayed) data, its neighbours' with weights a_ij and
/// the leader's with weight b_i.
#[inline]
pub fn consensus_errors(
    me: &Member,
    neighbours: impl Iterator<Item = (f64, Member)>,
    b: f64,
    leader: &LeaderInfo,
) -> ([f64; 3], [f64; 3]) {
    let mut ep = [0.0; 3];
    let mut ev = [0.0; 3];
    for (a, nb) in neighbours {
        for k in 0..3 {
            // Delta_ij = Lambda_i - Lambda_j = Delta_i0 - Delta_j0.
            ep[k] += a * (me.p[k] - nb.p[k] - (me.off[k] - nb.off[k]));
            ev[k] += a * (me.v[k] - nb.v[k] - (me.off_v[k] - nb.off_v[k]));
        }
    }
    for k in 0..3 {
        ep[k] += b * (me.p[k] - leader.p[k] - me.off[k]);
        ev[k] += b * (me.v[k] - leader.v[k] - me.off_v[k]);
    }
    (ep, ev)
}

/// Eq. (14) before the limits of D5: U_iP = -k_P e_iP - k_V e_iV - F-hat_iP + Delta_i0'' (+ P_d'' with
/// our feedforward, D4; - k_L (V_i - P_d' - Delta_i0') - k_LP (P_i - P_d - Delta_i0) with our
/// leader-relative terms, D11). Both leader terms need the leader's data: an agent without it
/// (`leader_data` false: `leader_broadcast = "pinned"` and b_i = 0, D17) uses neither. The caller
/// applies [`limit`] (and knows from the difference whether the limit is active).
pub fn raw_law(
    g: &PositionGains,
    ep: [f64; 3],
    ev: [f64; 3],
    f_hat: [f64; 3],
    me: &Member,
    leader: &LeaderInfo,
    leader_data: bool,
) -> [f64; 3] {
    let limit = g.position_error_limit_m.unwrap_or(f64::INFINITY);
    let ep = clip_norm(ep, limit);
    let leader_p = clip_norm(
        std::array::from_fn(|k| me.p[k] - leader.p[k] - me.off[k]),
        limit,
    );
    let mut u = [0.0; 3];
    for k in 0..3 {
        let consensus = -g.k_p * ep[k] - g.k_v * ev[k] - f_hat[k] + me.off_a[k];
        u[k] = consensus;
        if leader_data {
            // One expression, in the order of (14) + D11, so that `all` stays bit-identical.
            u[k] = consensus
                - g.leader_velocity_damping * (me.v[k] - leader.v[k] - me.off_v[k])
                - g.leader_position_gain * leader_p[k];
            if g.reference_acceleration_feedforward {
                u[k] += leader.a[k];
            }
        }
    }
    u
}

/// `v` scaled down to the norm `limit` when longer (D18; an infinite limit returns `v` unchanged).
pub fn clip_norm(v: [f64; 3], limit: f64) -> [f64; 3] {
    let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    if n > limit {
        let s = limit / n;
        [v[0] * s, v[1] * s, v[2] * s]
    } else {
        v
    }
}

/// The acceleration and tilt limits of D5.
pub fn limit(g: &PositionGains, gravity: f64, mut u: [f64; 3]) -> [f64; 3] {
    u[2] = u[2].clamp(-g.max_down_accel_m_s2, g.max_up_accel_m_s2);
    let tilt_cap = (u[2] + gravity) * g.max_tilt_rad.tan();
    let cap = g.max_horizontal_accel_m_s2.min(tilt_cap);
    let h = (u[0] * u[0] + u[1] * u[1]).sqrt();
    if h > cap {
        let s = cap / h;
        u[0] *= s;
        u[1] *= s;
    }
    u
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clip_norm_shortens_long_errors_along_their_direction_and_keeps_short_ones() {
        let c = clip_norm([3.0, 4.0, 0.0], 1.0);
        assert!((c[0] - 0.6).abs() < 1e-12 && (c[1] - 0.8).abs() < 1e-12 && c[2] == 0.0);
        assert_eq!(clip_norm([0.3, 0.4, 0.0], 1.0), [0.3, 0.4, 0.0]);
        assert_eq!(
            clip_norm([30.0, 40.0, 0.0], f64::INFINITY),
            [30.0, 40.0, 0.0]
        );
    }

    /// An agent without the leader's data (pinned broadcast, b_i = 0) ignores P_d entirely: the law does
    /// not change when the leader's information does.
    #[test]
    fn without_leader_data_the_law_ignores_the_leader() {
        let g = formation_config::Scenario::paper().controller.position;
        let me = Member {
            p: [1.0, 2.0, 3.0],
            v: [0.1, 0.0, -0.2],
            ..Member::default()
        };
        let a = LeaderInfo {
            p: [0.0; 3],
            v: [0.0; 3],
            a: [0.0; 3],
        };
        let b = LeaderInfo {
            p: [5.0, -3.0, 1.0],
            v: [1.0, 1.0, 0.0],
            a: [0.5, 0.0, 0.1],
        };
        let (ep, ev, f) = ([0.2, -0.1, 0.0], [0.0, 0.1, 0.0], [0.0; 3]);
        assert_eq!(
            raw_law(&g, ep, ev, f, &me, &a, false),
            raw_law(&g, ep, ev, f, &me, &b, false)
        );
        assert_ne!(
            raw_law(&g, ep, ev, f, &me, &a, true),
            raw_law(&g, ep, ev, f, &me, &b, true)
        );
    }
}
