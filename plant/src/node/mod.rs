//! The plant's event loop around [`crate::Plant`]. Each command is applied, its truth
//! taken and its quadrotor integrated as soon as it arrives (the quadrotors do not interact, so the
//! order of arrival changes nothing: `plant/tests/physics.rs`); once all N are in, k advances, the
//! states of k + 1 go out and then the step record of k.

mod lockstep;
mod ports;
mod realtime;

use lockstep::{Lockstep, States};

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
    let mut faults: Vec<FaultInjection> = Vec::new();
    let mut pace = Lockstep::new(n, steps);
    // Reading fewer subscribers per wake-up keeps the plant, which is on the critical path of every
    // step, short (docs/runtime.md, "Cost of a step"): the commands still missing on every wake-up;
    // stop and the lifeline on a wake-up that brought no command (a stop comes with a poke, the
    // parent's death with SIGTERM); progress and fault injections when the states of a step go out
    // at a multiple of HOUSEKEEPING_EVERY, on such a wake-up, and whenever the lead is used up.
    loop {
        let k = pace.k();
        let mut fresh = 0;
        for (i, sub) in ports.commands.iter().enumerate() {
            if arrived[i] {
                continue;
            }
            // One command per agent and step: a second receive would only find nothing (a
            // duplicate stays queued and is caught as out of step at the next step).
            if let Some(c) = sub.receive()? {
                if c.step != k || c.agent as usize != i {
                    return Err(NodeError::Protocol(format!(
                        "protocol error: command of agent {} for step {} while at step {k}",
                        c.agent, c.step
                    )));
                }
                // The quadrotors do not interact: each one moves to step k + 1 as soon as its
                // command is in, so only the last one is left for the last command (the states of
                // k + 1 still go out only once all N are in).
                plant.apply(i, &c);
                entries[i] = StepEntry {
                    truth: plant.truth(i),
                    command: *c,
                };
                plant.advance_vehicle(i);
                arrived[i] = true;
                pace.on_command();
                fresh += 1;
            }
        }
        // A wake-up without a command came from the orchestrator (progress, stop) or the timeout.
        let idle = fresh == 0;
        if idle {
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
            let k = pace.k();
            if pace.states_pending() && pace.must_read_slow_inputs(idle) {
                // Faults are forwarded before the progress that lets the plant reach their step,
                // so they are drained together with (after) the progress.
                while let Some(p) = ports.progress.receive()? {
                    pace.on_progress(p.recorded);
                }
                while let Some(f) = ports.faults.receive()? {
                    faults.push(*f);
                }
            }
            match pace.states() {
                States::Send => {
                    // Each agent is woken right after its state is out: the first ones start
                    // while the plant still publishes to the others.
                    for (i, (state, wake)) in
                        ports.states.iter().zip(&ports.agents_wake).enumerate()
                    {
                        send(state, plant.vehicle_state(i))?;
                        poke(wake);
                    }
                    pace.on_states_sent();
                    // Injections of step k act from its first command on.
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
                States::TellBlocked => {
                    poke(&ports.orchestrator_wake);
                    pace.on_told_blocked();
                }
                States::Wait => {}
            }
            // The record of the previous step goes out after the states of this one: the agents
            // are already computing while it is copied.
            if let Some(wake_orchestrator) = pace.take_record() {
                ports.publish_step(&entries)?;
                if wake_orchestrator {
                    poke(&ports.orchestrator_wake);
                }
            }
            if !pace.may_advance() {
                break;
            }
            arrived.fill(false);
            plant.advance();
            pace.on_advance();
        }
        ports.wake.wait(CHILD_WAIT)?;
    }
}
