//! The one interface of a run's outputs. `trajectory.csv`, `run.mcap`, the rosbag2, the live
//! Foxglove view, the live ROS 2 topics and the Zenoh export each implement [`Sink`]; the
//! recorder's fan-out (`fanout::Fanout`) hands every step to each sink at its [`Cadence`]: the
//! file sinks get the output steps on the recorder's writer thread, the live sinks every step on
//! the run loop's thread (each hands it on through a bounded queue of its own and never waits).

use formation_config::protocol::wire::{ControlCommand, PlantTruth, ReferenceFrame};
use serde_json::Value;

/// One step as every sink sees it.
#[derive(Debug, Clone, Copy)]
pub struct Step<'a> {
    /// Simulation step k.
    pub step: u64,
    /// The reference of step k (virtual leader P_d, ground target T_g, offsets Delta_i0).
    pub reference: &'a ReferenceFrame,
    /// The plant's truths of the N agents.
    pub truths: &'a [PlantTruth],
    /// The N commands.
    pub commands: &'a [ControlCommand],
    /// Formation error |P_i - P_d - Delta_i0| of each agent, m.
    pub errors: &'a [f64],
}

impl Step<'_> {
    /// Virtual leader P_d, m.
    pub fn p_d(&self) -> [f64; 3] {
        self.reference.p_d
    }

    /// Ground target T_g, m.
    pub fn target(&self) -> [f64; 3] {
        self.reference.target
    }

    /// Formation offsets Delta_i0 of the N agents, m.
    pub fn offsets(&self) -> &[[f64; 3]] {
        &self.reference.offset[..self.truths.len()]
    }
}

/// Which steps a sink gets, and on which thread.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Cadence {
    /// The output steps (every `output_decimation` steps and a divergence step), on the
    /// recorder's writer thread, in order: a file, which must hold every one of them.
    Output,
    /// Every step, on the run loop's thread: the sink takes what it publishes (a scene frame, an
    /// output step) and hands it on without waiting (a full queue drops it, counted).
    Every,
}

/// An output of a run.
pub trait Sink: Send {
    /// Which steps it gets.
    fn cadence(&self) -> Cadence;

    /// Takes one step.
    fn step(&mut self, step: &Step<'_>) -> std::io::Result<()>;

    /// Takes an injection (a line of `events.jsonl`), after the steps before it; a sink that
    /// shows no injections ignores it.
    fn event(&mut self, _line: &Value) -> std::io::Result<()> {
        Ok(())
    }

    /// Makes what was written so far readable by others (a killed run leaves a readable prefix).
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }

    /// Completes the output (a file's indexes and metadata; a live view stops and says what it
    /// sent).
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
