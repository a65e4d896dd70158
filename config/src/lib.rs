//! The contract every formation process shares.
//!
//! * [`scenario`]: the scenario schema (TOML, unknown fields rejected) with the paper scenario embedded
//!   as the default ([`Scenario::paper`]).
//! * [`validate`]: checks of the paper's assumptions with errors naming the field and the assumption.
//! * [`wire`]: `#[repr(C)]` zero-copy messages exchanged over iceoryx2, stamped with step and time.
//! * [`services`]: service names under a per-run prefix.
//! * [`ipc`]: iceoryx2 plumbing: nodes under a run prefix, services sized for N, residue cleanup.
//! * [`runtime`]: the lockstep protocol of `formation run` (pacing, control messages, role-process
//!   plumbing).
//! * [`graph`]: the communication graph (Laplacian `L`, leader weights `B`) built from a scenario.
#![warn(missing_docs)]

pub mod graph;
pub mod ipc;
pub mod runtime;
pub mod scenario;
pub mod services;
pub mod validate;
pub mod variant;
pub mod wire;

pub use scenario::Scenario;
pub use validate::{ValidationError, ValidationErrors};
pub use variant::Variant;

/// Largest number of quadrotors a run may have; fixes the size of the wire messages that carry
/// per-agent arrays (the reference frame).
pub const MAX_AGENTS: usize = 128;
