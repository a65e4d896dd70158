//! How a new agent process takes over from a dead or hung one (`docs/failures.md`): it restores
//! the last checkpoint and replays the control of every step from the checkpoint to the one it
//! went down at (warm: the controller state is then exactly the dead process's), or starts afresh
//! (cold); either way its delay histories are refilled with what it missed while down, from the
//! states the plant recorded. The in-process runner and the agent process call the same function.

use crate::Agent;
use formation_config::protocol::wire::{ReferenceFrame, VehicleState};

/// The window a new process rebuilds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Rejoin {
    /// Step of the checkpoint restored (warm), or None (cold).
    pub checkpoint: Option<u64>,
    /// First step the old process did not compute.
    pub down_from: u64,
    /// First step the new process computes.
    pub rejoin_at: u64,
    /// First step whose recorded states the caller holds: the rebuild reads none before it.
    pub recorded_from: u64,
}

impl Rejoin {
    /// The first step whose recorded states the rebuild reads, for histories of `capacity` steps.
    pub fn first_needed(&self, capacity: u64) -> u64 {
        let refill = self.rejoin_at.saturating_sub(capacity);
        match self.checkpoint {
            Some(s) => shares_before(s, capacity).min(refill),
            None => refill,
        }
    }
}

/// The first step whose neighbour shares a checkpoint of step `s` may lack, for histories of
/// `capacity` steps: a process writes its checkpoint before the control of s with the shares it
/// has read by then, and a neighbour's share of a step before s may come in later (in lockstep
/// the neighbour sends it when it gets its own state, possibly after this agent's state of s
/// went out; the control of s does not need it when the delay reaches further back). The dead
/// process then used it at a later step, so the rebuild observes again the shares of
/// [s - capacity + 1, s) (each at its own slot: one already held is stored again unchanged).
pub fn shares_before(s: u64, capacity: u64) -> u64 {
    s.saturating_sub(capacity.saturating_sub(1))
}

/// What the rebuild found: how many replayed commands matched the recorded ones.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Replayed {
    /// Steps whose control was replayed.
    pub steps: u64,
    /// Of them, steps whose command differed from the recorded one (0 unless something is wrong).
    pub mismatches: u64,
}

