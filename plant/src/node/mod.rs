//! The plant's event loop around [`crate::Plant`]. Each command is applied, its truth
//! taken and its quadrotor integrated as soon as it arrives (the quadrotors do not interact, so the
//! order of arrival changes nothing: `plant/tests/physics.rs`); once all N are in, k advances, the
//! states of k + 1 go out and then the step record of k.

mod deadline;
mod lockstep;
mod ports;
mod realtime;
mod roster;

use lockstep::{Lockstep, States};
use roster::{Reaction, Roster};

use crate::Plant;
use formation_config::node::boot::{boot, hello};
use formation_config::node::error::NodeError;
use formation_config::node::ports::{poke, send};
use formation_config::protocol::messages::{Role, StepEntry, CONTROL_STOP};
use formation_config::protocol::pacing::CHILD_WAIT;
use formation_config::protocol::wire::FaultInjection;

/// Runs the plant until the orchestrator says stop (or goes away).
pub fn run(args: formation_config::node::args::ChildArgs) -> Result<(), NodeError> {
    let b = boot(Role::Plant, args)?;
    let n = b.scenario.n_agents();
    let steps = b.scenario.n_steps();
    let ports = ports::Ports::open(&b.node, n)?;
    let _greeting = hello(&b.node, Role::Plant, 0)?;
    let mut plant = Plant::from_scenario(&b.scenario);
    if b.args.realtime {
        return realtime::run(&b, &ports, plant);
    }
    let mut arrived = vec![false; n];
    let mut entries = vec![StepEntry::default(); n];
    // The scenario's fault events go the way of the live injections.
    let mut faults: Vec<FaultInjection> = scenario_faults(&b.scenario);
    let mut roster = Roster::new(n, b.scenario.timeline());
    let runtime = b.scenario.runtime.clone();
    let mut pace = Lockstep::new(n, steps);
    let mut st = Step {
        plant: &mut plant,
        roster: &mut roster,
        runtime: &runtime,
        arrived: &mut arrived,
        entries: &mut entries,
        pace: &mut pace,
    };
    // Reading fewer subscribers per wake-up keeps the plant, which is on the critical path of every
    // step, short (docs/runtime.md, "Cost of a step"): the commands still missing on every wake-up;
    // stop and the lifeline on a wake-up that brought no command (a stop comes with a poke, the
    // parent's death with SIGTERM); progress and fault injections when the states of a step go out
    // at a multiple of HOUSEKEEPING_EVERY, on such a wake-up, and whenever the lead is used up.
    loop {
        let k = st.pace.k();
        let fresh = st.receive_commands(&ports)?;
        // A wake-up without a command came from the orchestrator (progress, stop, a runtime event)
        // or the timeout.
        let idle = fresh == 0;
        if idle {
            st.drain_events(&ports)?;
            while let Some(c) = ports.control.receive()? {
                if c.kind == CONTROL_STOP {
                    tracing::info!(step = k, "stop received");
                    return Ok(());
                }
            }
            if let Some(why) = b.lifeline.must_stop() {
                return Err(NodeError::Stopped(format!("stopping at step {k}: {why}")));
            }
        }
        loop {
            let k = st.pace.k();
            if st.pace.states_pending() && st.pace.must_read_slow_inputs(idle) {
                // Faults are forwarded before the progress that lets the plant reach their step,
                // so they are drained together with (after) the progress.
                while let Some(p) = ports.progress.receive()? {
                    st.pace.on_progress(p.recorded);
                }
                while let Some(f) = ports.faults.receive()? {
                    faults.push(*f);
                }
                st.drain_events(&ports)?;
            }
            let awaited = st.roster.awaited(k);
            match st.pace.states() {
                States::Send if awaited.is_some() => {
                    // A new agent process takes over at k: its neighbours' shares of k must reach
                    // its subscribers, so no state of k goes out before it has joined. The record
                    // of k - 1 (which it rebuilds from) goes out meanwhile.
                    if st.pace.take_record().is_some() {
                        ports.publish_step(st.entries)?;
                    }
                    poke(&ports.orchestrator_wake);
                }
                States::Send => {
                    // Injections of step k act from its first command on.
                    apply_due_faults(st.plant, &mut faults, k);
                    st.send_states(&ports, k)?;
                }
                States::TellBlocked => {
                    poke(&ports.orchestrator_wake);
                    st.pace.on_told_blocked();
                }
                States::Wait => {}
            }
            // The record of the previous step goes out after the states of this one: the agents
            // are already computing while it is copied.
            st.publish_record(&ports)?;
            if !st.pace.may_advance() {
                break;
            }
            st.arrived.fill(false);
            st.plant.advance();
            st.pace.on_advance();
        }
        ports.wake.wait(CHILD_WAIT)?;
    }
}

/// Injects the `faults` of step `k` and before into `plant` (they act from its first command on)
/// and drops them from the list.
fn apply_due_faults(plant: &mut Plant, faults: &mut Vec<FaultInjection>, k: u64) {
    faults.retain(|f| {
        if f.step <= k {
            plant.inject_fault(f);
            tracing::info!(
                step = k,
                agent = f.agent + 1,
                gamma = ?f.gamma,
                delta = ?f.delta,
                mode = f.mode,
                "fault injection applied"
            );
            false
        } else {
            true
        }
    });
}

