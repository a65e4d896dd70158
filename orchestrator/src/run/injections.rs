//! The orchestrator's side of `formation inject`: it drains the requests, validates them again
//! against the run's scenario, picks the step they apply at, forwards them to the plant (faults) or
//! the agents (delays), and appends one line per request to `DIR/events.jsonl`.
//!
//! The apply step is the requested one if it is far enough ahead, else the first step the plant
//! cannot have reached yet (`recorded + PLANT_LEAD + SLACK`). Requests are forwarded before the
//! orchestrator announces new progress, so the plant and the agents hold them before they can reach
//! that step: results of a lockstep run stay deterministic for a given apply step.

use crate::live::registry::unix_now;
use crate::live::validate::{self, DelayProfile};
use formation_config::node::error::PortError;
use formation_config::node::ports::{publisher, send, subscriber, Input, Output, RunNode};
use formation_config::protocol::messages::{
    InjectRequest, RuntimeEvent, INJECT_ASAP, INJECT_CRASH, INJECT_DELAY, INJECT_FAULT,
    INJECT_HANG, INJECT_LINK_DOWN, INJECT_LINK_UP,
};
use formation_config::protocol::pacing::PLANT_LEAD;
use formation_config::protocol::services;
use formation_config::protocol::wire::{DelayInjection, FaultInjection};
use formation_config::scenario::events::{Event, EventKind};
use formation_config::scenario::validate::ValidationErrors;
use formation_config::Scenario;
use serde_json::json;
use std::fs::File;
use std::io::Write;
use std::path::Path;

/// Steps beyond the plant's lead before an injection may apply: the role processes read the
/// injection services every `HOUSEKEEPING_EVERY` steps, so one such read always falls between the
/// forwarding and the step the injection applies at (plus margin).
pub const SLACK: u64 = formation_config::protocol::pacing::HOUSEKEEPING_EVERY + 4;

