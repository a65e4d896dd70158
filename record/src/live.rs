//! `--foxglove [ADDR]`: the recorder's feed of the live Foxglove view (crate `formation-viz`).
//!
//! At every scene frame (25 Hz of simulation time, `formation_viz::scene::SCENE_RATE_HZ`) the
//! recorder builds a small [`Frame`] from the step it records and offers it to the view, which
//! never blocks (a full queue drops the frame); scene building, encoding and the WebSocket server
//! run on the view's own threads at lowered priority.

use formation_config::protocol::wire::{ControlCommand, PlantTruth, ReferenceFrame};
use formation_config::scenario::events::Event;
use formation_config::Scenario;
use formation_viz::{Frame, Limits, LiveView, SceneConfig};

/// The live view of one run and what the recorder needs to feed it.
pub struct LiveFeed {
    view: LiveView,
    limits: Limits,
}

impl LiveFeed {
    /// Starts the server on `addr` and says where on standard error.
    /// With `wait_s` > 0, waits until a viewer connects (or that long) before returning.
    pub fn start(o: super::LiveOptions, s: &Scenario) -> std::io::Result<LiveFeed> {
        let view = LiveView::start(
            &o.addr.to_string(),
            &format!("formation {}", s.name),
            SceneConfig::from_scenario(s),
            &s.events,
        )
        .map_err(|e| std::io::Error::new(std::io::ErrorKind::AddrNotAvailable, e.to_string()))?;
        eprintln!(
            "foxglove: live view on ws://{} (Foxglove: Open connection, Foxglove WebSocket; layout docs/foxglove/formation.json)",
            view.addr()
        );
        if o.wait_s > 0.0 {
            eprintln!(
                "foxglove: waiting up to {} s for a viewer (--foxglove-wait)",
                o.wait_s
            );
            let joined = view.wait_for_viewer(std::time::Duration::from_secs_f64(o.wait_s));
            eprintln!(
                "foxglove: {}; the run starts",
                if joined {
                    "a viewer joined"
                } else {
                    "no viewer joined"
                }
            );
        }
        Ok(LiveFeed {
            view,
            limits: Limits::of(s),
        })
    }

    /// Offers step k to the view if it is a scene frame.
    pub fn step(
        &mut self,
        k: u64,
        r: &ReferenceFrame,
        truths: &[PlantTruth],
        commands: &[ControlCommand],
        errors: impl Iterator<Item = f64>,
    ) {
        if !self.view.wants(k) {
            return;
        }
        let n = truths.len();
        let errors: Vec<f64> = errors.collect();
        self.view.offer(Frame::from_records(
            k,
            r.t,
            r.p_d,
            r.target,
            &r.offset[..n],
            truths,
            commands,
            &errors,
            self.limits,
        ));
    }

    /// An accepted injection (a line of `events.jsonl` with its `scenario_event`).
    pub fn injection(&mut self, line: &serde_json::Value) {
        if let Some(e) = scenario_event(line) {
            self.view.event(e);
        }
    }

    /// Stops the view; says on standard error what it sent.
    pub fn finish(self) {
        let s = self.view.finish();
        tracing::info!(
            offered = s.offered,
            dropped = s.dropped,
            published = s.published,
            "foxglove live view stopped"
        );
    }
}

/// The timeline event of an accepted injection line (`None` for a rejection).
pub fn scenario_event(line: &serde_json::Value) -> Option<Event> {
    serde_json::from_value(line.get("scenario_event")?.clone()).ok()
}
