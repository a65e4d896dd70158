//! The leader's event loop around [`formation_leader::Mission`]: it keeps the references up to
//! `recorded + LEADER_LEAD` published, and wakes the agents only when one of them may be waiting.

use formation_config::runtime::boot::{boot, hello};
use formation_config::runtime::messages::{RunControl, RunProgress, CONTROL_STOP, ROLE_LEADER};
use formation_config::runtime::ports::{notifier, poke, publisher, subscriber, Wake};
use formation_config::runtime::{self as rt, CHILD_WAIT, LEADER_LEAD, PLANT_LEAD};
use formation_config::services;
use formation_config::wire::ReferenceFrame;
use formation_leader::Mission;

/// Runs the leader until the orchestrator says stop (or goes away).
pub fn run() -> Result<(), String> {
    let b = boot("leader")?;
    let node = &b.node;
    let n = b.scenario.n_agents();
    let steps = b.scenario.n_steps();
    let dt = b.scenario.simulation.dt_s;
    let control = subscriber::<RunControl>(node, rt::CONTROL)?;
    let progress = subscriber::<RunProgress>(node, rt::PROGRESS)?;
    let reference = publisher::<ReferenceFrame>(node, services::REFERENCE)?;
    let agents_wake = (0..n)
        .map(|i| notifier(node, &rt::wake_agent(i)))
        .collect::<Result<Vec<_>, _>>()?;
    let wake = Wake::open(node, rt::WAKE_LEADER)?;
    let _greeting = hello(node, ROLE_LEADER, 0)?;
    // The leader runs LEADER_LEAD steps ahead: it never needs the CPU before a plant or an agent.
    formation_config::runtime::sched::background_thread();
    let mission = Mission::from_scenario(&b.scenario);
    let mut frame = ReferenceFrame::default();
    let mut head: u64 = 0;
    let mut recorded: Option<u64> = None;
    loop {
        while let Some(c) = control.receive().map_err(|e| format!("{e:?}"))? {
            if c.kind == CONTROL_STOP {
                tracing::info!(published = head, "stop received");
                return Ok(());
            }
        }
        while let Some(p) = progress.receive().map_err(|e| format!("{e:?}"))? {
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
                        .map_err(|e| format!("cannot loan a reference frame: {e:?}"))?;
                    sample
                        .write_payload(frame)
                        .send()
                        .map_err(|e| format!("cannot send a reference frame: {e:?}"))?;
                    head += 1;
                }
                if someone_may_wait {
                    agents_wake.iter().for_each(poke);
                }
            }
        }
        if let Some(why) = b.lifeline.must_stop() {
            return Err(format!("stopping at reference {head}: {why}"));
        }
        wake.wait(CHILD_WAIT)?;
    }
}
