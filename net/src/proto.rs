//! Keys and messages between an orchestrator and the host daemons (JSON, with raw file bytes
//! after it where a file travels: see [`frame`]).
//!
//! | key | what |
//! |---|---|
//! | `formation/host/<name>` | liveliness token of a daemon |
//! | `formation/host/<name>/info` | queryable: [`HostInfo`] |
//! | `formation/host/<name>/req` | queryable: a [`Request`], answered by a [`Reply`] |
//! | `formation/run/<id>/orchestrator` | liveliness token of a run's orchestrator |
//! | `formation/run/<id>/exit` | a daemon's [`ExitReport`] for a process of the run |
//! | `formation/run/<id>/to/<host>` | the bridge's frames for that host ([`crate::bridge`]) |
//! | `formation/run/<id>/checkpoint` | a daemon's copy of each checkpoint its agents write ([`CheckpointNote`] and the file) |
//! | `formation/clock/<name>` | queryable: a daemon's `CLOCK_MONOTONIC`, ns, 8 bytes LE ([`crate::clock`]) |

use crate::auth::RunSecret;
use crate::colocate::{Facts, ShmPlace};
use crate::identity::Identity;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// Liveliness key of a daemon.
pub fn host_token(name: &str) -> String {
    format!("formation/host/{name}")
}
/// Every daemon's liveliness key.
pub const HOSTS: &str = "formation/host/*";
/// Info queryable of a daemon.
pub fn host_info(name: &str) -> String {
    format!("formation/host/{name}/info")
}
/// Request queryable of a daemon.
pub fn host_req(name: &str) -> String {
    format!("formation/host/{name}/req")
}
/// Liveliness key of a run's orchestrator.
pub fn run_token(run: &str) -> String {
    format!("formation/run/{run}/orchestrator")
}
/// Exit reports of a run.
pub fn run_exit(run: &str) -> String {
    format!("formation/run/{run}/exit")
}
/// Checkpoints of a run's remote agents, as their daemons forward them.
pub fn run_checkpoint(run: &str) -> String {
    format!("formation/run/{run}/checkpoint")
}
/// Bridge frames of a run for `host`.
pub fn run_to(run: &str, host: &str) -> String {
    format!("formation/run/{run}/to/{host}")
}

/// Clock queryable of a daemon (answered at once, outside its request loop).
pub fn clock_key(name: &str) -> String {
    format!("formation/clock/{name}")
}

/// True for a host name usable in keys: 1..=32 of `[A-Za-z0-9_-]`.
pub fn valid_name(name: &str) -> bool {
    !name.is_empty()
        && name.len() <= 32
        && name
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b == b'_' || b == b'-')
}

/// What a daemon says about itself.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct HostInfo {
    /// Its name (`--name`, default the machine's host name).
    pub name: String,
    /// CPUs it may use.
    pub cpus: usize,
    /// Its endpoints (`--listen`).
    pub listen: Vec<String>,
    /// Runs it holds now.
    pub runs: usize,
    /// Daemon pid.
    pub pid: u32,
    /// Protocol, build, layout.
    pub identity: Identity,
    /// Its wall clock when it answered, µs since the Unix epoch (clock offset estimate).
    pub clock_us: u64,
    /// Where its shared memory lives (`None`: unknown), its effective uid and its iceoryx2
    /// root: whether it is co-located with an orchestrator ([`crate::colocate`]).
    #[serde(default)]
    pub shm: Option<ShmPlace>,
    /// Its effective uid.
    #[serde(default)]
    pub uid: Option<u32>,
    /// Its iceoryx2 root folder.
    #[serde(default)]
    pub iox2_root: Option<String>,
}

impl HostInfo {
    /// What the co-location decision needs of this daemon.
    pub fn facts(&self) -> Facts {
        Facts {
            shm: self.shm.clone(),
            uid: self.uid,
            iox2_root: self.iox2_root.clone(),
        }
    }
}

/// A run on a co-located host ([`crate::colocate`]): the daemon creates no service and runs no
/// bridge; its agents open the orchestrator's services and join its membership lock. The daemon
/// checks all of it itself before it accepts the run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Colocated {
    /// The orchestrator's iceoryx2 root (must be the daemon's own).
    pub iox2_root: String,
    /// The orchestrator's membership lock of the run (`formation_config::node::members`), which
    /// the daemon's agents join: the last process of the run removes its files.
    pub members: std::path::PathBuf,
}

