//! How a command of the runtime (`sim`, `run`, `node`) ends when it does not succeed: one
//! [`CommandError`] per command, whose `Display` is the whole message printed on stderr. The
//! `formation` binary maps it to the exit code (docs/cli.md) in its `main`, the only place that
//! chooses one.
//!
//! * [`InputError`]: the scenario and the arguments every runner takes (exit 2).
//! * [`PlanError`]: what `formation run` checks before anything of the run exists (exit 2).
//! * [`RunError`]: what failed while a run was set up, driven or written (exit 1).

pub use crate::cli::InputError;
use crate::record::metrics::Divergence;
use formation_config::node::error::NodeError;
use std::path::PathBuf;

/// How `formation sim`, `formation run` or `formation node` ended when it did not succeed; its
/// `Display` is the message on stderr.
#[derive(Debug, thiserror::Error)]
pub enum CommandError {
    /// Bad input (exit 2).
    #[error("error: {0}")]
    Input(#[from] InputError),
    /// `formation run` refused before anything of the run existed (exit 2).
    #[error("error: {0}")]
    Plan(#[from] PlanError),
    /// The output folder of `formation sim` is in use or not this user's own (exit 2).
    #[error("error: {0}")]
    OutFolder(#[from] crate::out_lock::OutLockError),
    /// `formation sim` could not write `scenario.toml` into its output folder (exit 1).
    #[error("error: cannot write {}/scenario.toml: {source}", out.display())]
    WriteScenario {
        /// The output folder.
        out: PathBuf,
        /// The file system's error.
        source: std::io::Error,
    },
    /// `formation sim` could not write its outputs (exit 1).
    #[error("error: cannot write outputs to {}: {source}", out.display())]
    WriteOutputs {
        /// The output folder.
        out: PathBuf,
        /// The file system's error.
        source: std::io::Error,
    },
    /// A run failed while it was set up, driven or written (exit 1).
    #[error("error: {0}")]
    Run(#[from] RunError),
    /// A role process of a run died; it was named on stderr when it was detected (exit 1).
    #[error("a role process died")]
    Died,
    /// The run ran to its end and wrote its outputs, but diverged (exit 3).
    #[error(
        "diverged: t = {:.3} s, agent {}: {} (outputs up to that step are written; exit code {})",
        .0.time_s, .0.agent, .0.cause, crate::cli::EXIT_RESULT_FAILED
    )]
    Diverged(Divergence),
    /// The run ran to its end and wrote its outputs, but two quadrotors came nearer than the
    /// safety distance (exit 3).
    #[error(
        "separation failed: {steps} steps below the safety distance of {safety_m} m, closest {:.3} m (agents {} and {} at t = {:.3} s; outputs are written; exit code {})",
        .closest.distance_m, .closest.agents[0], .closest.agents[1], .closest.time_s,
        crate::cli::EXIT_RESULT_FAILED
    )]
    TooClose {
        /// Steps below the safety distance.
        steps: u64,
        /// The safety distance, m.
        safety_m: f64,
        /// The closest approach.
        closest: crate::record::separation::Approach,
    },
    /// Ctrl-C: the outputs up to the last recorded step are in `out` (exit 130).
    #[error("interrupted: outputs up to the last recorded step are in {}", .0.display())]
    Interrupted(PathBuf),
    /// `formation node` with a role that is none (exit 2).
    #[error("formation node: unknown role '{0}' (plant, leader or agent)")]
    UnknownRole(String),
    /// `formation node ROLE` with arguments it cannot read (exit 2).
    #[error("formation node {role}: {source}")]
    NodeArgs {
        /// The role.
        role: formation_config::protocol::messages::Role,
        /// What is wrong with the arguments.
        source: NodeError,
    },
    /// A role process failed (exit 1); also in its log.
    #[error("fm-{role}: {source}")]
    Node {
        /// The role.
        role: formation_config::protocol::messages::Role,
        /// What failed.
        source: NodeError,
    },
}

