//! The separation layer (ours, docs/deviations.md D25): a control-barrier-function safety filter
//! on the position loop's virtual control, after Wang, Ames and Egerstedt, "Safety barrier
//! certificates for collision-free multirobot systems" (IEEE T-RO 2017), made delay-aware and
//! aware that a quadrotor's acceleration follows U_iP only as fast as its attitude can turn.
//!
//! What an agent knows of the others: its plant reports, with every state of step k, the other
//! quadrotors within the sensing range as a position broadcast received them (position,
//! velocity, and whether their controller flies them), measured at step m <= k: up to the
//! broadcast delay tau_B old ([`formation_config::protocol::wire::Traffic`]). Neighbours in the
//! communication graph or not, every quadrotor in range is protected.
//!
//! For each reported quadrotor j, with the report's age tau_a = (k - m) dt and a_o the largest
//! acceleration any quadrotor of the fleet commands (D5's limits):
//!
//! ```text
//! p^_j = p_j + v_j tau_a                 carried forward to t_k
//! eps  = a_o tau_a² / 2,  nu = a_o tau_a  what j may have done since (position, velocity)
//! r = P_i - p^_j, n = r / |r|, d^ = |r| - eps       predicted separation
//! c = -n . (V_i - v_j) + nu                         worst closing speed
//! ```
//!
//! Agent i answers for a share rho of the pair: half when j's controller flies it (j takes the
//! other half by the same rule), all of it when j is down (its failsafe keeps its slot and does
//! not avoid). Its part of the closing speed is c_i = rho c and its room (d^ - D_L) rho. What it
//! needs to stop c_i, S(c_i, alpha), allows for its own closing acceleration alpha = -n . a_i
//! (a_i read off its attitude): the attitude loop's lag T_D, then the acceleration turned round
//! from alpha to -a_B at the jerk j_B, then braking at a_B. The barrier is
//!
//! ```text
//! h_i = rho (d^ - D_L) - S(c_i, alpha)
//! ```
//!
//! A pair enters the filter once d^ - S / rho < D_A (the activation distance); the condition
//! dh_i/dt >= -gamma_S h_i, with dc/dt = -n . (a_i - a_j) - |w_perp|² / |r| and j's part
//! symmetric, asks
//!
//! ```text
//! n . U_iS >= b = (c_i - gamma_S h_i) / S' - rho |w_perp|² / |r|,   S' = dS/dc_i
//! ```
//!
//! U_iS is the closest point to U_iP plus a sidestep (sigma_S times the pair's unmet demand, at
//! right angles to the line of sight, to the right seen from above) that meets every such
//! half-space (Hildreth's dual coordinate ascent, a fixed number of sweeps). While no pair is
//! within the activation distance, or every condition already holds, U_iS = U_iP bit for bit.
//!
//! Pure: no allocation, no clock, no logging.

use formation_config::kinematics::thrust_axis;
use formation_config::protocol::wire::{
    TrafficEntry, VehicleState, MAX_TRAFFIC, TRAFFIC_UNCOOPERATIVE,
};
use formation_config::scenario::{PositionGains, SeparationMethod, SeparationSpec};
use nalgebra::Vector3;

/// Sweeps of Hildreth's method over the active constraints: with at most [`MAX_TRAFFIC`] of them
/// it settles in a few; the bound keeps the step's cost fixed.
const QP_SWEEPS: usize = 32;

/// A sweep that moves no multiplier by more than this ends the iteration, m/s².
const QP_TOLERANCE: f64 = 1e-12;

/// The window over which an agent measures its own acceleration from its velocities, s: 10 steps
/// at 1 kHz, a lag of 5 ms.
pub const ACCEL_WINDOW_S: f64 = 0.01;

/// A line of sight closer to vertical than this (its horizontal part, -) gets no sidestep.
const SIDESTEP_MIN_HORIZONTAL: f64 = 1e-3;

/// The repulsive term's distance floor, m: it stays finite for coincident reports.
const REPULSION_MIN_DISTANCE_M: f64 = 1e-3;

