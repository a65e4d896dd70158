//! Quadrotor physics of eq. (1)-(4) for N vehicles: rigid-body translation and rotation, input
//! saturation (3), actuator faults (4) with time-varying Gamma_i(t), delta_i(t) of (63)-(64), the lumped
//! position uncertainty (61), the attitude disturbance (62) and the model perturbation Delta F_i.
//!
//! Pure math: no IPC, no clock, no allocation per step. Fixed-step RK4 with the inputs held over the
//! step. The process around it is the `node` module (feature `node`: its ports and its event loops,
//! lockstep and realtime).
#![warn(missing_docs)]

pub mod dynamics;
pub mod fallback;
pub mod faults;
pub mod memo;
pub mod perturbations;
pub mod plant;
pub mod traffic;

/// The role process around the library: its ports, its event loop (lockstep and realtime).
#[cfg(feature = "node")]
pub mod node;

pub use plant::Plant;
