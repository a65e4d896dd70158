//! The Foxglove view of a formation run.
//!
//! * [`frame`]: what one step looked like ([`Frame`]), from the step records or `trajectory.csv`.
//! * [`scene`]: the 3D scene as Foxglove's well-known messages (`foxglove.SceneUpdate`,
//!   `foxglove.FrameTransforms`, `foxglove.Log`) and the per-agent plot channels, built by pure
//!   functions from frames ([`SceneBuilder`]).
//! * [`channels`]: topics and schemas, and the encoding of a scene into their messages; the live
//!   server and `run.mcap` write the same bytes.
//! * [`live`]: the live view, a Foxglove WebSocket server fed through a bounded, dropping queue
//!   (`formation run|sim --foxglove`).
//!
//! The math crates and the core runtime do not depend on this crate: the orchestrator uses it
//! behind its `foxglove` feature.

pub mod channels;
pub mod frame;
pub mod live;
pub mod scene;
pub mod topview;

pub use frame::{AgentSample, Frame, Limits, StepRecords};
pub use live::{LiveError, LiveStats, LiveView};
pub use scene::{Scene, SceneBuilder, SceneConfig};

#[cfg(test)]
mod tests;