/// The layer's parameters for one agent, from the scenario.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SeparationParams {
    /// The layer acts on U_iP (otherwise it only predicts, for the telemetry).
    pub enabled: bool,
    /// The design: the barrier filter (default), buffered Voronoi cells or a repulsive term.
    pub method: SeparationMethod,
    /// k_R: gain of the repulsive term, m³/s².
    pub repulsive_gain: f64,
    /// D_L: distance the barrier keeps, m (safety distance + margin).
    pub keep_m: f64,
    /// The safety distance, m.
    pub safety: f64,
    /// The margin kept on top of it, m.
    pub margin: f64,
    /// D_A: activation distance, m.
    pub activation_m: f64,
    /// a_B, m/s².
    pub braking: f64,
    /// j_B, m/s³.
    pub jerk: f64,
    /// T_D, s.
    pub lag: f64,
    /// gamma_S, 1/s.
    pub rate: f64,
    /// sigma_S, -.
    pub sidestep: f64,
    /// a_o: the largest acceleration a quadrotor of the fleet commands (D5's limits), m/s².
    pub other_accel: f64,
    /// Step dt, s.
    pub dt: f64,
    /// Steps over which the agent measures its own acceleration ([`ACCEL_WINDOW_S`], at least 1).
    pub accel_window_steps: u64,
    /// g, m/s².
    pub gravity: f64,
}

impl SeparationParams {
    /// The parameters of a scenario's separation section, its safety distance, the position
    /// loop's limits, its step and gravity.
    pub fn new(
        spec: &SeparationSpec,
        safety_m: f64,
        pg: &PositionGains,
        dt: f64,
        gravity: f64,
    ) -> Self {
        SeparationParams {
            enabled: spec.enabled,
            method: spec.method,
            repulsive_gain: spec.repulsive_gain_m3_s2,
            keep_m: safety_m + spec.margin_m,
            safety: safety_m,
            margin: spec.margin_m,
            activation_m: spec.activation_m,
            braking: spec.braking_accel_m_s2,
            jerk: spec.jerk_m_s3,
            lag: spec.response_time_s,
            rate: spec.barrier_rate_1_s,
            sidestep: spec.sidestep_ratio,
            other_accel: pg
                .max_horizontal_accel_m_s2
                .max(pg.max_up_accel_m_s2)
                .max(pg.max_down_accel_m_s2),
            dt,
            accel_window_steps: (ACCEL_WINDOW_S / dt).round().max(1.0) as u64,
            gravity,
        }
    }
}

/// What the layer did in one step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Filtered {
    /// U_iS, m/s² (U_iP bit for bit when the layer did not act).
    pub u: [f64; 3],
    /// The smallest predicted separation d^ over the reports, m (infinite with none).
    pub predicted_m: f64,
    /// The layer changed U_iP.
    pub acted: bool,
}

