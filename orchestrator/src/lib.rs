//! The runtime of `formation`: what the `formation` command (crate `formation`, directory cli/)
//! runs, as a library. Figures, gain checks, sweeps and generated scenarios are the crate
//! `formation-analysis`, the IPC benchmark harness the crate `formation-bench`; neither is a
//! dependency of this one.
//!
//! * [`closed_loop`]: the whole closed loop in one process (the in-process runner).
//! * [`sim`], [`run`]: `formation sim` (in process) and `formation run` (one OS process per role
//!   over iceoryx2), recorded by [`record`] into the same outputs.
//! * [`role`]: `formation node <role>`, the role processes started from this same executable.
//! * [`live`]: `ps`, `inspect`, `inject` on a running run.
//! * [`schema`]: `formation schema`, the service table for outside clients and docs/services.md.
//! * [`rng`]: the seeded generator of coverage samples, generated graphs and sweeps.
//! * [`history`]: the recorded states a restarted agent rebuilds from.
//! * [`cli`], [`cpus`]: shared command-line plumbing and CPU sets.

pub mod cli;
pub mod closed_loop;
pub mod cpus;
pub mod history;
#[cfg(feature = "multihost")]
pub mod hosts;
pub mod live;
pub mod out_lock;
pub mod record;
pub mod rng;
pub mod role;
pub mod run;
pub mod schema;
pub mod sim;

pub use closed_loop::ClosedLoop;
/// Steps a lockstep run leaves out of its step timing (`timing` of summary.json); the benchmark
/// sizes its lockstep runs with it.
pub use run::step_timing::WARMUP_STEPS;