/// Flies quadrotor i on its fallback at step k (its controller down) and integrates it.
fn fly_fallback(
    plant: &mut Plant,
    roster: &Roster,
    runtime: &formation_config::scenario::events::Runtime,
    i: usize,
    k: u64,
    entries: &mut [StepEntry],
) {
    let since = roster.down_for(i, k).unwrap_or(0);
    let command = plant.apply_fallback(i, since, runtime);
    entries[i] = StepEntry {
        truth: plant.truth(i),
        command,
    };
    plant.advance_vehicle(i);
}

/// The fault events of the scenario's timeline as injections.
pub(super) fn scenario_faults(s: &formation_config::Scenario) -> Vec<FaultInjection> {
    let dt = s.simulation.dt_s;
    s.timeline()
        .changes()
        .iter()
        .filter_map(|c| FaultInjection::of_change(c, dt))
        .collect()
}

/// The parts of the plant's loop a runtime event may change.
struct Step<'a> {
    plant: &'a mut Plant,
    roster: &'a mut Roster,
    runtime: &'a formation_config::scenario::events::Runtime,
    arrived: &'a mut [bool],
    entries: &'a mut [StepEntry],
    pace: &'a mut Lockstep,
}

impl Step<'_> {
    /// Takes in the commands of step k still missing, one per agent (a second receive would only
    /// find nothing: a duplicate stays queued and is caught as out of step at the next step), and
    /// moves each quadrotor whose command is in to step k + 1 at once (the quadrotors do not
    /// interact; the states of k + 1 still go out only once all N are in). Returns how many came.
    fn receive_commands(&mut self, ports: &ports::Ports) -> Result<usize, NodeError> {
        let k = self.pace.k();
        let mut fresh = 0;
        for (i, sub) in ports.commands.iter().enumerate() {
            if self.arrived[i] {
                continue;
            }
            if let Some(c) = sub.receive()? {
                if c.step != k || c.agent as usize != i {
                    return Err(NodeError::Protocol(format!(
                        "protocol error: command of agent {} for step {} while at step {k}",
                        c.agent, c.step
                    )));
                }
                self.plant.apply(i, &c);
                self.entries[i] = StepEntry {
                    truth: self.plant.truth(i),
                    command: *c,
                };
                self.plant.advance_vehicle(i);
                self.arrived[i] = true;
                self.pace.on_command();
                fresh += 1;
            }
        }
        Ok(fresh)
    }

    /// Sends the states of step k, each agent woken right after its own is out (the first ones
    /// start while the plant still publishes to the others); a quadrotor whose controller is down
    /// flies its fallback instead, its entry written at once, so the record of k - 1 goes out
    /// before.
    fn send_states(&mut self, ports: &ports::Ports, k: u64) -> Result<(), NodeError> {
        if (0..self.arrived.len()).any(|i| self.roster.down_for(i, k).is_some()) {
            self.publish_record(ports)?;
        }
        for (i, (state, wake)) in ports.states.iter().zip(&ports.agents_wake).enumerate() {
            if self.roster.down_for(i, k).is_some() {
                fly_fallback(self.plant, self.roster, self.runtime, i, k, self.entries);
                self.arrived[i] = true;
                self.pace.on_command();
                continue;
            }
            send(state, self.plant.vehicle_state(i))?;
            poke(wake);
        }
        self.pace.on_states_sent();
        Ok(())
    }

    /// Publishes the record of the previous step if it is due, waking the orchestrator if it
    /// waits for it.
    fn publish_record(&mut self, ports: &ports::Ports) -> Result<(), NodeError> {
        if let Some(wake_orchestrator) = self.pace.take_record() {
            ports.publish_step(self.entries)?;
            if wake_orchestrator {
                poke(&ports.orchestrator_wake);
            }
        }
        Ok(())
    }

    /// Takes in every pending runtime event; a take-down request takes the agent down at the
    /// first step whose command is missing (this one unless it is in), says so to everyone, and
    /// flies the quadrotor on its fallback at once if the plant is waiting for that command.
    fn drain_events(&mut self, ports: &ports::Ports) -> Result<(), NodeError> {
        let k = self.pace.k();
        while let Some(e) = ports.events.receive()? {
            if let Reaction::TakeDown(i) = self.roster.on_event(&e) {
                let from = if self.arrived[i] { k + 1 } else { k };
                send(&ports.events_out, self.roster.take_down(i, from))?;
                // Neighbours waiting for its shares learn it now, not at their next timeout.
                ports.agents_wake.iter().for_each(poke);
                tracing::warn!(
                    agent = i + 1,
                    step = from,
                    "agent taken down: its process is gone"
                );
                if !self.arrived[i] && !self.pace.states_pending() {
                    fly_fallback(self.plant, self.roster, self.runtime, i, k, self.entries);
                    self.arrived[i] = true;
                    self.pace.on_command();
                }
            }
        }
        Ok(())
    }
}