/// One half-space n . u >= b of a pair in the filter.
#[derive(Debug, Clone, Copy, Default)]
struct Constraint {
    n: [f64; 3],
    b: f64,
    /// Sidestep direction (horizontal, sigma_S long).
    side: [f64; 3],
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// S(c, alpha) and dS/dc: the distance a vehicle closing at `c` (m/s) with closing acceleration
/// `alpha` (m/s²) covers before it stops: `lag` s at alpha, then its acceleration turned round
/// to -`braking` at `jerk`, then braking at `braking`. Zero (and slope `lag`) when it is
/// opening and not closing in.
pub fn stopping(c: f64, alpha: f64, braking: f64, jerk: f64, lag: f64) -> (f64, f64) {
    // The lag: the acceleration holds.
    let c1 = c + alpha * lag;
    let d0 = c * lag + 0.5 * alpha * lag * lag;
    if c1 <= 0.0 && alpha <= 0.0 {
        return (d0.max(0.0), lag);
    }
    // Turning round: alpha -> -braking at -jerk, for t1 (none if it already brakes harder).
    let t1 = (alpha + braking).max(0.0) / jerk;
    let c2 = c1 + alpha * t1 - 0.5 * jerk * t1 * t1;
    if c2 > 0.0 {
        let d1 = c1 * t1 + 0.5 * alpha * t1 * t1 - jerk * t1 * t1 * t1 / 6.0;
        (d0 + d1 + c2 * c2 / (2.0 * braking), lag + t1 + c2 / braking)
    } else {
        // It stops while turning round: at t* with c1 + alpha t - jerk t² / 2 = 0.
        let ts = (alpha + (alpha * alpha + 2.0 * jerk * c1.max(0.0)).sqrt()) / jerk;
        let d1 = c1 * ts + 0.5 * alpha * ts * ts - jerk * ts * ts * ts / 6.0;
        ((d0 + d1).max(0.0), lag + ts)
    }
}

/// The line of sight to one report, carried forward by its `age`.
struct Sight {
    /// |r|, r = P_i - p^_j, m.
    dist: f64,
    /// r / |r|.
    n: [f64; 3],
    /// a_o tau_a² / 2: how far j may be from where it is predicted, m.
    eps: f64,
    /// The report's velocity v_j, m/s.
    ve: [f64; 3],
}

/// The line of sight from report `e`, `age` s old, to agent i at `p`; `None` for coincident
/// centres (no direction to push along).
fn sight(sp: &SeparationParams, age: f64, p: [f64; 3], e: &TrafficEntry) -> Option<Sight> {
    let (pe, ve) = (e.p(), e.v());
    let pj: [f64; 3] = std::array::from_fn(|d| pe[d] + ve[d] * age);
    let r: [f64; 3] = std::array::from_fn(|d| p[d] - pj[d]);
    let dist = dot(r, r).sqrt();
    if dist <= 0.0 {
        return None;
    }
    Some(Sight {
        dist,
        n: std::array::from_fn(|d| r[d] / dist),
        eps: 0.5 * sp.other_accel * age * age,
        ve,
    })
}

/// The pair's half-space for agent i at `p`, `v` with acceleration `a` against one report
/// `age` s old, or `None` when the pair is not within the activation distance.
fn pair(
    sp: &SeparationParams,
    age: f64,
    (p, v, a): ([f64; 3], [f64; 3], [f64; 3]),
    (keep, activation): (f64, f64),
    e: &TrafficEntry,
) -> Option<Constraint> {
    let Sight { dist, n, eps, ve } = sight(sp, age, p, e)?;
    let nu = sp.other_accel * age;
    let predicted = dist - eps;
    let w: [f64; 3] = std::array::from_fn(|d| v[d] - ve[d]);
    let closing = -dot(n, w) + nu;
    let share = if e.flags & TRAFFIC_UNCOOPERATIVE == 0 {
        0.5
    } else {
        1.0
    };
    let alpha = -dot(n, a);
    let (stop, slope) = stopping(share * closing, alpha, sp.braking, sp.jerk, sp.lag);
    if predicted - stop / share >= activation {
        return None;
    }
    let h = share * (predicted - keep) - stop;
    let along = dot(n, w);
    let w_perp: [f64; 3] = std::array::from_fn(|d| w[d] - along * n[d]);
    let b = (share * closing - sp.rate * h) / slope - share * dot(w_perp, w_perp) / dist;
    Some(Constraint {
        n,
        b,
        side: sidestep(sp, n),
    })
}

/// Buffered Voronoi cells (Zhou et al., RA-L 2017) for a vehicle that cannot stop at once: agent
/// i at `p`, `v` with acceleration `a` keeps the point where it would stop inside its cell, the
/// half-space on its side of the bisector of the pair (from j's report carried forward by its
/// age, less eps) shrunk by half the `keep` distance. Only j's position enters: the cell's face
/// is taken to stand still, i answers for its own closing speed c = -n . V_i on its half of the
/// gap. `None` when the face is not within half the activation distance of the stopping point.
fn cell(
    sp: &SeparationParams,
    age: f64,
    (p, v, a): ([f64; 3], [f64; 3], [f64; 3]),
    (keep, activation): (f64, f64),
    e: &TrafficEntry,
) -> Option<Constraint> {
    let Sight { dist, n, eps, .. } = sight(sp, age, p, e)?;
    let face = 0.5 * (dist - eps) - 0.5 * keep;
    let closing = -dot(n, v);
    let (stop, slope) = stopping(closing, -dot(n, a), sp.braking, sp.jerk, sp.lag);
    if face - stop >= 0.5 * (activation - keep) {
        return None;
    }
    let h = face - stop;
    let b = (closing - sp.rate * h) / slope;
    Some(Constraint {
        n,
        b,
        side: sidestep(sp, n),
    })
}

/// The sidestep direction of a pair with line of sight `n`: to its right seen from above (z x n,
/// horizontal), sigma_S long; none for a line of sight close to vertical.
fn sidestep(sp: &SeparationParams, n: [f64; 3]) -> [f64; 3] {
    let side = [-n[1], n[0], 0.0];
    let hn = dot(side, side).sqrt();
    if hn > SIDESTEP_MIN_HORIZONTAL {
        side.map(|x| x * sp.sidestep / hn)
    } else {
        [0.0; 3]
    }
}

/// The repulsive term of one report for agent i at `p` (Khatib's potential field on the
/// predicted distance d^ = |p - p^_j| - eps): k_R (1/d^ - 1/D_A) / d^² along the line of sight
/// while d^ < D_A (with d^ floored at 1 mm), zero beyond.
fn repulsion(
    sp: &SeparationParams,
    age: f64,
    p: [f64; 3],
    activation: f64,
    e: &TrafficEntry,
) -> [f64; 3] {
    let Some(Sight { dist, n, eps, .. }) = sight(sp, age, p, e) else {
        return [0.0; 3];
    };
    let predicted = (dist - eps).max(REPULSION_MIN_DISTANCE_M);
    if predicted >= activation {
        return [0.0; 3];
    }
    let push = sp.repulsive_gain * (1.0 / predicted - 1.0 / activation) / (predicted * predicted);
    n.map(|x| push * x)
}

/// The acceleration the thrust gives a vehicle at attitude `att` that holds the vertical `u_z`
/// (m/s²): (g + u_z) times its thrust axis over the axis' vertical part, less g.
fn thrust_acceleration(att: [f64; 3], u_z: f64, g: f64) -> [f64; 3] {
    let axis = thrust_axis(&Vector3::from(att));
    let lift = (g + u_z) / axis[2].max(0.1);
    [lift * axis[0], lift * axis[1], u_z]
}

/// The distances a pair's filter keeps and activates at, (D_L,ij, D_A,ij), m, when the formation
/// itself puts their slots `desired` apart: never more than the formation asks less the margin,
/// so that the layer does not fight a formation whose slots are close (but never less than the
/// safety distance); the defaults D_L, D_A wherever the slots are far enough apart.
pub fn pair_distances(sp: &SeparationParams, desired: f64) -> (f64, f64) {
    let room = desired - sp.margin;
    let keep = room.clamp(sp.safety, sp.keep_m);
    let activation = room.clamp(keep, sp.activation_m.max(keep));
    (keep, activation)
}

/// The layer for agent i at its current state `own` (step, position, velocity, attitude and the
/// traffic it reports), with its measured acceleration `accel` (m/s², from its own recent
/// velocities; `None`: not yet known, the thrust's is used), and how far apart the formation
/// puts its slot and those of some quadrotors, `slots` ((agent index, squared distance m²); a
/// quadrotor not in it gets the defaults D_L, D_A), on the position loop's limited virtual
/// control `u`. The
/// vehicle's acceleration is U_iS plus what the thrust does not make (the lumped uncertainty and
/// disturbance, F~ = accel - thrust acceleration): the half-spaces bound U_iS + F~.
pub fn filter(
    sp: &SeparationParams,
    own: &VehicleState,
    accel: Option<[f64; 3]>,
    slots: &[(u32, f64)],
    u: [f64; 3],
) -> Filtered {
    let used = own.traffic.used();
    if used.is_empty() {
        return Filtered {
            u,
            predicted_m: f64::INFINITY,
            acted: false,
        };
    }
    // The thrust's acceleration is needed only once a pair is in the filter (before the first
    // report, the vehicle's own acceleration is taken to be it).
    let thrust = || thrust_acceleration(own.attitude, u[2], sp.gravity);
    let a = accel.unwrap_or_else(thrust);
    // A first pass without square roots: the predicted squared distances, and the distance
    // beyond which no report can be within the activation distance (a bound on d^ - S / rho
    // from the fastest relative speed of a report and the own acceleration; S grows with both:
    // the closing speed -n . (V_i - v_j) + nu is at most |V_i - v_j| + nu).
    let mut d2 = [f64::INFINITY; MAX_TRAFFIC];
    let (mut nearest, mut fastest) = (f64::INFINITY, 0.0_f64);
    let mut uncooperative = false;
    // One snapshot per report: every entry has the same age.
    let age = own.step.saturating_sub(own.traffic.step) as f64 * sp.dt;
    for (l, e) in used.iter().enumerate() {
        let (pj, vj) = (e.p(), e.v());
        let r: [f64; 3] = std::array::from_fn(|d| own.position[d] - pj[d] - vj[d] * age);
        let w: [f64; 3] = std::array::from_fn(|d| own.velocity[d] - vj[d]);
        d2[l] = dot(r, r);
        fastest = fastest.max(dot(w, w));
        nearest = nearest.min(d2[l]);
        uncooperative |= e.flags & TRAFFIC_UNCOOPERATIVE != 0;
    }
    let eps = 0.5 * sp.other_accel * age * age;
    let predicted_m = nearest.sqrt() - eps;
    let c_max = fastest.sqrt() + sp.other_accel * age;
    let alpha_max = dot(a, a).sqrt();
    let stop =
        |share: f64| stopping(share * c_max, alpha_max, sp.braking, sp.jerk, sp.lag).0 / share;
    // A report's share is 1/2, or 1 for a quadrotor whose controller is down.
    let worst = if uncooperative {
        stop(0.5).max(stop(1.0))
    } else {
        stop(0.5)
    };
    let gate = sp.activation_m + eps + worst;
    let unchanged = Filtered {
        u,
        predicted_m,
        acted: false,
    };
    if !sp.enabled || nearest >= gate * gate {
        return unchanged;
    }
    let mut cs = [Constraint::default(); MAX_TRAFFIC];
    let mut m = 0;
    let mut push = [0.0; 3];
    let me = (own.position, own.velocity, a);
    for (l, e) in used.iter().enumerate() {
        if d2[l] >= gate * gate {
            continue;
        }
        let desired = slots
            .iter()
            .find(|s| s.0 == e.agent)
            .map_or(f64::INFINITY, |s| s.1.sqrt());
        let distances = pair_distances(sp, desired);
        let c = match sp.method {
            SeparationMethod::Barrier => pair(sp, age, me, distances, e),
            SeparationMethod::Voronoi => cell(sp, age, me, distances, e),
            SeparationMethod::Repulsive => {
                let f = repulsion(sp, age, own.position, distances.1, e);
                (0..3).for_each(|d| push[d] += f[d]);
                None
            }
        };
        if let Some(c) = c {
            cs[m] = c;
            m += 1;
        }
    }
    if push != [0.0; 3] {
        return Filtered {
            u: std::array::from_fn(|d| u[d] + push[d]),
            predicted_m,
            acted: true,
        };
    }
    let cs = &mut cs[..m];
    if cs.is_empty() {
        return unchanged;
    }
    // n . (U_iS + F~) >= b, F~ = a - thrust acceleration.
    if accel.is_some() {
        let t = thrust();
        let rest: [f64; 3] = std::array::from_fn(|d| a[d] - t[d]);
        for c in cs.iter_mut() {
            c.b -= dot(c.n, rest);
        }
    }
    if cs.iter().all(|c| dot(c.n, u) >= c.b) {
        return unchanged;
    }
    Filtered {
        u: solve(cs, u),
        predicted_m,
        acted: true,
    }
}

/// U_iS for U_iP = `u` and the half-spaces `cs` (some unmet): the sidestep added, then the
/// closest point that meets them all.
fn solve(cs: &[Constraint], u: [f64; 3]) -> [f64; 3] {
    // The sidestep: each violated pair adds its share at right angles to its line of sight.
    let mut target = u;
    for c in cs.iter() {
        let unmet = (c.b - dot(c.n, u)).max(0.0);
        for d in 0..3 {
            target[d] += unmet * c.side[d];
        }
    }
    // Hildreth: min |x - target|² s.t. n_l . x >= b_l; x = target + sum lambda_l n_l, lambda >= 0.
    let mut lambda = [0.0; MAX_TRAFFIC];
    let mut x = target;
    for _ in 0..QP_SWEEPS {
        let mut moved = 0.0_f64;
        for (l, c) in cs.iter().enumerate() {
            let new = (lambda[l] + c.b - dot(c.n, x)).max(0.0);
            let delta = new - lambda[l];
            if delta != 0.0 {
                for d in 0..3 {
                    x[d] += delta * c.n[d];
                }
                lambda[l] = new;
                moved = moved.max(delta.abs());
            }
        }
        if moved <= QP_TOLERANCE {
            break;
        }
    }
    x
}

#[cfg(test)]
mod tests {
    use super::*;
    use formation_config::protocol::wire::Traffic;
    use formation_config::Scenario;