impl CommandError {
    /// Whether the message is already on stderr (a dead role process is named when detected).
    pub fn already_said(&self) -> bool {
        matches!(self, CommandError::Died)
    }
}

/// Why `formation run` refuses to start: bad input or a machine it cannot use (exit 2).
#[derive(Debug, thiserror::Error)]
pub enum PlanError {
    /// More agents than a run supports.
    #[error("{n} agents: at most {max} are supported")]
    TooManyAgents {
        /// The scenario's agents.
        n: usize,
        /// The most a run supports.
        max: usize,
    },
    /// More outside observers than the services support.
    #[error("--observers {given}: at most {max} outside observers are supported")]
    Observers {
        /// `--observers`.
        given: usize,
        /// The most supported.
        max: usize,
    },
    /// A realtime run with an event that takes an agent down (its index in the timeline).
    #[error("events[{index}]: a `{kind}` event needs a lockstep run (realtime runs take faults, delays, link faults and message loss; docs/failures.md)")]
    NeedsLockstep {
        /// The event's index in the scenario's timeline.
        index: usize,
        /// The event's kind.
        kind: String,
    },
    /// `--pin` is refused.
    #[error("{0}")]
    Pin(#[from] crate::run::placement::PinError),
    /// The runs folder cannot be used.
    #[error("{0}")]
    RunsFolder(#[from] crate::live::registry::RegistryError),
    /// A host cannot be reached, checked or prepared.
    #[error("{0}")]
    Hosts(#[from] crate::run::remote_error::RemoteError),
    /// `--rt-priority` is refused.
    #[error("{0}")]
    Rt(#[from] crate::run::rt::RtError),
    /// `--zenoh-listen` is refused.
    #[error("{0}")]
    Export(#[from] crate::run::export::ExportError),
    /// The output folder is in use or not this user's own.
    #[error("{0}")]
    OutFolder(#[from] crate::out_lock::OutLockError),
}

/// What failed while a run was set up, driven or written (exit 1); each names the file, service
/// or process.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    /// A role process could not be started.
    #[error("{0}")]
    Spawn(#[from] crate::run::spawn::SpawnError),
    /// The recorder's files cannot be created in the output folder.
    #[error("cannot write outputs to {}: {source}", out.display())]
    Outputs {
        /// The output folder.
        out: PathBuf,
        /// The file system's error.
        source: std::io::Error,
    },
    /// `scenario.toml` cannot be written into the run's folder.
    #[error("cannot write {}/scenario.toml: {source}", dir.display())]
    Scenario {
        /// The run's folder.
        dir: PathBuf,
        /// The file system's error.
        source: std::io::Error,
    },
    /// The orchestrator's iceoryx2 node cannot be made.
    #[error("{0}")]
    Node(#[from] formation_config::node::ipc::IpcError),
    /// A service or port of the run cannot be created or opened.
    #[error("{0}")]
    Port(#[from] formation_config::node::error::PortError),
    /// The export cannot start reading the run's services.
    #[error("{0}")]
    Export(#[from] crate::run::export::ExportError),
    /// The injection services or `events.jsonl` cannot be opened.
    #[error("{0}")]
    Injections(#[from] crate::run::injections::InjectionsError),
    /// A host of the run cannot be prepared or start an agent.
    #[error("{0}")]
    Remote(#[from] crate::run::remote_error::RemoteError),
    /// The run's record cannot be written into the runs folder.
    #[error("{0}")]
    Registry(#[from] crate::live::registry::RegistryError),
    /// The supervision's takeover cannot open its ports (its layer reports its errors as text).
    #[error("{0}")]
    Takeover(String),
    /// `summary.json` cannot be written.
    #[error("cannot write {}/summary.json: {source}", out.display())]
    Summary {
        /// The output folder.
        out: PathBuf,
        /// The file system's error.
        source: std::io::Error,
    },
    /// The run stopped on an error the driver detected (its message).
    #[error("{0}")]
    Failed(String),
}
