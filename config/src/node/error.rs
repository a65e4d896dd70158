//! Errors of a role process: which service or input, and what failed.

use super::ipc::IpcError;
use std::fmt;

/// What failed on a service.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PortErrorKind {
    /// The name is not a valid iceoryx2 service name.
    Name,
    /// The service could not be opened (missing, or another message type or limits).
    Open,
    /// The service could not be created.
    Create,
    /// A port (publisher, subscriber, notifier, listener) could not be made on it.
    Port,
    /// A sample could not be loaned or sent.
    Send,
    /// A sample could not be received.
    Receive,
    /// Waiting on the event failed.
    Wait,
}

impl PortErrorKind {
    fn verb(self) -> &'static str {
        match self {
            PortErrorKind::Name => "invalid service name",
            PortErrorKind::Open => "cannot open",
            PortErrorKind::Create => "cannot create",
            PortErrorKind::Port => "cannot make a port on",
            PortErrorKind::Send => "cannot send on",
            PortErrorKind::Receive => "cannot receive from",
            PortErrorKind::Wait => "cannot wait on",
        }
    }
}

/// A failure on one service of the run.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PortError {
    /// The service name (relative to the run prefix).
    pub service: String,
    /// What failed.
    pub kind: PortErrorKind,
    /// iceoryx2's error, as it reports it.
    pub detail: String,
}

impl PortError {
    /// A failure of `kind` on `service`, with iceoryx2's error `detail`.
    pub fn new(service: &str, kind: PortErrorKind, detail: impl fmt::Debug) -> PortError {
        PortError {
            service: service.to_string(),
            kind,
            detail: format!("{detail:?}"),
        }
    }
}

impl fmt::Display for PortError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} {}: {}", self.kind.verb(), self.service, self.detail)
    }
}

impl std::error::Error for PortError {}

/// Why a role process (or the orchestrator's side of the run) stopped with an error.
#[derive(Debug)]
pub enum NodeError {
    /// Its command line is wrong.
    Args(String),
    /// A file of the run (scenario, log, timing report) could not be read or written.
    File {
        /// The file.
        path: std::path::PathBuf,
        /// What went wrong.
        detail: String,
    },
    /// The run's scenario or variant does not fit this process (e.g. an agent index beyond N).
    Scenario(String),
    /// Its iceoryx2 node could not be created.
    Ipc(IpcError),
    /// A service failed.
    Port(PortError),
    /// A peer broke the protocol (a message out of step, a missing reference).
    Protocol(String),
    /// Its parent went away or a signal asked it to stop before the run ended.
    Stopped(String),
    /// The operating system refused a setting (scheduling policy, priority, CPU affinity).
    System(String),
}

impl fmt::Display for NodeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            NodeError::Args(e) => write!(f, "bad arguments: {e}"),
            NodeError::File { path, detail } => write!(f, "{}: {detail}", path.display()),
            NodeError::Scenario(e) => write!(f, "{e}"),
            NodeError::Ipc(e) => write!(f, "{e}"),
            NodeError::Port(e) => write!(f, "{e}"),
            NodeError::Protocol(e) => write!(f, "protocol: {e}"),
            NodeError::System(e) => write!(f, "{e}"),
            NodeError::Stopped(e) => write!(f, "{e}"),
        }
    }
}

impl std::error::Error for NodeError {}

impl NodeError {
    /// A port could not be made because the service has all the ports of that kind it allows:
    /// another process (a predecessor not gone yet) holds the one this process needs.
    pub fn port_held(&self) -> bool {
        matches!(self, NodeError::Port(PortError { kind: PortErrorKind::Port, detail, .. })
            if detail.starts_with("ExceedsMaxSupported"))
    }
}

impl From<PortError> for NodeError {
    fn from(e: PortError) -> Self {
        NodeError::Port(e)
    }
}

impl From<IpcError> for NodeError {
    fn from(e: IpcError) -> Self {
        NodeError::Ipc(e)
    }
}

/// The orchestrator's command-line layer reports errors as text: a port or node error becomes its
/// message (which names the service).
impl From<PortError> for String {
    fn from(e: PortError) -> String {
        e.to_string()
    }
}

impl From<NodeError> for String {
    fn from(e: NodeError) -> String {
        e.to_string()
    }
}
