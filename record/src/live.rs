//! `--foxglove [ADDR]`: the recorder's feed of the live Foxglove view (crate `formation-viz`).
//!
//! At every scene frame (25 Hz of simulation time, `formation_viz::scene::SCENE_RATE_HZ`) the
//! recorder builds a small [`Frame`] from the step it records and offers it to the view, which
//! never blocks (a full queue drops the frame); scene building, encoding and the WebSocket server
//! run on the view's own threads at lowered priority.

use super::sink::{Cadence, Sink, Step};
use formation_config::scenario::events::Event;
use formation_config::Scenario;
use formation_viz::{Frame, Limits, LiveView, SceneConfig, StepRecords};

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
}

/// The view takes the scene frames (every step is offered, the view keeps those of its rate) and
/// the accepted injections, without waiting.
impl Sink for LiveFeed {
    fn cadence(&self) -> Cadence {
        Cadence::Every
    }

    fn step(&mut self, s: &Step<'_>) -> std::io::Result<()> {
        if self.view.wants(s.step) {
            self.view.offer(Frame::from_records(
                StepRecords {
                    step: s.step,
                    t: s.reference.t,
                    p_d: s.p_d(),
                    target: s.target(),
                    offsets: s.offsets(),
                    truths: s.truths,
                    commands: s.commands,
                    errors: s.errors,
                },
                self.limits,
            ));
        }
        Ok(())
    }

    fn event(&mut self, line: &serde_json::Value) -> std::io::Result<()> {
        if let Some(e) = scenario_event(line) {
            self.view.event(e);
        }
        Ok(())
    }

    /// Stops the view; logs what it sent.
    fn finish(self: Box<Self>) -> std::io::Result<()> {
        let s = self.view.finish();
        tracing::info!(
            offered = s.offered,
            dropped = s.dropped,
            published = s.published,
            "foxglove live view stopped"
        );
        Ok(())
    }
}

/// The timeline event of an accepted injection line (`None` for a rejection).
pub fn scenario_event(line: &serde_json::Value) -> Option<Event> {
    serde_json::from_value(line.get("scenario_event")?.clone()).ok()
}
