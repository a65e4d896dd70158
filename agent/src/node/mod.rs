//! Agent i's event loop around [`crate::Agent`]. Per step k, as in the in-process
//! runner: observe the reference of k, the own state of k (sharing it at once), the neighbours'
//! shares, and compute the command of k once `ready(k)`. References arriving early are held here
//! and handed to the agent only when their step comes, so its delay histories match the in-process
//! run exactly.

mod early_references;
mod neighbour_delay;
mod ports;
mod realtime;
mod rejoin;
mod shares;
mod telemetry;

use crate::Agent;
use formation_config::node::boot::{boot, hello};
use formation_config::node::error::NodeError;
use formation_config::node::ports::{poke, send};
use formation_config::protocol::messages::{Role, CONTROL_STOP, EVENT_DOWN};
use formation_config::protocol::pacing::{CHILD_WAIT, HOUSEKEEPING_EVERY};
use formation_config::protocol::wire::{DelayInjection, NeighbourState, VehicleState};

/// Runs agent `--agent i` until the orchestrator says stop (or goes away).
pub fn run(args: formation_config::node::args::ChildArgs) -> Result<(), NodeError> {
    let b = boot(Role::Agent, args)?;
    let i = b
        .args
        .agent
        .ok_or_else(|| NodeError::Args("--agent is required".into()))?;
    let mut agent = Agent::new(&b.scenario, i, b.variant);
    let neighbours: Vec<usize> = agent.neighbour_ids().collect();
    let ports = ports::Ports::open(&b.node, i, &neighbours)?;
    // A new process taking over rebuilds its controller before it says hello (the plant sends it
    // nothing before that); its references come from the mission itself, which is what the leader
    // computes, because the leader's stream of the steps it missed is gone.
    let (start, local_mission) = match b.args.rejoin_at {
        Some(r) => {
            rejoin::rebuild(&b, i, &mut agent, r)?;
            (
                r,
                Some(formation_leader::Mission::from_scenario(&b.scenario)),
            )
        }
        None => (0, None),
    };
    let _greeting = hello(&b.node, Role::Agent, i as u32)?;
    let mut checkpoints = rejoin::Checkpoints::new(&b, i, start);
    if b.args.realtime {
        return realtime::run(&b, i, agent, &ports, &mut checkpoints, local_mission);
    }
    let mut local_reference = formation_config::protocol::wire::ReferenceFrame::default();
    let mut delays = neighbour_delay::NeighbourDelays::new(&b.scenario, &neighbours);
    let mut refs = early_references::EarlyReferences::for_entries(
        std::iter::once(i)
            .chain(neighbours.iter().copied())
            .collect(),
    );
    let mut pending_delays: Vec<DelayInjection> = Vec::new();
    let mut own: Option<VehicleState> = None;
    let mut observed = false;
    let mut share_later: Option<NeighbourState> = None;
    let mut k: u64 = start;
    let mut sampler = telemetry::Sampler::new(&b.scenario, i);
    let mut shares = shares::Shares::new(neighbours.len());
    tracing::info!(
        agent = i + 1,
        neighbours = ?neighbours.iter().map(|j| j + 1).collect::<Vec<_>>(),
        "agent ready"
    );
    // The per-step inputs (own state, neighbour shares up to the previous step, see `shares`) are
    // read on every wake-up; the slow ones (stop, delay injections, references) with the state of
    // every HOUSEKEEPING_EVERY-th step, when a reference is missing, and on any wake-up that brought
    // no state (docs/runtime.md, "Cost of a step").
    loop {
        shares.read_due(&ports.shares_in, k, &mut agent)?;
        let mut fresh = false;
        // One state per step: once it is in, the next one is read at the next step (a duplicate
        // is then caught as out of step).
        if own.is_none() {
            if let Some(s) = ports.state.receive()? {
                if s.step != k {
                    return Err(NodeError::Protocol(format!(
                        "protocol error: state of step {} while at step {k}",
                        s.step
                    )));
                }
                own = Some(*s);
                fresh = true;
            }
        }
        let reference_missing = local_mission.is_none() && refs.missing(k);
        if must_read_slow_inputs(fresh, reference_missing, k) {
            while let Some(c) = ports.control.receive()? {
                if c.kind == CONTROL_STOP {
                    tracing::info!(
                        step = k,
                        telemetry_samples = sampler.sent(),
                        telemetry_mean_send_us = sampler.mean_send_us(),
                        "stop received"
                    );
                    return Ok(());
                }
            }
            if let Some(why) = b.lifeline.must_stop() {
                return Err(NodeError::Stopped(format!(
                    "agent {} stopping at step {k}: {why}",
                    i + 1
                )));
            }
            while let Some(d) = ports.delays.receive()? {
                delays.observe(&d);
                pending_delays.push(*d);
            }
            while let Some(e) = ports.events.receive()? {
                e.apply(agent.timeline_mut());
                if e.kind == EVENT_DOWN {
                    agent.taken_down(e.agent as usize, e.step);
                }
            }
            while let Some(r) = ports.reference.receive()? {
                if local_mission.is_none() {
                    refs.push(&r)?;
                }
            }
        }
        match &local_mission {
            None => refs.take_due(k, |r| {
                agent.observe_reference(r);
                sampler.observe_reference(r);
            }),
            // Once per step (the frame carries its step; a process taking over starts at k > 0).
            Some(m) if local_reference.step != k => {
                m.reference(
                    k,
                    k as f64 * b.scenario.simulation.dt_s,
                    &mut local_reference,
                );
                agent.observe_reference(&local_reference);
                sampler.observe_reference(&local_reference);
            }
            Some(_) => {}
        }
        pending_delays.retain(|d| {
            if d.step <= k {
                agent.set_delay(d);
                if d.agent as usize == i {
                    tracing::info!(
                        step = k,
                        base_s = d.base_s,
                        amplitude_s = d.amplitude_s,
                        rate_rad_s = d.angular_rate_rad_s,
                        "delay injection applied"
                    );
                }
                false
            } else {
                true
            }
        });
        if let Some(s) = own {
            if !observed {
                let share = agent.observe_own(&s);
                // The share goes out before the command only if a neighbour may need it before
                // this agent's next step, which cannot start before the command is in (a neighbour
                // whose delayed step is this one is also woken). Otherwise it goes out after the
                // command, off the critical path of the step.
                // Before a down window the share goes out first: the process may be killed any time
                // after its last command.
                let last_before_down = !agent.timeline().up(i, k + 1);
                if last_before_down
                    || share_before_command(
                        (0..ports.neighbours_wake.len())
                            .map(|idx| delays.needed_before_next_step(idx, k)),
                    )
                {
                    send(&ports.share_out, share)?;
                } else {
                    share_later = Some(share);
                }
                for (idx, n) in ports.neighbours_wake.iter().enumerate() {
                    if delays.needs_now(idx, k) {
                        poke(n);
                    }
                }
                observed = true;
            }
            if !agent.ready(k) {
                // A delay that rounds to zero steps needs a share of this very step.
                shares.read_all(&ports.shares_in, &mut agent)?;
            }
            if agent.ready(k) {
                checkpoints.before_step(&agent, k);
                let sample = sampler.due(k);
                let started = sample.then(std::time::Instant::now);
                let cmd = agent.step(&s);
                send(&ports.command, cmd)?;
                poke(&ports.plant_wake);
                if let Some(share) = share_later.take() {
                    send(&ports.share_out, share)?;
                }
                if let Some(t0) = started {
                    let latency = t0.elapsed();
                    let t1 = std::time::Instant::now();
                    // Best effort: a failed telemetry send never disturbs control.
                    let _ = send(&ports.telemetry, sampler.sample(&s, &cmd, latency));
                    sampler.count_send(t1.elapsed());
                }
                k += 1;
                own = None;
                observed = false;
            }
        }
        ports.wake.wait(CHILD_WAIT)?;
    }
}

