//! The commands that look at or act on a running `formation run` from another terminal, and the
//! contract outside programs read a run by:
//!
//! * [`ps`]: the running runs and their processes.
//! * [`inspect`]: one agent's live telemetry.
//! * [`inject`]: faults, delays, crashes, hangs and link changes at runtime.
//! * [`schema`]: `formation schema`, every service of a run from the service table, for outside
//!   clients and docs/services.md.
//! * [`error`]: how they fail (the `formation` binary maps it to the exit code).
//!
//! How runs are found (the registry), the injection checks and the client node are the runtime's
//! (`formation_runtime::live`): a run registers itself there and reads its injections with them.

pub mod error;
pub mod inject;
pub mod inspect;
pub mod ps;
pub mod schema;
