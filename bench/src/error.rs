//! The errors of `formation bench`: a bad argument ([`ArgError`]), what failed in a case or a
//! peer process ([`CaseError`]), and why the command ([`BenchError`]) or a peer process
//! ([`PeerError`]) did not succeed, which the CLI maps to exit codes (docs/cli.md).

use std::error::Error;

/// An error from a layer below (iceoryx2, a socket, Zenoh, a file), as that layer typed it.
pub type Source = Box<dyn Error + Send + Sync>;

/// A bad argument of `formation bench`: the option and what it expects.
#[derive(Debug, thiserror::Error)]
pub enum ArgError {
    /// `--n` without a number.
    #[error("--n needs at least one number")]
    NoN,
    /// An N outside 1..=MAX_N.
    #[error("--n must be in 1..={max}, got {n}")]
    N {
        /// The N given.
        n: usize,
        /// The largest N.
        max: usize,
    },
    /// `--payload` outside its range.
    #[error("--payload must be in {min}..={max} bytes, got {got}")]
    Payload {
        /// The payload given, bytes.
        got: usize,
        /// The least payload, bytes.
        min: usize,
        /// The largest payload, bytes.
        max: usize,
    },
    /// `--seconds` outside (0, 3600].
    #[error("--seconds must be in (0, 3600], got {0}")]
    Seconds(f64),
    /// `--rounds` outside 1..=MAX_ROUNDS.
    #[error("--rounds must be in 1..={max}, got {got}")]
    Rounds {
        /// The rounds given.
        got: usize,
        /// The most rounds.
        max: usize,
    },
    /// `--spin-us` above one second.
    #[error("--spin-us must be at most 1000000, got {0}")]
    SpinUs(u64),
    /// `--cpu` is not a list of CPUs this process may use.
    #[error("{0}")]
    Cpu(formation_runtime::cpus::CpuListError),
    /// A name of `--transports` that is no transport.
    #[error("unknown transport '{0}'")]
    Transport(String),
    /// `--transports zenoh` in a build without the `multihost` feature.
    #[error(
        "transport 'zenoh' needs the cargo feature `multihost` (this formation was built without it)"
    )]
    ZenohNeedsMultihost,
}