/// Whether the slow inputs (stop, delay injections, references) are read on this wake-up: when it
/// brought no state of step k (`fresh_state` false: the wake-up came from the orchestrator, the
/// leader or a timeout), when the reference of step k is missing, and every HOUSEKEEPING_EVERY
/// steps. Otherwise the wake-up is the plant's, and only the per-step inputs are read.
fn must_read_slow_inputs(fresh_state: bool, reference_missing: bool, k: u64) -> bool {
    !fresh_state || reference_missing || k.is_multiple_of(HOUSEKEEPING_EVERY)
}

/// Whether the share of step k goes out before the command: only if some neighbour may need it
/// before this agent's next step (`needed`, one answer per neighbour); otherwise it goes out after
/// the command, off the critical path of the step.
fn share_before_command(mut needed: impl Iterator<Item = bool>) -> bool {
    needed.any(|n| n)
}

#[cfg(test)]
mod decisions {
    use super::*;

    #[test]
    fn a_plant_wake_up_with_the_state_and_the_reference_reads_no_slow_input() {
        assert!(!must_read_slow_inputs(true, false, HOUSEKEEPING_EVERY + 1));
    }

    #[test]
    fn slow_inputs_are_read_without_a_state_with_a_missing_reference_and_every_period() {
        assert!(
            must_read_slow_inputs(false, false, 3),
            "no state: another wake-up"
        );
        assert!(
            must_read_slow_inputs(true, true, 3),
            "reference of k missing"
        );
        assert!(must_read_slow_inputs(true, false, 2 * HOUSEKEEPING_EVERY));
    }

    #[test]
    fn the_share_goes_out_first_only_if_a_neighbour_may_need_it_before_the_next_step() {
        assert!(!share_before_command([false, false].into_iter()));
        assert!(share_before_command([false, true].into_iter()));
        assert!(!share_before_command(std::iter::empty()), "no neighbour");
    }
}
