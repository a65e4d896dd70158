//! The wire protocol of a run: what crosses process boundaries and how it is paced.
//!
//! * [`wire`]: the simulation messages (state, share, reference, command, truth, injections, telemetry).
//! * [`messages`]: the run-control messages (stop, progress, hello, step records, inject requests).
//! * [`services`]: the typed service table.
//! * [`layout`]: the per-field wire layout of each message.
//! * [`pacing`]: how far plant and leader may run ahead of the recorder, and the buffers that follow.

pub mod layout;
pub mod messages;
pub mod pacing;
pub mod services;
pub mod wire;
