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
use formation_config::node::boot::{boot, hello, Boot};
use formation_config::node::error::NodeError;
use formation_config::node::ports::{poke, send};
use formation_config::protocol::messages::{Role, CONTROL_STOP, EVENT_DOWN};
use formation_config::protocol::pacing::{CHILD_WAIT, HOUSEKEEPING_EVERY};
use formation_config::protocol::wire::{
    DelayInjection, NeighbourState, ReferenceFrame, VehicleState,
};

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
    let mut node = Lockstep {
        b: &b,
        i,
        ports: &ports,
        checkpoints,
        local_mission,
        local_reference: ReferenceFrame::default(),
        delays: neighbour_delay::NeighbourDelays::new(&b.scenario, &neighbours),
        refs: early_references::EarlyReferences::for_entries(
            std::iter::once(i)
                .chain(neighbours.iter().copied())
                .collect(),
        ),
        pending_delays: Vec::new(),
        own: None,
        observed: false,
        share_later: None,
        k: start,
        sampler: telemetry::Sampler::new(&b.scenario, i),
        shares: shares::Shares::new(neighbours.len()),
        agent,
    };
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
        if node.wake_up()? == Wake::Stop {
            return Ok(());
        }
        ports.wake.wait(CHILD_WAIT)?;
    }
}

/// What the loop does after a wake-up.
#[derive(Debug, PartialEq, Eq)]
enum Wake {
    /// Wait for the next one.
    Wait,
    /// The orchestrator said stop.
    Stop,
}

/// Agent i in lockstep: the controller and what its loop holds between wake-ups.
struct Lockstep<'a> {
    b: &'a Boot,
    /// Agent index i (0-based).
    i: usize,
    ports: &'a ports::Ports,
    agent: Agent,
    checkpoints: rejoin::Checkpoints,
    /// A process taking over computes its references from the mission itself.
    local_mission: Option<formation_leader::Mission>,
    /// The reference frame of the current step computed from `local_mission`.
    local_reference: ReferenceFrame,
    delays: neighbour_delay::NeighbourDelays,
    /// References that arrived before their step.
    refs: early_references::EarlyReferences,
    /// Delay injections not yet at their step.
    pending_delays: Vec<DelayInjection>,
    /// The state of step k, once it is in.
    own: Option<VehicleState>,
    /// The state of step k is observed (and its share sent or held in `share_later`).
    observed: bool,
    /// The share of step k held to go out after the command.
    share_later: Option<NeighbourState>,
    /// The step being computed.
    k: u64,
    sampler: telemetry::Sampler,
    shares: shares::Shares,
}

