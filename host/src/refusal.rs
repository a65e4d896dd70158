//! Why a host daemon does not start ([`ServeError`]) or refuses a request ([`Refusal`], whose
//! text is the reply's `Refused` reason on the wire, read by the orchestrator).

use formation_config::node::error::NodeError;
use formation_config::node::ipc::IpcError;
use formation_net::bridge::BridgeError;
use formation_net::colocate::ServicesError;
use std::io::ErrorKind;
use std::path::PathBuf;

/// Why `formation host` does not start (exit 2).
#[derive(Debug, thiserror::Error)]
pub enum ServeError {
    /// `--name` that is no host name (or the launcher's).
    #[error("--name '{name}': use 1..=32 characters of [A-Za-z0-9_-] (and not '{launcher}')")]
    Name {
        /// The name given.
        name: String,
        /// The launcher's name, reserved.
        launcher: &'static str,
    },
    /// The runs folder cannot be made owner-only.
    #[error("{0}")]
    Folder(#[from] FolderError),
    /// The daemon's link cannot open.
    #[error("{0}")]
    Link(#[from] formation_net::daemon_link::LinkError),
}

/// Why a folder of the daemon cannot be made owner-only.
#[derive(Debug, thiserror::Error)]
pub enum FolderError {
    /// It cannot be looked at or its mode set.
    #[error("{}: {source}", dir.display())]
    Io {
        /// The folder.
        dir: PathBuf,
        /// The file system's error.
        source: std::io::Error,
    },
    /// A symbolic link, or another user's folder.
    #[error("{}: not a folder of this user (refusing a symbolic link or another user's folder)", .0.display())]
    NotOwn(PathBuf),
}

/// Why a daemon refuses a request about a run; each names the run, agent or file.
#[derive(Debug, thiserror::Error)]
pub enum Refusal {
    /// No such run here.
    #[error("no run {run} on host {host}")]
    NoRun {
        /// The run's id.
        run: String,
        /// This host.
        host: String,
    },
    /// The orchestrator's build, protocol or wire layout differ from this daemon's.
    #[error("the orchestrator and host {host} differ: {}", differences.join("; "))]
    Differ {
        /// This host.
        host: String,
        /// What differs.
        differences: Vec<String>,
    },
    /// A run id that is not 1..=16 hexadecimal digits.
    #[error("run id '{0}': expected 1..=16 hexadecimal digits")]
    RunId(String),
    /// A prefix that is not the run's.
    #[error("prefix '{prefix}' is not the run's ({expected})")]
    Prefix {
        /// The prefix asked for.
        prefix: String,
        /// The run's.
        expected: String,
    },
    /// The run is prepared here already.
    #[error("run {0} is already prepared here")]
    AlreadyPrepared(String),
    /// The run's scenario cannot be read.
    #[error("scenario: {0}")]
    Scenario(#[from] formation_config::scenario::LoadError),
    /// The run's scenario breaks its rules.
    #[error("scenario: {0}")]
    InvalidScenario(#[from] formation_config::scenario::validate::ValidationErrors),
    /// More agents than a run supports.
    #[error("{n} agents: at most {max} are supported")]
    TooManyAgents {
        /// The scenario's agents.
        n: usize,
        /// The most supported.
        max: usize,
    },
    /// A variant that is none.
    #[error("unknown variant '{0}'")]
    Variant(String),
    /// A placement with another count of hosts than agents.
    #[error("{hosts} agent hosts for {n} agents")]
    AgentHosts {
        /// The hosts in the placement.
        hosts: usize,
        /// The run's agents.
        n: usize,
    },
    /// A host name of the placement is unfit for a key.
    #[error("a host name of the placement is not key-safe")]
    NotKeySafe,
    /// No agent of the run is placed here.
    #[error("no agent of the run is placed on {0}")]
    NothingHere(String),
    /// A realtime priority above 99.
    #[error("rt_priority {0}: at most 99")]
    RtPriority(u32),
    /// More outside observers than the services support.
    #[error("{given} observers: at most {max}")]
    Observers {
        /// The observers asked for.
        given: usize,
        /// The most supported.
        max: usize,
    },
    /// The run's folder cannot be created here (the daemon's log names it).
    #[error("cannot create the run's folder on this host")]
    RunFolder,
    /// The run's scenario cannot be written into its folder.
    #[error("cannot write the scenario: {0}")]
    WriteScenario(std::io::Error),
    /// The run's membership file cannot be created.
    #[error("{0}")]
    Membership(NodeError),
    /// The daemon's iceoryx2 node for the run cannot be made.
    #[error("{0}")]
    Node(#[from] IpcError),
    /// The run's bridge cannot start or re-plan.
    #[error("{0}")]
    Bridge(#[from] BridgeError),
    /// A co-located run whose services are not this host's.
    #[error("{0}")]
    Services(#[from] ServicesError),
    /// A co-located run's membership lock is unfit (the daemon's log names the path).
    #[error("a co-located run whose membership lock is not a private file of this host's user")]
    Members,
    /// An agent that is not placed here.
    #[error("agent {agent} of run {run} is not placed on {host}")]
    NotPlacedHere {
        /// The agent, 1-based.
        agent: usize,
        /// The run's id.
        run: String,
        /// This host.
        host: String,
    },
    /// An agent that runs here already.
    #[error("agent {agent} of run {run} is already running here")]
    Running {
        /// The agent, 1-based.
        agent: usize,
        /// The run's id.
        run: String,
    },
    /// A rejoin file that fails its checks.
    #[error("the rejoin file of agent {agent} is refused: {why}")]
    Rejoin {
        /// The agent, 1-based.
        agent: usize,
        /// Why.
        why: formation_config::node::restart::Refusal,
    },
    /// A rejoin file that cannot be written.
    #[error("cannot write agent {agent}'s rejoin file: {kind}")]
    WriteRejoin {
        /// The agent, 1-based.
        agent: usize,
        /// The file system's error.
        kind: ErrorKind,
    },
    /// An agent process that cannot be started.
    #[error("cannot start agent {agent}: {source}")]
    Start {
        /// The agent, 1-based.
        agent: usize,
        /// The system's error.
        source: std::io::Error,
    },
    /// A signal other than SIGSTOP and SIGCONT.
    #[error("signal {0}: only SIGSTOP and SIGCONT are sent on request")]
    Signal(i32),
    /// An agent with no process here.
    #[error("agent {0} is not running here")]
    NotRunning(usize),
    /// An agent's checkpoint cannot be read.
    #[error("agent {agent}'s checkpoint: {kind}")]
    Checkpoint {
        /// The agent, 1-based.
        agent: usize,
        /// The file system's error.
        kind: ErrorKind,
    },
    /// A re-plan whose placement does not fit the run.
    #[error(
        "re-plan of run {run}: {hosts} agent hosts for {agents} agents, or a name not key-safe"
    )]
    ReplanShape {
        /// The run's id.
        run: String,
        /// The hosts in the new placement.
        hosts: usize,
        /// The run's agents.
        agents: usize,
    },
    /// A re-plan that moves an agent to or from this host.
    #[error("re-plan of run {run}: agent {agent} would move from {was} to {now}; agents move off a lost host to the launcher only")]
    ReplanMove {
        /// The run's id.
        run: String,
        /// The agent, 1-based.
        agent: usize,
        /// Its host.
        was: String,
        /// The host asked for.
        now: String,
    },
    /// This host's bridge's link delays cannot be written.
    #[error("{0}")]
    TimingReport(NodeError),
    /// The run's timing folder cannot be listed.
    #[error("the run's timing folder: {0}")]
    TimingFolder(ErrorKind),
    /// A timing file cannot be read.
    #[error("timing file {name}: {kind}")]
    TimingFile {
        /// The file's name.
        name: String,
        /// The file system's error.
        kind: ErrorKind,
    },
}