/// A run's share of one host: its agents, and what the daemon needs to start them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunRequest {
    /// Run id (`[0-9a-f]`).
    pub run_id: String,
    /// The run's secret ([`crate::auth`]): every later request about the run, the daemon's
    /// replies, the bridge's frames and the daemon's reports carry proof of it.
    pub secret: RunSecret,
    /// iceoryx2 prefix.
    pub prefix: String,
    /// The resolved scenario (validated again by the daemon).
    pub scenario_toml: String,
    /// Controller variant.
    pub variant: String,
    /// Host of every agent (index = 0-based agent).
    pub agent_hosts: Vec<String>,
    /// The launching host (plant, leader, orchestrator, clients).
    pub launcher: String,
    /// Realtime mode.
    pub realtime: bool,
    /// `SCHED_FIFO` priority the run asks for its agents in realtime mode (`--rt-priority`; 0:
    /// normal policy); a daemon grants at most its own `--max-rt-priority`.
    pub rt_priority: u32,
    /// Outside observer slots of every service (the run's, plus one for the bridge).
    pub observers: usize,
    /// The orchestrator's identity (checked again).
    pub identity: Identity,
    /// Every host's `CLOCK_MONOTONIC` minus the launcher's, ns (estimated at the handshake,
    /// [`crate::clock`]); the bridges translate send stamps with them.
    pub clock_offsets_ns: BTreeMap<String, i64>,
    /// `Some`: the daemon shares the orchestrator's `/dev/shm`; the run's services exist already
    /// and are not bridged ([`crate::colocate`]).
    #[serde(default)]
    pub colocated: Option<Box<Colocated>>,
}

/// What an orchestrator asks a daemon.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
// One request per message, built and matched once: `Prepare`'s size costs nothing worth a box.
#[allow(clippy::large_enum_variant)]
pub enum Request {
    /// Prepare a run: services, bridge; start nothing yet.
    Prepare(RunRequest),
    /// Start agent processes of a prepared run. `rejoin`: the rejoin file (after the JSON, see
    /// [`frame`]) and the step a new process takes over at.
    Spawn {
        /// Run id.
        run_id: String,
        /// 0-based agent.
        agent: usize,
        /// `Some(step)`: a new process taking over, whose rejoin file follows the JSON.
        rejoin_at: Option<u64>,
    },
    /// SIGKILL (and reap) an agent's process.
    Kill {
        /// Run id.
        run_id: String,
        /// 0-based agent.
        agent: usize,
    },
    /// Send a signal to an agent's process (SIGSTOP for a timeline hang).
    Signal {
        /// Run id.
        run_id: String,
        /// 0-based agent.
        agent: usize,
        /// Signal number: only SIGSTOP and SIGCONT are accepted.
        signal: i32,
    },
    /// Whether the agent's process is stopped (SIGSTOP, a debugger: state `T` or `t` in its
    /// `/proc/<pid>/stat`): the reply carries one byte, 1 if it is, 0 if not.
    Stopped {
        /// Run id.
        run_id: String,
        /// 0-based agent.
        agent: usize,
    },
    /// The agent's latest checkpoint file (the reply carries its bytes).
    Checkpoint {
        /// Run id.
        run_id: String,
        /// 0-based agent.
        agent: usize,
    },
    /// A host of the run was lost and its agents moved: the new host of every agent (the
    /// daemon re-plans its bridge; it starts and stops nothing).
    Replan {
        /// Run id.
        run_id: String,
        /// Host of every agent (index = 0-based agent).
        agent_hosts: Vec<String>,
    },
    /// What the run measured on this host, once its processes have stopped: its agents' timing
    /// files and its bridge's link delays (the reply carries a JSON [`HostReport`]).
    Report {
        /// Run id.
        run_id: String,
    },
    /// End the run: stop its processes, remove its files.
    End {
        /// Run id.
        run_id: String,
    },
}