    fn params() -> SeparationParams {
        let s = Scenario::paper();
        SeparationParams::new(
            &s.controller.separation,
            s.metrics.safety_distance_m,
            &s.controller.position,
            s.simulation.dt_s,
            s.simulation.gravity_m_s2,
        )
    }

    /// Agent i at step `k`, level, at `p` with velocity `v`, reporting `entries` measured at
    /// step `m`.
    fn own_at(k: u64, m: u64, p: [f64; 3], v: [f64; 3], entries: &[TrafficEntry]) -> VehicleState {
        let mut s = own(k, p, v, entries);
        s.traffic.step = m;
        s
    }

    /// Agent i at step `k`, level, at `p` with velocity `v`, reporting `entries` of step k.
    fn own(k: u64, p: [f64; 3], v: [f64; 3], entries: &[TrafficEntry]) -> VehicleState {
        let mut t = Traffic {
            step: k,
            ..Traffic::default()
        };
        for (slot, e) in t.entries.iter_mut().zip(entries) {
            *slot = *e;
        }
        t.count = entries.len() as u32;
        VehicleState {
            step: k,
            position: p,
            velocity: v,
            traffic: t,
            ..VehicleState::default()
        }
    }

    fn at(_step: u64, p: [f64; 3], v: [f64; 3]) -> TrafficEntry {
        TrafficEntry {
            agent: 1,
            flags: 0,
            position: p.map(|x| x as f32),
            velocity: v.map(|x| x as f32),
        }
    }

