//! The runtime of `formation`: what the `formation` command (crate `formation`, directory cli/)
//! runs, as a library. The IPC benchmark harness is the crate `formation-bench`.
//!
//! * [`closed_loop`]: the whole closed loop in one process (the in-process runner).
//! * [`sim`], [`run`]: `formation sim` (in process) and `formation run` (one OS process per role
//!   over iceoryx2), recorded by [`record`] into the same outputs.
//! * [`role`]: `formation node <role>`, the role processes started from this same executable.
//! * [`live`]: `ps`, `inspect`, `inject` on a running run.
//! * [`plot`], [`check`], [`scenario_gen`], [`sweep`]: figures, gain checks, generated scenarios
//!   of any N, parameter sweeps.
//! * [`schema`]: `formation schema`, the service table for outside clients and docs/services.md.
//! * [`rng`]: the seeded generator of generated graphs and sweeps.
//! * [`history`]: the recorded states a restarted agent rebuilds from.
//! * [`cli`], [`cpus`]: shared command-line plumbing and CPU sets.

pub mod check;
pub mod cli;
pub mod closed_loop;
pub mod cpus;
pub mod history;
#[cfg(feature = "multihost")]
pub mod hosts;
pub mod live;
pub mod out_lock;
pub mod plot;
pub mod record;
pub mod rng;
pub mod role;
pub mod run;
pub mod scenario_gen;
pub mod schema;
pub mod sim;
pub mod sweep;

pub use closed_loop::ClosedLoop;
/// Steps a lockstep run leaves out of its step timing (`timing` of summary.json); the benchmark
/// sizes its lockstep runs with it.
pub use run::step_timing::WARMUP_STEPS;
