//! Process plumbing shared by the role processes and the orchestrator (feature `node`).
//!
//! * [`ipc`]: iceoryx2 nodes under a per-run prefix, services sized for N, residue cleanup.
//! * [`ports`]: opening the run's services and making typed ports on them.
//! * [`args`], [`boot`], [`error`]: a role process's command line, start-up and errors.
//! * [`process`], [`sched`], [`clock`]: parent watch, scheduling policy and CPU placement, time.
//! * [`logging`], [`timing`]: per-process log files and latency histograms.

pub mod args;
pub mod boot;
pub mod clock;
pub mod error;
pub mod files;
pub mod ipc;
pub mod logging;
pub mod members;
pub mod ports;
pub mod process;
pub mod restart;
pub mod sched;
pub mod timing;