    #[test]
    fn far_traffic_leaves_the_virtual_control_untouched_bit_for_bit() {
        let sp = params();
        let u = [0.123_456_789, -2.5, 0.3];
        let s = own(
            100,
            [0.0; 3],
            [1.0, 0.0, 0.0],
            &[at(100, [5.0, 0.0, 0.0], [-1.0, 0.0, 0.0])],
        );
        let f = filter(&sp, &s, None, &[], u);
        assert!(!f.acted);
        assert_eq!(f.u, u);
        assert_eq!(f.predicted_m, 5.0);
        let none = filter(&sp, &own(100, [0.0; 3], [0.0; 3], &[]), None, &[], u);
        assert_eq!((none.u, none.predicted_m), (u, f64::INFINITY));
    }

    /// Head-on at 1 m/s each, 2 m apart, both commanding more speed ahead: the filter brakes
    /// along the line of sight and steps to the right.
    #[test]
    fn two_vehicles_head_on_brake_and_step_aside() {
        let sp = params();
        let s = own(
            100,
            [0.0; 3],
            [1.0, 0.0, 0.0],
            &[at(100, [2.0, 0.0, 0.0], [-1.0, 0.0, 0.0])],
        );
        let f = filter(&sp, &s, None, &[], [1.0, 0.0, 0.0]);
        assert!(f.acted);
        assert!(f.u[0] < 0.0, "brakes away from the other: {:?}", f.u);
        // n = -x (from the other to me); right of it seen from above: z x n = -y.
        assert!(f.u[1] < 0.0, "steps to its right: {:?}", f.u);
    }

