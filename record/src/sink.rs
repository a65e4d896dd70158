//! The one interface of the recorder's file outputs: `trajectory.csv`, `run.mcap` and the rosbag2
//! each implement [`Sink`], and the writer thread (`csv::TrajectoryWriter`) fans every output step
//! and every injection out to the sinks of the run, in order, off the simulation loop.

use formation_config::protocol::wire::{ControlCommand, PlantTruth};
use serde_json::Value;

/// The rows of one output step, handed to the writer thread.
pub(crate) struct StepRows {
    /// Virtual leader P_d, m.
    pub(crate) p_d: [f64; 3],
    /// Ground target T_g, m.
    pub(crate) target: [f64; 3],
    /// Formation offsets Delta_i0 of the N agents, m.
    pub(crate) offsets: Vec<[f64; 3]>,
    /// The plant's truths of the N agents.
    pub(crate) truths: Vec<PlantTruth>,
    /// The N commands.
    pub(crate) commands: Vec<ControlCommand>,
    /// Formation error of each agent, m.
    pub(crate) errors: Vec<f64>,
}

/// A file output of a run, written on the recorder's writer thread.
pub(crate) trait Sink: Send {
    /// Writes one output step.
    fn step(&mut self, rows: &StepRows) -> std::io::Result<()>;

    /// Writes an injection (a line of `events.jsonl`), after the steps before it; a sink that
    /// records no events ignores it.
    fn event(&mut self, _line: &Value) -> std::io::Result<()> {
        Ok(())
    }

    /// Makes what was written so far readable by others (a killed run leaves a readable prefix).
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }

    /// Completes the file (indexes, summaries, metadata).
    fn finish(self: Box<Self>) -> std::io::Result<()>;
}

/// The event message of an injection line of `events.jsonl` (`None` for a rejected request): the
/// fields that describe what applies and when, without the wall-clock time and the request's
/// nonce, so that a lockstep run with injections at given steps records the same bytes every time.
/// `run.mcap`'s `/events` and the rosbag2's `/formation/events` carry it.
pub fn event_message(line: &Value) -> Option<(u64, Value)> {
    let kind = line.get("event")?.as_str()?;
    if kind != "fault" && kind != "delay" {
        return None;
    }
    let step = line.get("step")?.as_u64()?;
    let mut out = serde_json::Map::new();
    out.insert("step".into(), step.into());
    out.insert("t".into(), line.get("t")?.clone());
    out.insert("kind".into(), kind.into());
    out.insert("agent".into(), line.get("agent")?.clone());
    let fields: &[&str] = if kind == "fault" {
        &["requested_step", "gamma", "delta"]
    } else {
        &[
            "requested_step",
            "base_s",
            "amplitude_s",
            "angular_rate_rad_s",
        ]
    };
    for f in fields {
        if let Some(v) = line.get(*f).filter(|v| !v.is_null()) {
            out.insert((*f).into(), v.clone());
        }
    }
    Some((step, Value::Object(out)))
}
