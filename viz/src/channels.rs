//! The channels of the scene (topic, schema, message encoding) and the encoding of a [`Scene`]
//! into their messages: the one description the live server and `run.mcap` share, so a recording
//! and the live view carry the same bytes on the same topics.

use crate::scene::{plot_schema, step_ns, Scene, PLOT_SCHEMA_NAME};
use foxglove::messages::{FrameTransforms, Log, SceneUpdate};
use foxglove::{Encode, Schema};
use std::borrow::Cow;

/// `/tf`.
pub const TF: usize = 0;
/// `/scene/agents`.
pub const AGENTS: usize = 1;
/// `/scene/mission`.
pub const MISSION: usize = 2;
/// `/scene/links`.
pub const LINKS: usize = 3;
/// `/scene/events`.
pub const EVENTS: usize = 4;
/// `/log`.
pub const LOG: usize = 5;
/// `/agent/1/plot`; agent i's is `PLOT + i - 1`.
pub const PLOT: usize = 6;

/// A channel's schema, as MCAP and Foxglove's protocol carry it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ChannelSchema {
    /// Name (`foxglove.SceneUpdate`, the plot schema's name).
    pub name: String,
    /// Encoding (`protobuf` or `jsonschema`).
    pub encoding: String,
    /// The schema itself (a protobuf file descriptor set, or a JSON Schema).
    pub data: Vec<u8>,
}

impl From<Schema> for ChannelSchema {
    fn from(s: Schema) -> ChannelSchema {
        ChannelSchema {
            name: s.name,
            encoding: s.encoding,
            data: s.data.into_owned(),
        }
    }
}

impl From<ChannelSchema> for Schema {
    fn from(s: ChannelSchema) -> Schema {
        Schema::new(s.name, s.encoding, Cow::Owned(s.data))
    }
}

/// One channel: its topic, schema and message encoding.
#[derive(Debug, Clone)]
pub struct ChannelSpec {
    /// Topic.
    pub topic: String,
    /// Schema (name, encoding, data).
    pub schema: ChannelSchema,
    /// Message encoding (`protobuf` or `json`).
    pub message_encoding: &'static str,
}

fn well_known<T: Encode>(topic: &str) -> ChannelSpec {
    ChannelSpec {
        topic: topic.into(),
        schema: T::get_schema()
            .expect("every well-known message has a schema")
            .into(),
        message_encoding: "protobuf",
    }
}

/// The channels of a run of `n` agents, indexed by [`TF`], [`AGENTS`], ..., [`PLOT`] + i - 1.
pub fn channels(n: usize) -> Vec<ChannelSpec> {
    let mut out = vec![
        well_known::<FrameTransforms>("/tf"),
        well_known::<SceneUpdate>("/scene/agents"),
        well_known::<SceneUpdate>("/scene/mission"),
        well_known::<SceneUpdate>("/scene/links"),
        well_known::<SceneUpdate>("/scene/events"),
        well_known::<Log>("/log"),
    ];
    let plot: ChannelSchema = Schema::new(
        PLOT_SCHEMA_NAME,
        "jsonschema",
        plot_schema().to_string().into_bytes(),
    )
    .into();
    for id in 1..=n {
        out.push(ChannelSpec {
            topic: format!("/agent/{id}/plot"),
            schema: plot.clone(),
            message_encoding: "json",
        });
    }
    out
}

/// One message of a channel of [`channels`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Encoded {
    /// Index into [`channels`].
    pub channel: usize,
    /// Log time: simulation time in nanoseconds.
    pub log_time_ns: u64,
    /// The encoded message.
    pub data: Vec<u8>,
}

fn protobuf<T: Encode>(msg: &T) -> Vec<u8> {
    let mut buf = Vec::with_capacity(msg.encoded_len().unwrap_or(256));
    // Encoding into a Vec cannot run out of space.
    let _ = msg.encode(&mut buf);
    buf
}

/// The messages of `scene` (step length `dt`), appended to `out` in channel order: the events'
/// `/log` lines at their own steps, every other message at the frame's step.
pub fn encode(scene: &Scene, dt: f64, out: &mut Vec<Encoded>) {
    let time = step_ns(scene.step, dt);
    let mut push = |channel, log_time_ns, data| {
        out.push(Encoded {
            channel,
            log_time_ns,
            data,
        })
    };
    push(TF, time, protobuf(&scene.transforms));
    push(AGENTS, time, protobuf(&scene.agents));
    push(MISSION, time, protobuf(&scene.mission));
    push(LINKS, time, protobuf(&scene.links));
    push(EVENTS, time, protobuf(&scene.events));
    for (step, log) in &scene.logs {
        push(LOG, step_ns(*step, dt), protobuf(log));
    }
    for p in &scene.plots {
        // Serialising plain numbers cannot fail.
        let json = serde_json::to_vec(p).unwrap_or_default();
        push(PLOT + p.agent - 1, time, json);
    }
}