/// Rebuilds `agent` (already restored from the checkpoint of `plan.checkpoint`, or fresh) up to
/// step `plan.rejoin_at`: observes the neighbour shares and the references the checkpoint may lack
/// ([`shares_before`]), replays the control of [checkpoint, down_from) and observes
/// [max(down_from, rejoin_at - capacity), rejoin_at) (cold: [rejoin_at - capacity, rejoin_at),
/// nothing before it having been observed), then re-synchronises its filters to the
/// vehicle's state of rejoin_at - 1 (`Agent::resync`, under `runtime.rejoin_resync`) and re-seeds
/// its RBFNN to the external acceleration the failsafe observed ([`observed_disturbance`],
/// `Agent::reseed`, under `runtime.rejoin_reseed`). `reference(k)` is the reference of step k,
/// `state(k, j)` the state quadrotor j had at step k, `recorded(k)` the thrust and torque command
/// quadrotor `agent` was flown with at step k: the agent's own before `down_from`, the held or
/// failsafe command from then on.
pub fn rebuild(
    agent: &mut Agent,
    plan: &Rejoin,
    mut reference: impl FnMut(u64) -> ReferenceFrame,
    state: impl Fn(u64, usize) -> VehicleState,
    recorded: impl Fn(u64) -> (f64, [f64; 3]),
) -> Replayed {
    let me = agent.id();
    let neighbours: Vec<usize> = agent.neighbour_ids().collect();
    let capacity = agent.history_capacity() as u64;
    if let Some(s) = plan.checkpoint {
        for k in shares_before(s, capacity).max(plan.recorded_from)..s {
            // The leader's frames of these steps may also have reached the process after its
            // checkpoint (a late stream on a busy machine): a pure function of the step, observed
            // again, unchanged where held.
            agent.observe_reference(&reference(k));
            for &j in &neighbours {
                agent.observe_neighbour(&crate::agent::share_of(&state(k, j)));
            }
        }
    }
    let mut observe = |agent: &mut Agent, k: u64| {
        agent.observe_reference(&reference(k));
        let own = state(k, me);
        agent.observe_own(&own);
        for &j in &neighbours {
            let s = state(k, j);
            agent.observe_neighbour(&crate::agent::share_of(&s));
        }
        own
    };
    let mut out = Replayed::default();
    if let Some(s) = plan.checkpoint {
        for k in s..plan.down_from {
            let own = observe(agent, k);
            let cmd = agent.step(&own);
            out.steps += 1;
            if (cmd.thrust_n, cmd.torque_nm) != recorded(k) {
                out.mismatches += 1;
            }
        }
    }
    // The histories hold the last `capacity` steps: every step the control of rejoin_at may read
    // (its delayed step, back by the staleness bound for a neighbour that was down) is in them.
    // Warm, the replay observed everything before down_from; cold, nothing was, so the refill
    // starts `capacity` steps back: a neighbour down over the whole window (lost with the same
    // host) is read at its last share before it went down, which precedes down_from.
    let window = plan
        .rejoin_at
        .saturating_sub(capacity)
        .max(plan.recorded_from);
    let refill = match plan.checkpoint {
        Some(_) => plan.down_from.max(window),
        None => window,
    };
    let mut last = None;
    for k in refill..plan.rejoin_at {
        last = Some(observe(agent, k));
    }
    // Bumpless re-entry: the filters meet the vehicle where the failsafe left it.
    if let Some(own) = last.filter(|_| agent.params().rejoin_resync) {
        agent.resync(&own);
    }
    // Re-entry that has learned: the network starts from what the failsafe observed.
    if let (Some(own), true) = (last, agent.params().rejoin_reseed) {
        let p = agent.params();
        let flown = |k: u64| (state(k, me), recorded(k).0);
        if let Some(d) = observed_disturbance(
            plan.down_from..plan.rejoin_at,
            flown,
            p.mass,
            p.gravity,
            p.dt,
        ) {
            agent.reseed(own.position, own.velocity, d);
        }
    }
    out
}

/// Rate of the disturbance observer a returning controller runs over its down window, 1/s: the
/// failsafe's own (`plant/src/fallback.rs`, `DISTURBANCE_OBSERVER_RATE`), so that it reads the
/// estimate the failsafe flew with at the return.
pub const OBSERVED_DISTURBANCE_RATE: f64 = 10.0;

