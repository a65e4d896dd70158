//! The orchestrator of `formation`: everything behind the `formation` command, as a library.
//!
//! * [`closed_loop`]: the whole closed loop in one process (the in-process runner).
//! * [`sim`], [`run`]: `formation sim` (in process) and `formation run` (one OS process per role
//!   over iceoryx2), recorded by [`record`] into the same outputs.
//! * [`role`]: `formation node <role>`, the role processes started from this same executable.
//! * [`live`]: `ps`, `inspect`, `inject` on a running run.
//! * [`plot`], [`check`], [`bench`], [`scenario_gen`], [`sweep`]: figures, gain checks, IPC
//!   benchmarks, generated scenarios of any N, parameter sweeps.
//! * [`schema`]: `formation schema`, the service table for outside clients and docs/services.md.
//! * [`rng`]: the seeded generator of generated graphs and sweeps.
//! * [`history`]: the recorded states a restarted agent rebuilds from.
//! * [`cli`], [`cpus`]: shared command-line plumbing and CPU sets.

pub mod bench;
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