impl Request {
    /// The run a request is about; `None` for `Prepare`, which creates it (and carries its
    /// secret instead of proof of it).
    pub fn run_id(&self) -> Option<&str> {
        match self {
            Request::Prepare(_) => None,
            Request::Spawn { run_id, .. }
            | Request::Kill { run_id, .. }
            | Request::Signal { run_id, .. }
            | Request::Stopped { run_id, .. }
            | Request::Checkpoint { run_id, .. }
            | Request::Replan { run_id, .. }
            | Request::Report { run_id }
            | Request::End { run_id } => Some(run_id),
        }
    }
}

/// A daemon's answer.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum Reply {
    /// Done; a process id where one was started.
    Ok {
        /// The new process's pid (on that host).
        pid: Option<u32>,
    },
    /// Refused, nothing changed; why.
    Refused(String),
}

/// What a run measured on one host: its timing files by name (`agent-4.json`, `bridge-b.json`),
/// in the format of `formation_config::node::timing::TimingReport`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct HostReport {
    /// File name -> contents.
    pub timing: BTreeMap<String, String>,
}

/// A process of a run that exited on a daemon's host.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ExitReport {
    /// Host name.
    pub host: String,
    /// 0-based agent.
    pub agent: usize,
    /// Its pid there.
    pub pid: u32,
    /// `exited with code 0`, `was killed (SIGKILL)`, ...
    pub how: String,
}

/// A checkpoint file an agent wrote on a daemon's host, forwarded to the orchestrator as it is
/// written (the file follows the JSON, see [`frame`]), so a warm takeover does not need that host.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CheckpointNote {
    /// Host name.
    pub host: String,
    /// 0-based agent.
    pub agent: usize,
    /// The step it was taken before (read from its header by the daemon).
    pub step: u64,
}

/// JSON followed by raw bytes: `[u32 LE json length][json][bytes]`.
pub fn frame<T: Serialize>(msg: &T, bytes: &[u8]) -> Vec<u8> {
    let json = serde_json::to_vec(msg).expect("protocol messages serialise");
    let mut v = Vec::with_capacity(4 + json.len() + bytes.len());
    v.extend_from_slice(&(json.len() as u32).to_le_bytes());
    v.extend_from_slice(&json);
    v.extend_from_slice(bytes);
    v
}

/// Why bytes are not a [`frame`].
#[derive(Debug, thiserror::Error)]
pub enum FrameError {
    /// Shorter than the length prefix.
    #[error("malformed message: {0} bytes")]
    Short(usize),
    /// A length prefix beyond the bytes.
    #[error("malformed message: length {len} beyond {have} bytes")]
    Length {
        /// The JSON length announced.
        len: usize,
        /// The bytes present.
        have: usize,
    },
    /// The JSON is not the expected message.
    #[error("malformed message: {0}")]
    Json(#[from] serde_json::Error),
}

/// Splits a [`frame`]; a clear error for anything else.
pub fn decode_frame<T: for<'de> Deserialize<'de>>(data: &[u8]) -> Result<(T, &[u8]), FrameError> {
    if data.len() < 4 {
        return Err(FrameError::Short(data.len()));
    }
    let n = u32::from_le_bytes(data[..4].try_into().unwrap()) as usize;
    let json = data.get(4..4 + n).ok_or(FrameError::Length {
        len: n,
        have: data.len(),
    })?;
    Ok((serde_json::from_slice(json)?, &data[4 + n..]))
}

/// Wall clock, µs since the Unix epoch.
pub fn now_us() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_micros() as u64)
        .unwrap_or(0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_framed_request_round_trips_with_its_bytes_and_garbage_is_an_error() {
        let r = Request::Spawn {
            run_id: "ab12".into(),
            agent: 3,
            rejoin_at: Some(20_500),
        };
        let f = frame(&r, &[1, 2, 3]);
        let (back, rest): (Request, &[u8]) = decode_frame(&f).unwrap();
        assert_eq!(back, r);
        assert_eq!(rest, &[1, 2, 3]);
        assert!(decode_frame::<Request>(&[9, 0, 0, 0, b'{']).is_err());
        assert!(decode_frame::<Request>(&[1]).is_err());
        assert!(decode_frame::<Request>(&frame(&"x", &[])).is_err());
    }

    #[test]
    fn host_names_are_key_safe() {
        assert!(valid_name("b"));
        assert!(valid_name("host-2_x"));
        assert!(!valid_name(""));
        assert!(!valid_name("a/b"));
        assert!(!valid_name("*"));
        assert!(!valid_name(&"x".repeat(33)));
    }
}