impl Lockstep<'_> {
    /// Reads what a wake-up brought and answers step k if it can.
    fn wake_up(&mut self) -> Result<Wake, NodeError> {
        let k = self.k;
        self.shares
            .read_due(&self.ports.shares_in, k, &mut self.agent)?;
        let fresh = self.receive_state()?;
        let reference_missing = self.local_mission.is_none() && self.refs.missing(k);
        if must_read_slow_inputs(fresh, reference_missing, k)
            && self.read_slow_inputs()? == Wake::Stop
        {
            return Ok(Wake::Stop);
        }
        self.take_reference();
        self.apply_due_delays();
        if let Some(s) = self.own {
            if !self.observed {
                self.share_own(&s)?;
                self.observed = true;
            }
            if !self.agent.ready(k) {
                // A delay that rounds to zero steps needs a share of this very step.
                self.shares
                    .read_all(&self.ports.shares_in, &mut self.agent)?;
            }
            if self.agent.ready(k) {
                self.answer(&s)?;
            }
        }
        Ok(Wake::Wait)
    }

    /// Takes the state of step k if it came: one state per step, so once it is in the next one is
    /// read at the next step (a duplicate is then caught as out of step). Whether it came now.
    fn receive_state(&mut self) -> Result<bool, NodeError> {
        if self.own.is_some() {
            return Ok(false);
        }
        let Some(s) = self.ports.state.receive()? else {
            return Ok(false);
        };
        if s.step != self.k {
            return Err(NodeError::Protocol(format!(
                "protocol error: state of step {} while at step {}",
                s.step, self.k
            )));
        }
        self.own = Some(*s);
        Ok(true)
    }

    /// Reads the slow inputs: stop, the lifeline, delay injections, runtime events, references.
    fn read_slow_inputs(&mut self) -> Result<Wake, NodeError> {
        let (k, ports) = (self.k, self.ports);
        while let Some(c) = ports.control.receive()? {
            if c.kind == CONTROL_STOP {
                tracing::info!(
                    step = k,
                    telemetry_samples = self.sampler.sent(),
                    telemetry_mean_send_us = self.sampler.mean_send_us(),
                    "stop received"
                );
                return Ok(Wake::Stop);
            }
        }
        if let Some(why) = self.b.lifeline.must_stop() {
            return Err(NodeError::Stopped(format!(
                "agent {} stopping at step {k}: {why}",
                self.i + 1
            )));
        }
        while let Some(d) = ports.delays.receive()? {
            self.delays.observe(&d);
            self.pending_delays.push(*d);
        }
        while let Some(e) = ports.events.receive()? {
            e.apply(self.agent.timeline_mut());
            if e.kind == EVENT_DOWN {
                self.agent.taken_down(e.agent as usize, e.step);
            }
        }
        while let Some(r) = ports.reference.receive()? {
            if self.local_mission.is_none() {
                self.refs.push(&r)?;
            }
        }
        Ok(Wake::Wait)
    }

    /// Hands the reference of step k to the agent: the leader's once its step has come, or, for a
    /// process taking over, the mission's (once per step: the frame carries its step, and such a
    /// process starts at k > 0).
    fn take_reference(&mut self) {
        let k = self.k;
        let (agent, sampler) = (&mut self.agent, &mut self.sampler);
        match &self.local_mission {
            None => self.refs.take_due(k, |r| {
                agent.observe_reference(r);
                sampler.observe_reference(r);
            }),
            Some(m) if self.local_reference.step != k => {
                m.reference(
                    k,
                    k as f64 * self.b.scenario.simulation.dt_s,
                    &mut self.local_reference,
                );
                agent.observe_reference(&self.local_reference);
                sampler.observe_reference(&self.local_reference);
            }
            Some(_) => {}
        }
    }

    /// Applies the delay injections of step k and before.
    fn apply_due_delays(&mut self) {
        let (k, i, agent) = (self.k, self.i, &mut self.agent);
        self.pending_delays.retain(|d| {
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
    }

    /// Observes the own state `s` of step k and shares it: before the command only if a neighbour
    /// may need it before this agent's next step, which cannot start before the command is in (a
    /// neighbour whose delayed step is this one is also woken); otherwise after the command, off
    /// the critical path of the step. Before a down window the share goes out first: the process
    /// may be killed any time after its last command.
    fn share_own(&mut self, s: &VehicleState) -> Result<(), NodeError> {
        let (k, ports) = (self.k, self.ports);
        let share = self.agent.observe_own(s);
        let last_before_down = !self.agent.timeline().up(self.i, k + 1);
        if last_before_down
            || share_before_command(
                (0..ports.neighbours_wake.len())
                    .map(|idx| self.delays.needed_before_next_step(idx, k)),
            )
        {
            send(&ports.share_out, share)?;
        } else {
            self.share_later = Some(share);
        }
        for (idx, n) in ports.neighbours_wake.iter().enumerate() {
            if self.delays.needs_now(idx, k) {
                poke(n);
            }
        }
        Ok(())
    }

    /// Computes and sends the command of step k for the own state `s`, then the held share and a
    /// telemetry sample when one is due, and moves on to step k + 1.
    fn answer(&mut self, s: &VehicleState) -> Result<(), NodeError> {
        let (k, ports) = (self.k, self.ports);
        self.checkpoints.before_step(&self.agent, k);
        let sample = self.sampler.due(k);
        let started = sample.then(std::time::Instant::now);
        let cmd = self.agent.step(s);
        send(&ports.command, cmd)?;
        poke(&ports.plant_wake);
        self.sampler.observe_command(&cmd);
        if let Some(share) = self.share_later.take() {
            send(&ports.share_out, share)?;
        }
        if let Some(t0) = started {
            let latency = t0.elapsed();
            let t1 = std::time::Instant::now();
            // Best effort: a failed telemetry send never disturbs control.
            let _ = send(&ports.telemetry, self.sampler.sample(s, &cmd, latency));
            self.sampler.count_send(t1.elapsed());
        }
        self.k += 1;
        self.own = None;
        self.observed = false;
        Ok(())
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