/// Why the injections of a run cannot be taken or forwarded (the run then stops).
#[derive(Debug, thiserror::Error)]
pub enum InjectionsError {
    /// A port of the injection services cannot be opened or sent on.
    #[error("{0}")]
    Port(#[from] PortError),
    /// `events.jsonl` cannot be created.
    #[error("cannot create {}: {source}", path.display())]
    Create {
        /// The file.
        path: std::path::PathBuf,
        /// The file system's error.
        source: std::io::Error,
    },
    /// A line cannot be appended to `events.jsonl`.
    #[error("cannot write events.jsonl: {0}")]
    Write(std::io::Error),
}

/// Why one injection request is refused (logged in `events.jsonl`, the run goes on).
#[derive(Debug, thiserror::Error)]
enum Refusal {
    /// An option outside its range.
    #[error("{0}")]
    Check(#[from] validate::InjectError),
    /// A request kind this orchestrator does not know.
    #[error("unknown injection kind {0}")]
    UnknownKind(u32),
    /// The event breaks the rules of a timeline event.
    #[error("{0}")]
    Event(#[from] ValidationErrors),
    /// A crash or hang asked of a realtime run, which takes them only as they happen.
    #[error("a `{0}` injection needs a lockstep run (realtime runs take faults, delays and link faults; end or stop the process itself, e.g. `kill -9 PID`, and the supervision handles it under runtime.restart; docs/failures.md)")]
    Realtime(&'static str),
}

/// Ports and log of the injections of one run.
pub struct Injections {
    requests: Input<InjectRequest>,
    faults: Output<FaultInjection>,
    delays: Output<DelayInjection>,
    events: File,
    /// The lines written to `events.jsonl` since the last [`Injections::take_logged`].
    logged: Vec<serde_json::Value>,
    /// The fault and delay injections accepted to apply inside the run, as timeline events.
    changes: Vec<Event>,
    scenario: Scenario,
    /// A realtime run: crashes and hangs are refused.
    realtime: bool,
}

impl Injections {
    /// Opens the ports and creates `out/events.jsonl`; `realtime`: the run is on the wall clock.
    pub fn open(
        node: &RunNode,
        scenario: &Scenario,
        out: &Path,
        realtime: bool,
    ) -> Result<Injections, InjectionsError> {
        let path = out.join("events.jsonl");
        Ok(Injections {
            requests: subscriber(node, &services::INJECT_REQUEST.named())?,
            faults: publisher(node, &services::FAULT_INJECTION.named())?,
            delays: publisher(node, &services::DELAY_INJECTION.named())?,
            events: formation_config::node::files::create_replacing(&path).map_err(|source| {
                InjectionsError::Create {
                    path: path.clone(),
                    source,
                }
            })?,
            logged: Vec::new(),
            changes: Vec::new(),
            scenario: scenario.clone(),
            realtime,
        })
    }

    /// Handles every pending request; call it before announcing `recorded` as progress. Returns
    /// the runtime events to publish (crashes, hangs, links).
    pub fn poll(&mut self, recorded: u64) -> Result<Vec<RuntimeEvent>, InjectionsError> {
        let mut out = Vec::new();
        while let Ok(Some(r)) = self.requests.receive() {
            let r = *r;
            if let Some(e) = self.handle(&r, recorded)? {
                out.push(e);
            }
        }
        Ok(out)
    }

    /// The checks of a timeline event of the same kind at the step it applies (`down_s` at most
    /// the run's remaining time from there), after the client's own.
    fn check(&self, r: &InjectRequest, step: u64) -> Result<(), Refusal> {
        validate::agent(r.agent as usize + 1, self.scenario.n_agents())?;
        match r.kind {
            INJECT_FAULT => validate::fault(&self.scenario, r.gamma, r.delta)?,
            INJECT_DELAY => validate::delay(&self.scenario, &profile(r))?,
            INJECT_CRASH if self.realtime => return Err(Refusal::Realtime("crash")),
            INJECT_HANG if self.realtime => return Err(Refusal::Realtime("hang")),
            INJECT_CRASH | INJECT_HANG | INJECT_LINK_DOWN | INJECT_LINK_UP => {}
            k => return Err(Refusal::UnknownKind(k)),
        }
        // An injection after the end is checked as if at the last step (it changes nothing).
        let last = self.scenario.n_steps().saturating_sub(1);
        let e = event_of(r, self.scenario.simulation.dt_s, step.min(last));
        formation_config::scenario::validate::validate_event(&self.scenario, "inject", &e)?;
        Ok(())
    }

    fn handle(
        &mut self,
        r: &InjectRequest,
        recorded: u64,
    ) -> Result<Option<RuntimeEvent>, InjectionsError> {
        let wall = unix_now();
        let earliest = recorded + PLANT_LEAD + SLACK;
        let step = if r.at_step != INJECT_ASAP && r.at_step >= earliest {
            r.at_step
        } else {
            earliest
        };
        if let Err(e) = self.check(r, step) {
            tracing::warn!(nonce = r.nonce, "injection rejected: {e}");
            return self
                .log(json!({
                    "wall_time_unix_s": wall, "event": "rejected", "nonce": r.nonce,
                    "recorded_step": recorded, "error": e.to_string(),
                }))
                .map(|_| None);
        }
        let dt = self.scenario.simulation.dt_s;
        let t = step as f64 * dt;
        let requested = (r.at_step != INJECT_ASAP).then_some(r.at_step);
        let after_end = step >= self.scenario.n_steps();
        let agent = r.agent as usize + 1;
        let event = event_of(r, dt, step);
        let scenario_event = serde_json::to_value(&event).unwrap_or_default();
        if let Some(rt) = RuntimeEvent::from_event(&event, dt) {
            tracing::info!(
                agent,
                step,
                t,
                kind = event.kind.name(),
                "runtime event accepted"
            );
            self.log(json!({
                "wall_time_unix_s": wall, "event": event.kind.name(), "nonce": r.nonce, "agent": agent,
                "step": step, "t": t, "requested_step": requested, "recorded_step": recorded,
                "after_end": after_end, "scenario_event": scenario_event,
            }))?;
            return Ok(Some(rt));
        }
        if !after_end {
            self.changes.push(event.clone());
        }
        if r.kind == INJECT_FAULT {
            send(
                &self.faults,
                FaultInjection {
                    step,
                    t,
                    agent: r.agent,
                    mode: 1,
                    gamma: r.gamma,
                    delta: r.delta,
                },
            )?;
            tracing::info!(agent, step, t, gamma = ?r.gamma, delta = ?r.delta, "fault injection accepted");
            self.log(json!({
                "wall_time_unix_s": wall, "event": "fault", "nonce": r.nonce, "agent": agent,
                "step": step, "t": t, "requested_step": requested, "recorded_step": recorded,
                "after_end": after_end, "gamma": r.gamma, "delta": r.delta,
                "scenario_event": scenario_event,
            }))
            .map(|_| None)
        } else {
            let d = profile(r);
            send(
                &self.delays,
                DelayInjection {
                    step,
                    t,
                    agent: r.agent,
                    _pad: 0,
                    base_s: d.base_s,
                    amplitude_s: d.amplitude_s,
                    angular_rate_rad_s: d.angular_rate_rad_s,
                },
            )?;
            tracing::info!(
                agent,
                step,
                t,
                base_s = d.base_s,
                amplitude_s = d.amplitude_s,
                rate_rad_s = d.angular_rate_rad_s,
                "delay injection accepted"
            );
            self.log(json!({
                "wall_time_unix_s": wall, "event": "delay", "nonce": r.nonce, "agent": agent,
                "step": step, "t": t, "requested_step": requested, "recorded_step": recorded,
                "after_end": after_end, "base_s": d.base_s, "amplitude_s": d.amplitude_s,
                "angular_rate_rad_s": d.angular_rate_rad_s, "scenario_event": scenario_event,
            }))
            .map(|_| None)
        }
    }

    /// The fault and delay injections accepted so far (inside the run), as the timeline events a
    /// replay of `events.jsonl` reads: `summary.json`'s `events[]` lists them like a replay does.
    pub fn changes(&self) -> &[Event] {
        &self.changes
    }

    /// The lines written to `events.jsonl` since the last call (the recorder puts the accepted
    /// ones into `run.mcap`).
    pub fn take_logged(&mut self) -> Vec<serde_json::Value> {
        std::mem::take(&mut self.logged)
    }

    fn log(&mut self, v: serde_json::Value) -> Result<(), InjectionsError> {
        writeln!(self.events, "{v}")
            .and_then(|_| self.events.flush())
            .map_err(InjectionsError::Write)?;
        self.logged.push(v);
        Ok(())
    }
}

fn profile(r: &InjectRequest) -> DelayProfile {
    DelayProfile {
        base_s: r.base_s,
        amplitude_s: r.amplitude_s,
        angular_rate_rad_s: r.angular_rate_rad_s,
    }
}

/// The timeline event of a request applied at `step` (agent ids 1-based, as in a scenario).
pub fn event_of(r: &InjectRequest, dt: f64, step: u64) -> Event {
    let kind = match r.kind {
        INJECT_FAULT => EventKind::Fault,
        INJECT_DELAY => EventKind::Delay,
        INJECT_CRASH => EventKind::Crash,
        INJECT_HANG => EventKind::Hang,
        INJECT_LINK_DOWN => EventKind::LinkDown,
        _ => EventKind::LinkUp,
    };
    let mut e = Event::new(step as f64 * dt, kind);
    let a = r.agent as usize + 1;
    match kind {
        EventKind::Fault => {
            e.agent = Some(a);
            e.gamma = Some(r.gamma);
            e.delta = Some(r.delta);
        }
        EventKind::Delay => {
            e.agent = Some(a);
            e.base_s = Some(r.base_s);
            e.amplitude_s = Some(r.amplitude_s);
            e.angular_rate_rad_s = Some(r.angular_rate_rad_s);
        }
        EventKind::Crash | EventKind::Hang => {
            e.agent = Some(a);
            e.down_s = Some(r.down_s);
        }
        _ => e.agents = Some([a, r.other as usize + 1]),
    }
    e
}
