//! What `formation` computes from scenarios and from the outputs of runs, as a library over the
//! runtime (crate `formation-runtime`, which depends on nothing here):
//!
//! * [`plot`]: `formation plot`, the paper's figures from a run directory.
//! * [`check`]: `formation check`, what decides whether a gain set can work (graph spectrum,
//!   Theorem 1, bandwidths).
//! * [`sweep`]: `formation sweep`, Monte Carlo or grid over scenario parameters with the
//!   in-process runner.
//! * [`scenario_gen`]: `formation scenario`, generated scenarios of any N.

pub mod check;
pub mod plot;
pub mod scenario_gen;
pub mod sweep;
