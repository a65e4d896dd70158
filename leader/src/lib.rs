//! Virtual leader P_d, ground target T_g and formation function Lambda_F of Section 4, with analytic
//! first and second derivatives.
//!
//! Pure math: no IPC, no clock, no allocation per step. The process around it is the `node`
//! module (feature `node`).
#![warn(missing_docs)]
// Per-axis loops index several arrays at once, as the paper's component equations do.
#![allow(clippy::needless_range_loop)]

pub mod mission;
pub mod shaping;
pub mod smooth;

/// The role process around the library: its ports, its event loop (lockstep and realtime).
#[cfg(feature = "node")]
pub mod node;

pub use mission::Mission;
