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
}

impl Rejoin {
    /// The first step whose recorded states the rebuild reads, for histories of `capacity` steps.
    pub fn first_needed(&self, capacity: u64) -> u64 {
        let refill = self.rejoin_at.saturating_sub(capacity);
        match self.checkpoint {
            Some(s) => s.min(refill),
            None => refill,
        }
    }
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
/// step `plan.rejoin_at`: replays the control of [checkpoint, down_from) and observes
/// [max(down_from, rejoin_at - capacity), rejoin_at), then re-synchronises its filters to the
/// vehicle's state of rejoin_at - 1 (`Agent::resync`, under `runtime.rejoin_resync`). `reference(k)` is the reference of step k,
/// `state(k, j)` the state quadrotor j had at step k, `recorded(k)` the thrust and torque command
/// the agent sent at step k.
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
    let refill = plan.down_from.max(plan.rejoin_at.saturating_sub(capacity));
    let mut last = None;
    for k in refill..plan.rejoin_at {
        last = Some(observe(agent, k));
    }
    // Bumpless re-entry: the filters meet the vehicle where the failsafe left it.
    if let Some(own) = last.filter(|_| agent.params().rejoin_resync) {
        agent.resync(&own);
    }
    out
}
