//! How `ps`, `inspect`, `inject` and `schema` end when they do not succeed ([`LiveError`]): its
//! `Display` is the whole message on stderr; the `formation` binary maps it to the exit code.

use formation_config::node::error::PortError;
use formation_runtime::live::registry::RegistryError;
use formation_runtime::live::validate::InjectError;
use formation_runtime::live::ClientError;

/// Why a command on running runs (or `schema`) failed.
#[derive(Debug, thiserror::Error)]
pub enum LiveError {
    /// The runs folder cannot be used, or no run (or several) answers to `--run` (exit 2).
    #[error("error: {0}")]
    Registry(#[from] RegistryError),
    /// `inspect`: the run is another user's (exit 2).
    #[error("error: {0}")]
    Access(#[from] ClientError),
    /// `inspect`: no such agent in the run (exit 2).
    #[error("error: {0}")]
    Agent(#[from] InjectError),
    /// `inspect`: no telemetry in time, or it cannot be read (exit 1).
    #[error("error: {0}")]
    Inspect(#[from] InspectError),
    /// `inject`: a bad value or a run it cannot reach; nothing sent (exit 2).
    #[error("error: {0}")]
    Request(#[from] RequestError),
    /// `inject`: sent, but not confirmed (exit 1).
    #[error("error: {0}")]
    Confirm(#[from] ConfirmError),
    /// `schema --n` outside 1..=MAX_AGENTS (exit 2).
    #[error("error: --n {n}: must be within 1..={max} agents")]
    AgentCount {
        /// `--n`.
        n: usize,
        /// The most agents a run supports.
        max: usize,
    },
    /// `schema --json`: the table cannot be written as JSON (exit 1).
    #[error("error: {0}")]
    Json(#[from] serde_json::Error),
}

/// Why `formation inject` sends nothing: a bad value, or a run it cannot reach (exit 2).
#[derive(Debug, thiserror::Error)]
pub enum RequestError {
    /// `--gamma` or `--delta` without three values (the option's name).
    #[error("--{0}: expected three comma-separated values")]
    Three(&'static str),
    /// `--agents` without two ids.
    #[error("--agents: expected two comma-separated agent ids")]
    Agents,
    /// A value outside its range.
    #[error("{0}")]
    Check(#[from] InjectError),
    /// The event breaks the rules of a timeline event.
    #[error("{0}")]
    Event(#[from] formation_config::scenario::validate::ValidationErrors),
    /// No run, several, or not the one named.
    #[error("{0}")]
    Registry(#[from] RegistryError),
    /// The run is another user's, or its scenario cannot be read.
    #[error("{0}")]
    Client(#[from] ClientError),
}

/// Why an injection sent was not confirmed (exit 1).
#[derive(Debug, thiserror::Error)]
pub enum ConfirmError {
    /// The client's node or the injection services cannot be opened.
    #[error("{0}")]
    Client(#[from] ClientError),
    /// A port cannot be opened or sent on.
    #[error("{0}")]
    Port(#[from] formation_config::node::error::PortError),
    /// The run refused it (its line in `events.jsonl`).
    #[error("the run rejected the injection: {0}")]
    Rejected(String),
    /// The run ended first.
    #[error("run {0} ended before confirming the injection")]
    Ended(String),
    /// No confirmation in time (`formation_live::inject`'s wait, 10 s).
    #[error("run {run} did not confirm the injection within {seconds} s")]
    Timeout {
        /// The run's id.
        run: String,
        /// How long it waited, s.
        seconds: u64,
    },
}

/// Why `formation inspect` stopped without showing a sample (exit 1).
#[derive(Debug, thiserror::Error)]
pub enum InspectError {
    /// The client's node cannot be made.
    #[error("{0}")]
    Client(#[from] ClientError),
    /// The agent's telemetry service cannot be opened.
    #[error("{0}")]
    Port(#[from] PortError),
    /// A sample of the telemetry cannot be received.
    #[error("telemetry: {0:?}")]
    Telemetry(PortError),
    /// No sample in time (`formation_live::inspect`'s wait, 10 s).
    #[error("no telemetry from agent {agent} of run {run} within {seconds} s")]
    NoSample {
        /// The agent, 1-based.
        agent: usize,
        /// The run's id.
        run: String,
        /// How long it waited, s.
        seconds: u64,
    },
}
