//! The leader's event loop around [`crate::Mission`]: it keeps the references up to
//! `recorded + LEADER_LEAD` published, and wakes the agents only when one of them may be waiting.

use crate::Mission;
use formation_config::node::boot::{boot, hello};
use formation_config::node::error::{NodeError, PortError, PortErrorKind};
use formation_config::node::ports::{notifier, poke, publisher, subscriber, Wake};
use formation_config::protocol::messages::{Role, RunControl, RunProgress, CONTROL_STOP};
use formation_config::protocol::pacing::{CHILD_WAIT, LEADER_LEAD, PLANT_LEAD};
use formation_config::protocol::services;
use formation_config::protocol::wire::ReferenceFrame;

/// Runs the leader until the orchestrator says stop (or goes away).
pub fn run(args: formation_config::node::args::ChildArgs) -> Result<(), NodeError> {
    let b = boot(Role::Leader, args)?;
    let node = &b.node;
    let n = b.scenario.n_agents();
    let steps = b.scenario.n_steps();
    let dt = b.scenario.simulation.dt_s;
    let control = subscriber::<RunControl>(node, &services::CONTROL.named())?;
    let progress = subscriber::<RunProgress>(node, &services::PROGRESS.named())?;
    let reference_name = services::REFERENCE.named().name;
    let reference = publisher::<ReferenceFrame>(node, &services::REFERENCE.named())?;
    let agents_wake = (0..n)
        .map(|i| notifier(node, &services::WAKE_AGENT.at(i)))
        .collect::<Result<Vec<_>, _>>()?;
    let wake = Wake::open(node, &services::WAKE_LEADER.named())?;
    let _greeting = hello(node, Role::Leader, 0)?;
    // The leader runs LEADER_LEAD steps ahead: it never needs the CPU before a plant or an agent.
    formation_config::node::sched::background_thread();
    let mission = Mission::from_scenario(&b.scenario);
    let mut frame = ReferenceFrame::default();
    let mut head: u64 = 0;
    let mut recorded: Option<u64> = None;
    loop {
        while let Some(c) = control.receive()? {
            if c.kind == CONTROL_STOP {
                tracing::info!(published = head, "stop received");
                return Ok(());
            }
        }
        while let Some(p) = progress.receive()? {
            recorded = Some(recorded.map_or(p.recorded, |r| r.max(p.recorded)));
        }
        if let Some(r) = recorded {
            let allowed = (r + LEADER_LEAD).min(steps);
            if head < allowed {
                // An agent can only be waiting for a reference the plant may already have reached.
                let someone_may_wait = head <= r + PLANT_LEAD + 1;
                while head < allowed {
                    mission.reference(head, head as f64 * dt, &mut frame);
                    let sample = reference
                        .loan_uninit()
                        .map_err(|e| PortError::new(&reference_name, PortErrorKind::Send, e))?;
                    sample
                        .write_payload(frame)
                        .send()
                        .map_err(|e| PortError::new(&reference_name, PortErrorKind::Send, e))?;
                    head += 1;
                }
                if someone_may_wait {
                    agents_wake.iter().for_each(poke);
                }
            }
        }
        if let Some(why) = b.lifeline.must_stop() {
            return Err(NodeError::Stopped(format!(
                "stopping at reference {head}: {why}"
            )));
        }
        wake.wait(CHILD_WAIT)?;
    }
}
