//! Why a run spread over hosts cannot be placed, reached, prepared or taken over
//! ([`RemoteError`]); each names the argument, the host or the file.

#[cfg(feature = "multihost")]
use formation_net::{bridge::BridgeError, cluster, colocate, plan, session};
use std::path::PathBuf;

/// What failed with the other hosts of a run (or the placement options that name them).
#[derive(Debug, thiserror::Error)]
#[cfg_attr(not(feature = "multihost"), allow(dead_code))]
pub enum RemoteError {
    /// `--hosts` names something that is no host name (the `launcher` name included).
    #[error("--hosts: '{host}' is not a host name (1..=32 of [A-Za-z0-9_-], not '{launcher}')")]
    HostName {
        /// The name given.
        host: String,
        /// The name of this machine in a placement.
        launcher: &'static str,
    },
    /// A `--place` that is not `IDS@HOST`.
    #[error("--place {0}: expected IDS@HOST, e.g. 4,5@b")]
    PlaceForm(String),
    /// A `--place` host that is not in `--hosts`.
    #[error("--place {place}: host '{host}' is not in --hosts")]
    PlaceHost {
        /// The `--place` argument.
        place: String,
        /// Its host.
        host: String,
    },
    /// A `--place` id that is no number.
    #[error("--place {place}: '{id}' is not an agent id")]
    PlaceId {
        /// The `--place` argument.
        place: String,
        /// The id as written.
        id: String,
    },
    /// A `--place` id outside the run's agents.
    #[error("--place {place}: agent {agent} does not exist (ids 1..={n})")]
    PlaceRange {
        /// The `--place` argument.
        place: String,
        /// The id, 1-based.
        agent: usize,
        /// The run's agents.
        n: usize,
    },
    /// An agent in two `--place` arguments.
    #[error("--place {place}: agent {agent} is placed twice")]
    PlaceTwice {
        /// The second `--place` argument naming it.
        place: String,
        /// The id, 1-based.
        agent: usize,
    },
    /// `--place` or `--connect` without `--hosts`.
    #[error("--place and --connect need --hosts")]
    NeedsHosts,
    /// A host's default endpoint (its socket in this user's runtime folder) cannot be named.
    #[cfg(feature = "multihost")]
    #[error("{0}")]
    Endpoint(#[from] session::OptionError),
    /// The session cannot open, or hosts did not answer the handshake (with what is wrong with
    /// each endpoint that could be diagnosed).
    #[cfg(feature = "multihost")]
    #[error("{source}{}", diagnosed(diagnoses))]
    Handshake {
        /// The handshake's error.
        source: cluster::HandshakeError,
        /// What is wrong with each endpoint (authentication, socket, address), if anything.
        diagnoses: Vec<String>,
    },
    /// A daemon shares this machine's `/dev/shm` in a way the run cannot use.
    #[cfg(feature = "multihost")]
    #[error("{0}")]
    Colocation(#[from] colocate::ColocationError),
    /// This machine's bridge's link delays cannot be written.
    #[error("{0}")]
    TimingReport(formation_config::node::error::NodeError),
    /// A host did not answer the clock probe.
    #[error("host {0} did not answer the clock probe")]
    ClockProbe(String),
    /// The run cannot be announced to the hosts.
    #[cfg(feature = "multihost")]
    #[error("{0}")]
    Announce(#[from] cluster::AnnounceError),
    /// The run's secret was not made before it was needed.
    #[error("the run's secret was not made")]
    NoSecret,
    /// A request to a host failed (no answer, a broken link).
    #[cfg(feature = "multihost")]
    #[error("{0}")]
    Request(#[from] cluster::RequestError),
    /// A host refused to prepare the run.
    #[error("host {host} refused the run: {why}")]
    Refused {
        /// The host.
        host: String,
        /// Its reason.
        why: String,
    },
    /// This machine's bridge cannot start or re-plan.
    #[cfg(feature = "multihost")]
    #[error("{0}")]
    Bridge(#[from] BridgeError),
    /// A host refused a request about the run (its reason).
    #[error("host {host}: {why}")]
    Host {
        /// The host.
        host: String,
        /// Its reason.
        why: String,
    },
    /// A host's timing report is no JSON report.
    #[error("host {host}: a malformed report: {source}")]
    Report {
        /// The host.
        host: String,
        /// The JSON reader's error.
        source: serde_json::Error,
    },
    /// A host sent a timing file whose name would leave the timing folder.
    #[error("host {host}: refused a timing file named '{name}'")]
    TimingName {
        /// The host.
        host: String,
        /// The name it sent.
        name: String,
    },
    /// A file of the run (timing, rejoin, checkpoint) cannot be read or written.
    #[error("{}: {source}", path.display())]
    File {
        /// The file or folder.
        path: PathBuf,
        /// The file system's error.
        source: std::io::Error,
    },
    /// A host started an agent but gave no pid.
    #[error("host {host} started {label} without a pid")]
    NoPid {
        /// The host.
        host: String,
        /// The agent, e.g. `agent 4 (--agent 3)`.
        label: String,
    },
    /// A host refused to start an agent.
    #[error("host {host} cannot start {label}: {why}")]
    Spawn {
        /// The host.
        host: String,
        /// The agent, e.g. `agent 4 (--agent 3)`.
        label: String,
        /// Its reason.
        why: String,
    },
    /// The agents of a lost host cannot be placed anew.
    #[cfg(feature = "multihost")]
    #[error("{0}")]
    Placement(#[from] plan::PlanError),
    /// A remaining host refused to re-plan after a host was lost.
    #[error("host {host} cannot re-plan after {lost} was lost: {why}")]
    Replan {
        /// The host asked.
        host: String,
        /// The host lost.
        lost: String,
        /// Its reason.
        why: String,
    },
}

/// The diagnoses of the endpoints after a handshake's error: `: ONE; TWO`, or nothing.
#[cfg(feature = "multihost")]
fn diagnosed(diagnoses: &[String]) -> String {
    if diagnoses.is_empty() {
        String::new()
    } else {
        format!(": {}", diagnoses.join("; "))
    }
}

impl RemoteError {
    /// A file of the run that cannot be read or written.
    pub fn file(path: impl Into<PathBuf>) -> impl FnOnce(std::io::Error) -> RemoteError {
        let path = path.into();
        move |source| RemoteError::File { path, source }
    }
}

// The supervision's takeover still reports its errors as text: a failure with the other hosts is
// said there with this message.
impl From<RemoteError> for String {
    fn from(e: RemoteError) -> String {
        e.to_string()
    }
}
