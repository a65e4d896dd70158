//! The controller of one quadrotor (Fig. 2): the position loop NTDPC (consensus errors (8)-(9) on
//! delayed information, control law (14), RBFNN (11) with update law (15)), the command conversion (28),
//! command filters (Fig. 3), and the attitude loop AFTAC with the tan-type barrier Lyapunov function
//! ((31)-(34), (40)-(45)), auxiliary systems ((35), (50)) and adaptive fault estimation ((46)-(49)).
//!
//! Pure math: no IPC, no clock, no logging and no allocation per step (buffers are sized at
//! construction). The process around it is the `node` module (feature `node`: its ports and its event loop,
//! lockstep and realtime); the in-process runner calls the same [`Agent`] methods with the same
//! messages.
#![warn(missing_docs)]
// Per-axis loops index several arrays at once, as the paper's component equations do.
#![allow(clippy::needless_range_loop)]

pub mod agent;
pub mod attitude;
pub mod blf;
pub mod checkpoint;
pub mod command_filter;
pub mod conversion;
pub mod delay;
pub mod fault_id;
pub mod params;
pub mod position;
pub mod rbfnn;
pub mod restart;
pub mod separation;
pub mod startup;

/// The role process around the library: its ports, its event loop (lockstep and realtime).
#[cfg(feature = "node")]
pub mod node;

pub use agent::Agent;
pub use params::AgentParams;