/// Why `formation bench` did not succeed; its `Display` is the message on stderr.
#[derive(Debug, thiserror::Error)]
pub enum BenchError {
    /// A bad argument (bad input).
    #[error("error: {0}")]
    Arg(#[from] ArgError),
    /// `--host` with `--seconds` outside (0, 3600] (bad input).
    #[error("error: --seconds {0}: expected 0 < s <= 3600")]
    HostSeconds(f64),
    /// The bench's own iceoryx2 node could not be made.
    #[error("error: {0}")]
    Node(formation_config::node::ipc::IpcError),
    /// Ctrl-C: the cases measured so far are not reported.
    #[error("formation bench: interrupted")]
    Interrupted,
    /// Cases failed (each said on stderr as it failed); the others are reported.
    #[error("formation bench: {0} case(s) failed")]
    CasesFailed(usize),
}

/// Why a `formation bench-peer` process stopped; its `Display` is the message on stderr.
#[derive(Debug, thiserror::Error)]
pub enum PeerError {
    /// `--transport` names no transport (bad input).
    #[error("formation bench-peer: unknown transport '{0}'")]
    Transport(String),
    /// `--wait` names no waiting strategy (bad input).
    #[error("formation bench-peer: unknown wait strategy '{0}'")]
    Wait(String),
    /// `--payload` outside its range, bytes (bad input).
    #[error("formation bench-peer: payload {0} out of range")]
    Payload(usize),
    /// `--prefix` is no valid iceoryx2 prefix (bad input).
    #[error("formation bench-peer: invalid prefix '{0}'")]
    Prefix(String),
    /// `--cpu` could not be applied (bad input).
    #[error("formation bench-peer: cannot pin to cpu {cpu}: {source}")]
    Pin {
        /// The CPU of `--cpu`.
        cpu: usize,
        /// What the system said.
        source: std::io::Error,
    },
    /// `--batch` could not be applied (bad input).
    #[error("formation bench-peer: {0}")]
    Batch(formation_config::node::error::NodeError),
    /// The case failed in this peer.
    #[error("formation bench-peer {transport} #{index} (case {case}): {source}")]
    Case {
        /// The transport of `--transport`.
        transport: String,
        /// The agent index of `--index`.
        index: u32,
        /// The case number of `--case`.
        case: usize,
        /// What failed.
        source: CaseError,
    },
}

/// What failed in a case of `formation bench` or in a peer process.
#[derive(Debug, thiserror::Error)]
pub enum CaseError {
    /// An operation failed: which (`uds bind`, `send step 12`, a file's path) and the error of
    /// the layer below.
    #[error("{what}: {source}")]
    Op {
        /// The operation or file.
        what: String,
        /// The error under it.
        source: Source,
    },
    /// An error of the layer below that names what failed by itself.
    #[error(transparent)]
    Below(Source),
    /// The bench was interrupted (Ctrl-C).
    #[error("interrupted")]
    Interrupted,
    /// Fewer replies than agents before the step's deadline.
    #[error("{got} of {n} replies arrived (timeout or a peer process died)")]
    Replies {
        /// Replies received.
        got: usize,
        /// Replies expected.
        n: usize,
    },
    /// A peer process whose parent (the bench) is gone.
    #[error("parent process is gone")]
    Orphaned,
    /// A peer process that received no step for its idle timeout.
    #[error("no step arrived in time")]
    Idle,
    /// Peer processes that failed or had to be killed: one entry per peer.
    #[error("{}", .0.join("; "))]
    Peers(Vec<String>),
    /// A case of transport `zenoh` planned among the generic ones.
    #[error("zenoh is measured by its own cases (bench::zenoh)")]
    ZenohCase,
    /// A peer process started without an option its transport needs.
    #[error("{0}")]
    Missing(&'static str),
    /// A `formation run` of the bench exited with a failure: its status and last stderr line.
    #[error("formation run failed ({status}): {last}")]
    RunFailed {
        /// Its exit status.
        status: std::process::ExitStatus,
        /// The last line of its stderr.
        last: String,
    },
    /// A run's summary.json without the lockstep step timing (`timing.step_us`).
    #[error("{what} has no lockstep step timing")]
    NoTiming {
        /// The run folder or file named.
        what: String,
    },
    /// The split run's host daemon exited before listening.
    #[error("the host daemon exited ({status}): {why}")]
    DaemonExited {
        /// Its exit status.
        status: std::process::ExitStatus,
        /// Why (its last log line, or the private /dev/shm it could not mount).
        why: String,
    },
    /// The split run's host daemon did not listen within its start timeout.
    #[error("the host daemon did not listen in time: {0}")]
    DaemonSlow(String),
    /// The split run failed: its error and the host daemon's last log line.
    #[error("{run} (host daemon: {last})")]
    Split {
        /// The run's error.
        run: Box<CaseError>,
        /// The daemon's last log line.
        last: String,
    },
    /// The split run left iceoryx2 files in the daemon's /dev/shm.
    #[error("the run left {} file(s) in the host daemon's /dev/shm: {}", .0.len(), .0.join(" "))]
    Residue(Vec<String>),
}

impl CaseError {
    /// An error of the layer below that names what failed by itself.
    pub fn below(e: impl Into<Source>) -> CaseError {
        CaseError::Below(e.into())
    }

    /// `what` failed with `e`.
    pub fn op(what: impl Into<String>, e: impl Into<Source>) -> CaseError {
        CaseError::Op {
            what: what.into(),
            source: e.into(),
        }
    }

    /// File `path` failed with `e`.
    pub fn file(path: &std::path::Path, e: impl Into<Source>) -> CaseError {
        CaseError::op(path.display().to_string(), e)
    }
}

/// `result.ctx(what)`: the error of `result` as [`CaseError::Op`] naming `what`.
pub trait ResultExt<T> {
    /// Names the operation that failed.
    fn ctx(self, what: impl Into<String>) -> Result<T, CaseError>;
}

impl<T, E: Into<Source>> ResultExt<T> for Result<T, E> {
    fn ctx(self, what: impl Into<String>) -> Result<T, CaseError> {
        self.map_err(|e| CaseError::op(what, e))
    }
}