    /// The two other designs on the same head-on pair: buffered Voronoi cells brake (the
    /// stopping point would leave the cell) and step aside; the repulsive term pushes back
    /// only once the pair is within the activation distance, harder the closer it is.
    #[test]
    fn voronoi_cells_and_the_repulsive_term_push_a_head_on_pair_apart() {
        let head_on = |gap: f64| {
            own(
                100,
                [0.0; 3],
                [1.0, 0.0, 0.0],
                &[at(100, [gap, 0.0, 0.0], [-1.0, 0.0, 0.0])],
            )
        };
        let cells = SeparationParams {
            method: SeparationMethod::Voronoi,
            ..params()
        };
        let f = filter(&cells, &head_on(2.0), None, &[], [1.0, 0.0, 0.0]);
        assert!(f.acted && f.u[0] < 0.0 && f.u[1] < 0.0, "{:?}", f.u);
        // Far apart and opening: the cell's face is out of reach.
        let far = own(
            100,
            [0.0; 3],
            [-1.0, 0.0, 0.0],
            &[at(100, [3.0, 0.0, 0.0], [1.0, 0.0, 0.0])],
        );
        assert!(!filter(&cells, &far, None, &[], [1.0, 0.0, 0.0]).acted);
        let rep = SeparationParams {
            method: SeparationMethod::Repulsive,
            ..params()
        };
        let u = [1.0, 0.0, 0.0];
        let outside = filter(&rep, &head_on(1.0), None, &[], u);
        assert!(
            !outside.acted && outside.u == u,
            "beyond D_A = 0.9 m: {:?}",
            outside.u
        );
        let (near, nearer) = (
            filter(&rep, &head_on(0.8), None, &[], u),
            filter(&rep, &head_on(0.6), None, &[], u),
        );
        assert!(
            near.acted && near.u[0] < u[0] && nearer.u[0] < near.u[0],
            "{near:?} {nearer:?}"
        );
        // k_R (1/0.6 - 1/0.9) / 0.36 along -x (the report in f32: to 1e-6).
        let want = 0.5 * (1.0 / 0.6 - 1.0 / 0.9) / 0.36;
        assert!((u[0] - nearer.u[0] - want).abs() < 1e-6, "{:?}", nearer.u);
    }

