//! How a command of the runtime (`sim`, `run`, `node`) ends when it does not succeed: one
//! [`CommandError`] per command, whose `Display` is the whole message printed on stderr. The
//! `formation` binary maps it to the exit code (docs/cli.md) in its `main`, the only place that
//! chooses one.
//!
//! * [`InputError`]: the scenario and the arguments every runner takes (exit 2).
//! * [`crate::run::PlanError`]: what `formation run` checks before anything of the run exists
//!   (exit 2).
//! * [`crate::run::RunError`]: what failed while a run was set up, driven or written (exit 1).

use crate::cli::{print_lines, OverrideError};
use crate::record::metrics::Divergence;
use formation_config::node::error::NodeError;
use formation_config::scenario::validate::ValidationErrors;
use std::path::PathBuf;

/// Why the scenario or the arguments of a runner (`sim`, `run`, `check`) are refused: bad input,
/// exit 2. Each names the argument or file.
#[derive(Debug, thiserror::Error)]
pub enum InputError {
    /// The scenario cannot be loaded (its name or file, and why).
    #[error("{0}")]
    Load(#[from] formation_config::scenario::LoadError),
    /// A `--set` override is refused.
    #[error("{0}")]
    Override(#[from] OverrideError),
    /// The scenario `name` after the overrides breaks its rules: every broken rule, one a line.
    #[error("scenario '{name}' is invalid:\n{}", print_lines(&errors.0))]
    Invalid {
        /// The scenario's name or file as given.
        name: String,
        /// The broken rules.
        errors: ValidationErrors,
    },
    /// The scenario with the runtime flags and the `--events` file breaks its rules.
    #[error("the scenario with its runtime settings and events is invalid:\n{}", print_lines(&.0 .0))]
    InvalidWithEvents(ValidationErrors),
    /// `--variant` names no variant.
    #[error("unknown variant '{0}' (expected proposed, no-rbfnn or unconstrained)")]
    Variant(String),
    /// The `--events` file cannot be read or holds something else than events.
    #[error("--events {}: {source}", path.display())]
    Events {
        /// The file.
        path: PathBuf,
        /// What is wrong with it.
        source: crate::cli::EventsError,
    },
    /// `--ros2` or `--record rosbag2` in a build without ROS 2.
    #[error("{}", crate::record::NO_ROS2)]
    NoRos2,
    /// `--ros2` in an environment that is no valid ROS 2 one.
    #[cfg(feature = "ros2")]
    #[error("--ros2: {0}")]
    Ros2Env(crate::record::ros2::EnvError),
}

/// How `formation sim`, `formation run` or `formation node` ended when it did not succeed; its
/// `Display` is the message on stderr.
#[derive(Debug, thiserror::Error)]
pub enum CommandError {
    /// Bad input (exit 2).
    #[error("error: {0}")]
    Input(#[from] InputError),
    /// `formation run` refused before anything of the run existed (exit 2).
    #[error("error: {0}")]
    Plan(#[from] crate::run::PlanError),
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
    Run(#[from] crate::run::RunError),
    /// A role process of a run died; it was named on stderr when it was detected (exit 1).
    #[error("a role process died")]
    Died,
    /// The run ran to its end and wrote its outputs, but diverged (exit 3).
    #[error(
        "diverged: t = {:.3} s, agent {}: {} (outputs up to that step are written; exit code {})",
        .0.time_s, .0.agent, .0.cause, crate::cli::EXIT_RESULT_FAILED
    )]
    Diverged(Divergence),
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
