//! The host daemon of multi-host runs and its commands (docs/multi-host.md):
//!
//! * [`daemon`]: `formation host`, a machine's daemon that starts a run's agent processes on
//!   request, bridges the run's services and reports their exits; its Zenoh side is
//!   `formation_net::daemon_link`.
//! * [`commands`]: the command lines of `formation host`, `formation hosts` (the daemons an
//!   orchestrator can reach) and `formation certs` (a CA and per-host certificates).
//! * [`error`]: why one of them did not succeed ([`HostError`]).

pub mod commands;
pub mod daemon;
pub mod error;
pub mod refusal;

pub use commands::{certs_main, host_main, hosts_main, CertsArgs, HostArgs, HostsArgs};
pub use error::HostError;