    /// The same pair seen through a report 50 ms old: the other is carried forward, and the worst
    /// closing speed grows by a_o tau: the filter brakes harder.
    #[test]
    fn a_delayed_report_is_carried_forward_and_its_uncertainty_counted() {
        let sp = params();
        let v = [1.0, 0.0, 0.0];
        let fresh = own(
            100,
            [0.0; 3],
            v,
            &[at(100, [1.5, 0.0, 0.0], [-1.0, 0.0, 0.0])],
        );
        let old = own_at(
            100,
            50,
            [0.0; 3],
            v,
            &[at(50, [1.55, 0.0, 0.0], [-1.0, 0.0, 0.0])],
        );
        let a = filter(&sp, &fresh, None, &[], [0.0; 3]);
        let b = filter(&sp, &old, None, &[], [0.0; 3]);
        assert!((b.predicted_m - (1.5 - 0.5 * sp.other_accel * 0.05 * 0.05)).abs() < 1e-6);
        assert!(
            b.u[0] < a.u[0],
            "older data, harder braking: {:?} {:?}",
            a.u,
            b.u
        );
    }

    /// A vehicle already accelerating towards the other needs longer to stop (its acceleration
    /// must turn round at j_B first): the filter acts earlier and harder.
    #[test]
    fn a_vehicle_accelerating_towards_the_other_is_stopped_earlier() {
        let sp = params();
        let (slow, _) = stopping(0.5, 0.0, sp.braking, sp.jerk, sp.lag);
        let (fast, _) = stopping(0.5, 2.0, sp.braking, sp.jerk, sp.lag);
        assert!(fast > slow + 0.2, "{slow} {fast}");
        let mut s = own(
            0,
            [0.0; 3],
            [1.0, 0.0, 0.0],
            &[at(0, [2.2, 0.0, 0.0], [0.0; 3])],
        );
        let level = filter(&sp, &s, None, &[], [0.0; 3]);
        // Pitched forward 0.2 rad: accelerating along +x, towards the other.
        s.attitude = [0.0, 0.2, 0.0];
        let pitched = filter(&sp, &s, None, &[], [0.0; 3]);
        assert!(!level.acted && pitched.acted, "{level:?} {pitched:?}");
    }

    /// Saturation: the demand is met within the limits a vehicle can fly; a demand beyond them
    /// is the caller's to clip (D5), and the filter's output still points the right way.
    #[test]
    fn the_stopping_distance_grows_with_speed_and_is_zero_when_opening() {
        let sp = params();
        let mut last = -1.0;
        for i in 0..40 {
            let (d, slope) = stopping(i as f64 * 0.1, 0.0, sp.braking, sp.jerk, sp.lag);
            assert!(d > last && slope > 0.0);
            last = d;
        }
        assert_eq!(stopping(-1.0, -0.5, sp.braking, sp.jerk, sp.lag).0, 0.0);
        // The closed form agrees with a 1 kHz integration of the same manoeuvre.
        let (c, alpha) = (1.2, 1.0);
        let (mut x, mut v, mut a, mut t) = (0.0, c, alpha, 0.0);
        while v > 0.0 {
            if t >= sp.lag {
                a = (a - sp.jerk * 1e-4).max(-sp.braking);
            }
            x += v * 1e-4 + 0.5 * a * 1e-8;
            v += a * 1e-4;
            t += 1e-4;
        }
        let (d, _) = stopping(c, alpha, sp.braking, sp.jerk, sp.lag);
        assert!((d - x).abs() < 2e-3, "{d} vs {x}");
    }

