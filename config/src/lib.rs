//! The contract every formation process shares, in three layers, and what every view draws alike:
//!
//! * [`scenario`]: the scenario model (TOML schema, unknown fields rejected, the paper scenario
//!   embedded as the default), its validation against the paper's assumptions, the communication
//!   graph and the controller variants. Pure data; what the control libraries build on.
//! * [`protocol`]: the wire messages (`#[repr(C)]`, stamped with step and time), the typed service
//!   table (each service's name, message type, limits, publishers and subscribers, declared once)
//!   and the pacing constants of the lockstep protocol. With the `ipc` feature the messages are
//!   iceoryx2 `ZeroCopySend` types.
//! * [`kinematics`]: the quadrotor's rotation matrices, Euler-angle rates and rotational drift
//!   (eq. (1)-(2)), the model the plant integrates and the controller inverts.
//! * [`view`]: what every view of a run draws alike (agent colours, edge states, attitudes as
//!   quaternions), for the Foxglove scene, the ROS 2 markers and the figures.
//! * [`node`] (feature `node`): the plumbing of a role process — iceoryx2 nodes under a run prefix,
//!   ports opened from the service table, process boot, scheduling, clock, logging, histograms.
//!
//! The agent, plant and leader *libraries* depend on this crate without default features: they see
//! the scenario and the message structs, and none of the process plumbing.
#![warn(missing_docs)]

pub mod kinematics;
pub mod protocol;
pub mod scenario;
pub mod view;

#[cfg(feature = "node")]
pub mod node;

pub use scenario::validate::{ValidationError, ValidationErrors};
pub use scenario::variant::Variant;
pub use scenario::Scenario;

/// Largest number of quadrotors a run may have; fixes the size of the wire messages that carry
/// per-agent arrays (the reference frame).
pub const MAX_AGENTS: usize = 128;