/// The external acceleration quadrotor i met over `window` (m/s²), as the failsafe's observer
/// estimates it: at every step k whose next state is in the window, the acceleration measured
/// ((v_{k+1} - v_k) / dt) less the one its thrust T_k along its thrust axis at attitude A_k and
/// gravity give, low-passed at [`OBSERVED_DISTURBANCE_RATE`] from the first measurement.
/// `flown(k)` is the state of step k and the thrust it was flown with; `mass` the nominal mass
/// (kg). None for a window of fewer than two steps.
pub fn observed_disturbance(
    window: std::ops::Range<u64>,
    flown: impl Fn(u64) -> (VehicleState, f64),
    mass: f64,
    gravity: f64,
    dt: f64,
) -> Option<[f64; 3]> {
    let gain = (OBSERVED_DISTURBANCE_RATE * dt).min(1.0);
    let mut estimate: Option<[f64; 3]> = None;
    for k in window.start..window.end.saturating_sub(1) {
        let (x, thrust) = flown(k);
        let (next, _) = flown(k + 1);
        let [phi, theta, psi] = x.attitude;
        let (sf, cf) = phi.sin_cos();
        let (st, ct) = theta.sin_cos();
        let (sp, cp) = psi.sin_cos();
        let axis = [st * cp * cf + sp * sf, st * sp * cf - cp * sf, ct * cf];
        let measured: [f64; 3] = std::array::from_fn(|a| {
            let thrust_acc = axis[a] * thrust / mass - if a == 2 { gravity } else { 0.0 };
            (next.velocity[a] - x.velocity[a]) / dt - thrust_acc
        });
        estimate = Some(match estimate {
            None => measured,
            Some(e) => std::array::from_fn(|a| e[a] + (measured[a] - e[a]) * gain),
        });
    }
    estimate
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::agent::share_of;
    use formation_config::scenario::Scenario;
    use formation_config::Variant;

    /// Quadrotor j's state at step k: every quadrotor moving, each differently.
    fn moving(k: u64, j: usize) -> VehicleState {
        let t = k as f64 * 0.001;
        VehicleState {
            step: k,
            t,
            agent: j as u32,
            position: [
                j as f64 + 0.3 * t,
                0.5 * j as f64 - 0.2 * t * t,
                1.0 + 0.1 * t,
            ],
            velocity: [0.3, -0.4 * t, 0.1 + 0.01 * j as f64],
            ..VehicleState::default()
        }
    }

    /// A successor of agent `me` restored from the checkpoint of step `s` and rebuilt up to the
    /// step `down` the live controller went down at, checked against its `commands`.
    fn replay_warm(
        sc: &Scenario,
        me: usize,
        checkpoint: &[u8],
        (s, down): (u64, u64),
        commands: &[(f64, [f64; 3])],
    ) -> (Replayed, Rejoin) {
        let mut successor = Agent::new(sc, me, Variant::Proposed);
        successor.restore(checkpoint).unwrap();
        let plan = Rejoin {
            checkpoint: Some(s),
            down_from: down,
            rejoin_at: down + 1,
            recorded_from: 0,
        };
        let replayed = rebuild(&mut successor, &plan, reference, moving, |k| {
            commands[k.min(down - 1) as usize]
        });
        (replayed, plan)
    }

    fn reference(k: u64) -> ReferenceFrame {
        ReferenceFrame {
            step: k,
            t: k as f64 * 0.001,
            n_agents: 5,
            p_d: [0.1 * k as f64 * 0.001, 0.0, 1.0],
            ..ReferenceFrame::default()
        }
    }

    #[test]
    fn a_share_that_came_in_after_the_checkpoint_was_written_is_in_the_rebuilt_controller() {
        let sc = Scenario::paper();
        let me = 3;
        let mut live = Agent::new(&sc, me, Variant::Proposed);
        let nb: Vec<usize> = live.neighbour_ids().collect();
        let late = nb[0];
        // Checkpoint at s; the late neighbour's share of s - 1 comes in after the control of s
        // (which does not need it: its delay reaches further back), before that of s + 1.
        let (s, down) = (300u64, 420u64);
        let mut checkpoint = None;
        let mut commands = Vec::new();
        for k in 0..down {
            if k == s {
                assert!(
                    live.delayed_step(s) < s - 1,
                    "the control of s needs no share of s - 1"
                );
                checkpoint = Some(live.checkpoint().unwrap());
            }
            if k == s + 1 {
                live.observe_neighbour(&share_of(&moving(s - 1, late)));
            }
            live.observe_reference(&reference(k));
            let own = moving(k, me);
            live.observe_own(&own);
            for &j in &nb {
                if !(j == late && k == s - 1) {
                    live.observe_neighbour(&share_of(&moving(k, j)));
                }
            }
            let c = live.step(&own);
            commands.push((c.thrust_n, c.torque_nm));
        }
        let (replayed, plan) = replay_warm(&sc, me, &checkpoint.unwrap(), (s, down), &commands);
        assert_eq!(replayed.steps, down - s);
        assert_eq!(
            replayed.mismatches, 0,
            "the replay computes every command the live controller computed"
        );
        assert!(plan.first_needed(live.history_capacity() as u64) < s - 1);
    }

    /// The leader's frames of the steps just before the checkpoint reach the live process after
    /// it wrote the checkpoint of s (its control of s reads the delayed step only): the replay
    /// from that checkpoint still computes every command the live controller computed.
    #[test]
    fn references_that_came_in_after_the_checkpoint_was_written_are_in_the_rebuilt_controller() {
        let sc = Scenario::paper();
        let me = 2;
        let mut live = Agent::new(&sc, me, Variant::Proposed);
        let nb: Vec<usize> = live.neighbour_ids().collect();
        let (s, down) = (300u64, 420u64);
        let late = s - 5..s;
        assert!(
            live.delayed_step(s) < late.start,
            "the control of s needs none of them"
        );
        let mut checkpoint = None;
        let mut commands = Vec::new();
        for k in 0..down {
            if k == s {
                checkpoint = Some(live.checkpoint().unwrap());
            }
            if k == s + 1 {
                late.clone()
                    .for_each(|l| live.observe_reference(&reference(l)));
            }
            if !late.contains(&k) {
                live.observe_reference(&reference(k));
            }
            let own = moving(k, me);
            live.observe_own(&own);
            for &j in &nb {
                live.observe_neighbour(&share_of(&moving(k, j)));
            }
            let c = live.step(&own);
            commands.push((c.thrust_n, c.torque_nm));
        }
        let (replayed, _) = replay_warm(&sc, me, &checkpoint.unwrap(), (s, down), &commands);
        assert_eq!(
            (replayed.steps, replayed.mismatches),
            (down - s, 0),
            "the replay computes every command the live controller computed"
        );
    }

    /// Agents 4 and 5 (neighbours) lost together at step 10 and taken over cold at 126: the
    /// control of 126 reads agent 5 at its last share before it went down (step 9, within the
    /// staleness bound of the delayed step), which the rebuilt controller holds; without it
    /// the successor would wait for a share that no process will ever send.
    #[test]
    fn a_cold_successor_holds_the_last_share_of_a_neighbour_lost_with_it() {
        let sc = Scenario::paper();
        let (me, other) = (3, 4);
        let (down, rejoin) = (10u64, 126u64);
        let mut successor = Agent::new(&sc, me, Variant::Proposed);
        assert!(successor.neighbour_ids().any(|j| j == other));
        for i in [me, other] {
            let t = successor.timeline_mut();
            t.set_down(
                i,
                down,
                formation_config::scenario::events::EventKind::Crash,
            );
            t.set_up_again(i, rejoin);
        }
        let kd = successor.delayed_step(rejoin);
        assert!(
            kd >= down && kd - (down - 1) <= sc.runtime.stale_steps(sc.simulation.dt_s),
            "the control of {rejoin} reads agent 5 at step {} (delayed step {kd})",
            down - 1
        );
        let plan = Rejoin {
            checkpoint: None,
            down_from: down,
            rejoin_at: rejoin,
            recorded_from: 0,
        };
        let capacity = successor.history_capacity() as u64;
        assert!(plan.first_needed(capacity) < down - 1, "the file holds it");
        rebuild(&mut successor, &plan, reference, moving, |_| {
            (0.0, [0.0; 3])
        });
        successor.observe_reference(&reference(rejoin));
        successor.observe_own(&moving(rejoin, me));
        assert!(
            successor.ready(rejoin),
            "the successor computes its first step from what it rebuilt"
        );
    }

    /// A quadrotor tilted by 0.1 rad in roll with hover thrust along its axis, accelerating at
    /// exactly what its thrust gives plus a constant 0.7 m/s² along y: the observer reads 0.7 along
    /// y and 0 elsewhere (to rounding), and nothing from a window of one step.
    #[test]
    fn the_observed_disturbance_is_the_acceleration_the_thrust_does_not_explain() {
        let (m, g, dt) = (0.856, 9.81, 0.001);
        let phi: f64 = 0.1;
        let thrust = m * g / phi.cos();
        // Thrust axis at roll phi (theta = psi = 0): [0, -sin phi, cos phi].
        let acc = [
            0.0,
            -phi.sin() * thrust / m + 0.7,
            phi.cos() * thrust / m - g,
        ];
        let state = |k: u64| VehicleState {
            step: k,
            attitude: [phi, 0.0, 0.0],
            velocity: std::array::from_fn(|a| acc[a] * k as f64 * dt),
            ..VehicleState::default()
        };
        let d = observed_disturbance(100..300, |k| (state(k), thrust), m, g, dt).unwrap();
        assert!(
            d[0].abs() < 1e-9 && (d[1] - 0.7).abs() < 1e-9 && d[2].abs() < 1e-9,
            "{d:?}"
        );
        assert_eq!(
            observed_disturbance(5..6, |k| (state(k), thrust), m, g, dt),
            None
        );
    }
}