    /// A quadrotor whose controller is down does not brake: agent i takes the whole demand.
    #[test]
    fn a_neighbour_down_leaves_the_whole_avoidance_to_the_agent() {
        let sp = params();
        let mut e = at(100, [1.2, 0.0, 0.0], [0.0; 3]);
        let v = [1.0, 0.0, 0.0];
        let up = filter(&sp, &own(100, [0.0; 3], v, &[e]), None, &[], [0.0; 3]);
        e.flags = TRAFFIC_UNCOOPERATIVE;
        let down = filter(&sp, &own(100, [0.0; 3], v, &[e]), None, &[], [0.0; 3]);
        assert!(up.acted && down.acted);
        assert!(
            down.u[0] < up.u[0],
            "harder braking alone: {down:?} vs {up:?}"
        );
    }

    /// Three pairs at once: the result meets every half-space and is the closest such point
    /// (nothing along z, where no constraint points).
    #[test]
    fn every_violated_pair_is_met_at_once() {
        let mut sp = params();
        sp.sidestep = 0.0;
        let s = own(
            0,
            [0.0; 3],
            [0.0; 3],
            &[
                at(0, [0.7, 0.0, 0.0], [0.0; 3]),
                at(0, [-0.7, 0.0, 0.0], [0.0; 3]),
                at(0, [0.0, 0.8, 0.0], [0.0; 3]),
            ],
        );
        let f = filter(&sp, &s, None, &[], [0.0, 2.0, 0.5]);
        assert!(f.acted);
        assert!(f.u[1] < 2.0, "held back from the one ahead on y: {:?}", f.u);
        assert!(
            f.u[0].abs() < 1e-9 && (f.u[2] - 0.5).abs() < 1e-12,
            "{:?}",
            f.u
        );
    }

    /// A formation whose slots are 0.7 m apart: the pair keeps 0.55 m (the slots less the
    /// margin), not the 0.65 m of D_L, and is left alone while it holds its slots; slots far apart
    /// get the defaults; slots closer than the safety distance still get the safety distance.
    #[test]
    fn the_layer_does_not_fight_a_formation_whose_slots_are_close() {
        let sp = params();
        assert_eq!(pair_distances(&sp, 5.0), (sp.keep_m, sp.activation_m));
        let (keep, act) = pair_distances(&sp, 0.7);
        assert!((keep - 0.55).abs() < 1e-12 && (act - 0.55).abs() < 1e-12);
        assert_eq!(pair_distances(&sp, 0.2), (sp.safety, sp.safety));
        let slots = [(1, 0.7 * 0.7)];
        let mut s = own(0, [0.0; 3], [0.0; 3], &[at(0, [0.7, 0.0, 0.0], [0.0; 3])]);
        s.agent = 0;
        let mut e = s.traffic.entries[0];
        e.agent = 1;
        s.traffic.entries[0] = e;
        let u = [1.0, 0.0, 0.0];
        let held = filter(&sp, &s, None, &slots, u);
        assert!(!held.acted, "{held:?}");
        let far_slots = [(1, 3.0 * 3.0)];
        let pushed = filter(&sp, &s, None, &far_slots, u);
        assert!(pushed.acted && pushed.u[0] < u[0], "{pushed:?}");
    }

    #[test]
    fn the_layer_switched_off_predicts_but_does_not_act() {
        let mut sp = params();
        sp.enabled = false;
        let s = own(
            0,
            [0.0; 3],
            [1.0, 0.0, 0.0],
            &[at(0, [0.6, 0.0, 0.0], [-1.0, 0.0, 0.0])],
        );
        let f = filter(&sp, &s, None, &[], [1.0, 0.0, 0.0]);
        assert!(!f.acted);
        assert_eq!(f.u, [1.0, 0.0, 0.0]);
        assert!((f.predicted_m - 0.6).abs() < 1e-6);
    }
}
