//! The runtime of `formation`: what the `formation` command (crate `formation`, directory cli/)
//! runs, as a library. Figures, gain checks, sweeps and generated scenarios are the crate
//! `formation-analysis`, the IPC benchmark harness the crate `formation-bench`; neither is a
//! dependency of this one. The recorder is the crate `formation-record` (re-exported as
//! [`record`]); the commands on a running run (`ps`, `inspect`, `inject`) and `schema` are the
//! crate `formation-live`, the host daemon and its commands the crate `formation-host`: those
//! depend on this one.
//!
//! * [`closed_loop`]: the whole closed loop in one process (the in-process runner).
//! * [`sim`], [`run`]: `formation sim` (in process) and `formation run` (one OS process per role
//!   over iceoryx2), recorded by [`record`] into the same outputs.
//! * [`role`]: `formation node <role>`, the role processes started from this same executable.
//! * [`live`]: the registry of running runs, the injection checks, the client node of a command
//!   on a running run.
//! * [`link`]: the Zenoh link options of `run --hosts` and of the host commands (feature
//!   `multihost`).
//! * [`rng`]: the seeded generator of coverage samples, generated graphs and sweeps.
//! * [`history`]: the recorded states a restarted agent rebuilds from.
//! * [`cli`], [`cpus`]: shared command-line plumbing and CPU sets.
//! * [`error`]: how `sim`, `run` and `node` end when they fail (the binary maps it to an exit
//!   code).

pub mod cli;
pub mod closed_loop;
pub mod cpus;
pub mod error;
pub mod history;
#[cfg(feature = "multihost")]
pub mod link;
pub mod live;
pub mod out_lock;
pub mod role;
pub mod run;
pub mod sim;

/// The recorder (crate `formation-record`): `trajectory.csv`, `summary.json`, `run.mcap`, the live
/// Foxglove and ROS 2 sinks.
pub use formation_record as record;
/// The seeded generator of coverage samples, generated graphs and sweeps (crate `formation-record`).
pub use formation_record::rng;

pub use closed_loop::ClosedLoop;
/// Steps a lockstep run leaves out of its step timing (`timing` of summary.json); the benchmark
/// sizes its lockstep runs with it.
pub use run::step_timing::WARMUP_STEPS;
