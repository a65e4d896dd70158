//! The 3D scene channels of `run.mcap` (feature `foxglove`): the same messages as the live view
//! (`formation_viz::channels`: `/tf`, `/scene/agents`, `/scene/mission`, `/scene/links`,
//! `/scene/events`, `/log`, `/agent/{i}/plot`), built from the recorded output steps at every
//! scene frame and from the run's events, so that Foxglove's 3D panel shows the swarm.

use super::sink::Step;
use formation_config::Scenario;
use formation_viz::channels::{channels, encode, Encoded};
use formation_viz::{Frame, Limits, SceneBuilder, StepRecords};
use std::collections::BTreeMap;

/// The scene's part of the MCAP writer.
pub(crate) struct McapScene {
    builder: SceneBuilder,
    /// MCAP channel id of each channel of `formation_viz::channels`.
    ids: Vec<u16>,
    limits: Limits,
    encoded: Vec<Encoded>,
}

impl McapScene {
    /// Adds the scene's schemas and channels to `writer`.
    pub(crate) fn create<W: std::io::Write + std::io::Seek>(
        writer: &mut mcap::Writer<W>,
        s: &Scenario,
    ) -> Result<McapScene, mcap::McapError> {
        let mut schemas: BTreeMap<String, u16> = BTreeMap::new();
        let mut ids = Vec::new();
        let none = BTreeMap::new();
        for c in channels(s.n_agents()) {
            let schema = match schemas.get(&c.schema.name) {
                Some(id) => *id,
                None => {
                    let id =
                        writer.add_schema(&c.schema.name, &c.schema.encoding, &c.schema.data)?;
                    schemas.insert(c.schema.name.clone(), id);
                    id
                }
            };
            ids.push(writer.add_channel(schema, &c.topic, c.message_encoding, &none)?);
        }
        Ok(McapScene {
            builder: SceneBuilder::for_scenario(s),
            ids,
            limits: Limits::of(s),
            encoded: Vec::new(),
        })
    }

    /// The scene messages of an output step (none unless it is a scene frame), handed to
    /// `write(channel id, log time, bytes)`.
    pub(crate) fn step(
        &mut self,
        rows: &Step<'_>,
        mut write: impl FnMut(u16, u64, &[u8]) -> std::io::Result<()>,
    ) -> std::io::Result<()> {
        let Some(first) = rows.truths.first() else {
            return Ok(());
        };
        let (step, t) = (first.state.step, first.state.t);
        if !self.builder.is_frame(step) {
            return Ok(());
        }
        let frame = Frame::from_records(
            StepRecords {
                step,
                t,
                p_d: rows.p_d(),
                target: rows.target(),
                offsets: rows.offsets(),
                truths: rows.truths,
                commands: rows.commands,
                errors: rows.errors,
            },
            self.limits,
        );
        let scene = self.builder.build(&frame);
        self.encoded.clear();
        encode(&scene, self.builder.config().dt, &mut self.encoded);
        for m in &self.encoded {
            write(self.ids[m.channel], m.log_time_ns, &m.data)?;
        }
        Ok(())
    }

    /// An accepted injection (a line of `events.jsonl`): its event joins the scene's timeline.
    pub(crate) fn injection(&mut self, line: &serde_json::Value) {
        if let Some(e) = super::live::scenario_event(line) {
            self.builder.add_event(&e);
        }
    }
}
