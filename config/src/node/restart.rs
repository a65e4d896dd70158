//! The files behind a warm restart (`docs/failures.md`), in the run's `DIR/checkpoints/` folder
//! (owner-only, like every file of the run): each agent process writes its latest checkpoint
//! there (`agent-<id>.ckpt`, written to a temporary name and renamed, so a process killed mid-write
//! leaves the previous one whole); before starting a new agent process the orchestrator writes what
//! it must rebuild from (`agent-<id>.rejoin`: the recorded states and commands of the window, and
//! the runtime events so far). Ids in file names are 1-based. Both are bincode (serde).
//!
//! A checkpoint file says what it is before anything trusts it ([`write_checkpoint`]): a magic
//! number, a format version, the agent id, the hash of the run's `scenario.toml` and the step,
//! then the state, then an FNV-1a 64 checksum of everything before it. A file that fails any of
//! these (bit flips, another agent's or another run's file, truncated) is refused, naming the
//! file and what failed, and the restart falls back to cold at once ([`read_checkpoint`]).

use crate::protocol::messages::RuntimeEvent;
use crate::protocol::wire::VehicleState;
use serde::{Deserialize, Serialize};
use std::io;
use std::path::{Path, PathBuf};

/// The folder of a run's checkpoints.
pub fn dir(run_dir: &Path) -> PathBuf {
    run_dir.join("checkpoints")
}

/// Agent i's checkpoint file (0-based index, 1-based in the name).
pub fn checkpoint_path(run_dir: &Path, agent: usize) -> PathBuf {
    dir(run_dir).join(format!("agent-{}.ckpt", agent + 1))
}

/// Agent i's rejoin file.
pub fn rejoin_path(run_dir: &Path, agent: usize) -> PathBuf {
    dir(run_dir).join(format!("agent-{}.rejoin", agent + 1))
}

/// A checkpoint: the controller state taken before the control of `step`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Checkpoint {
    /// The step whose control had not run yet.
    pub step: u64,
    /// `formation_agent::Agent::checkpoint`.
    pub state: Vec<u8>,
}

/// The first bytes of every checkpoint file.
pub const CHECKPOINT_MAGIC: [u8; 8] = *b"FMCKPT\r\n";
/// The checkpoint file format [`write_checkpoint`] writes.
pub const CHECKPOINT_VERSION: u32 = 2;
/// Bytes before the body of a checkpoint or rejoin file: magic, version, agent id, scenario hash,
/// step, body length.
const HEADER_LEN: usize = 8 + 4 + 4 + 8 + 8 + 8;

/// FNV-1a 64 of `bytes`.
fn fnv1a(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |h, &b| {
        (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3)
    })
}

/// The hash of a run's `scenario.toml` text that its checkpoints carry.
pub fn scenario_hash(scenario_toml: &[u8]) -> u64 {
    fnv1a(scenario_toml)
}

/// Bytes of a framed file: `magic`, `version`, agent id (1-based), scenario hash, `step`, body
/// length, body, then an FNV-1a 64 checksum of everything before it.
fn encode_framed(
    magic: &[u8; 8],
    version: u32,
    agent: usize,
    scenario: u64,
    step: u64,
    body: &[u8],
) -> Vec<u8> {
    let mut out = Vec::with_capacity(HEADER_LEN + body.len() + 8);
    out.extend_from_slice(magic);
    out.extend_from_slice(&version.to_le_bytes());
    out.extend_from_slice(&((agent + 1) as u32).to_le_bytes());
    out.extend_from_slice(&scenario.to_le_bytes());
    out.extend_from_slice(&step.to_le_bytes());
    out.extend_from_slice(&(body.len() as u64).to_le_bytes());
    out.extend_from_slice(body);
    let sum = fnv1a(&out);
    out.extend_from_slice(&sum.to_le_bytes());
    out
}

/// Why the bytes of a checkpoint or rejoin file (`what`) were refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum Refusal {
    /// Shorter than a header and a checksum.
    #[error("truncated ({len} bytes)")]
    Truncated {
        /// Bytes present.
        len: usize,
    },
    /// The first eight bytes are not this kind of file's magic number.
    #[error("not a {what} (wrong magic number)")]
    Magic {
        /// `checkpoint` or `rejoin file`.
        what: &'static str,
    },
    /// Another format version.
    #[error("format version {found}, this build reads {reads}")]
    Version {
        /// The file's version.
        found: u32,
        /// The version this build reads.
        reads: u32,
    },
    /// The body length announced is not the body present.
    #[error("truncated or padded: {announced} body bytes announced, {present} present")]
    Length {
        /// Body bytes the header announces.
        announced: u64,
        /// Body bytes present.
        present: usize,
    },
    /// The checksum does not match.
    #[error("checksum mismatch (the file was altered or damaged)")]
    Checksum,
    /// Another agent's file.
    #[error("it is agent {found}'s {what}, not agent {want}'s")]
    Agent {
        /// `checkpoint` or `rejoin file`.
        what: &'static str,
        /// The file's agent id (1-based).
        found: usize,
        /// The agent id expected (1-based).
        want: usize,
    },
    /// Another run's file.
    #[error("it belongs to another scenario (its scenario hash differs from this run's)")]
    Scenario,
    /// A rejoin file for another step.
    #[error("it rejoins at step {step}, not at {rejoin_at}")]
    Step {
        /// The step the file rejoins at.
        step: u64,
        /// The step expected.
        rejoin_at: u64,
    },
    /// The body is not bincode of the expected type.
    #[error("its body does not decode: {0}")]
    Body(String),
    /// A rejoin file whose window does not hold what it announces.
    #[error("its window is inconsistent (agent, steps, states, commands or flown)")]
    Inconsistent,
}

/// A checkpoint or rejoin file that could not be read or was refused: which file and why.
#[derive(Debug, thiserror::Error)]
pub enum ReadError {
    /// The file could not be opened or read.
    #[error("{what} {}: {source}", path.display())]
    Io {
        /// `checkpoint` or `rejoin file`.
        what: &'static str,
        /// The file.
        path: PathBuf,
        /// What the system said.
        source: io::Error,
    },
    /// The file was read and refused.
    #[error("{what} {} refused: {why}", path.display())]
    Refused {
        /// `checkpoint` or `rejoin file`.
        what: &'static str,
        /// The file.
        path: PathBuf,
        /// What failed.
        why: Refusal,
    },
}

/// The `(step, body)` of a framed file if it is a `what` of agent i of the run whose scenario
/// hashes to `scenario`; otherwise what failed.
fn decode_framed<'a>(
    bytes: &'a [u8],
    (what, magic, version): (&'static str, &[u8; 8], u32),
    agent: usize,
    scenario: u64,
) -> Result<(u64, &'a [u8]), Refusal> {
    let u32_at = |o: usize| u32::from_le_bytes(bytes[o..o + 4].try_into().expect("4 bytes"));
    let u64_at = |o: usize| u64::from_le_bytes(bytes[o..o + 8].try_into().expect("8 bytes"));
    if bytes.len() < HEADER_LEN + 8 {
        return Err(Refusal::Truncated { len: bytes.len() });
    }
    if bytes[..8] != *magic {
        return Err(Refusal::Magic { what });
    }
    let found = u32_at(8);
    if found != version {
        return Err(Refusal::Version {
            found,
            reads: version,
        });
    }
    let len = u64_at(32);
    if len != (bytes.len() - HEADER_LEN - 8) as u64 {
        return Err(Refusal::Length {
            announced: len,
            present: bytes.len() - HEADER_LEN - 8,
        });
    }
    let body = bytes.len() - 8;
    if fnv1a(&bytes[..body]) != u64_at(body) {
        return Err(Refusal::Checksum);
    }
    let id = u32_at(12) as usize;
    if id != agent + 1 {
        return Err(Refusal::Agent {
            what,
            found: id,
            want: agent + 1,
        });
    }
    if u64_at(16) != scenario {
        return Err(Refusal::Scenario);
    }
    Ok((u64_at(24), &bytes[HEADER_LEN..body]))
}

/// The bytes of the file at `path` (a `what`), read without following a symbolic link at its name
/// nor blocking on a FIFO.
fn read_nofollow(what: &'static str, path: &Path) -> Result<Vec<u8>, ReadError> {
    use std::io::Read;
    use std::os::unix::fs::OpenOptionsExt;
    let mut bytes = Vec::new();
    std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NOFOLLOW | libc::O_NONBLOCK)
        .open(path)
        .and_then(|mut f| f.read_to_end(&mut bytes))
        .map_err(|source| ReadError::Io {
            what,
            path: path.to_path_buf(),
            source,
        })?;
    Ok(bytes)
}

/// The bytes of agent i's checkpoint `c` in a run whose scenario hashes to `scenario`.
pub fn encode_checkpoint(agent: usize, scenario: u64, c: &Checkpoint) -> Vec<u8> {
    encode_framed(
        &CHECKPOINT_MAGIC,
        CHECKPOINT_VERSION,
        agent,
        scenario,
        c.step,
        &c.state,
    )
}

/// The checkpoint in `bytes` if it is agent i's of the run whose scenario hashes to `scenario`;
/// otherwise what failed.
pub fn decode_checkpoint(bytes: &[u8], agent: usize, scenario: u64) -> Result<Checkpoint, Refusal> {
    let (step, state) = decode_framed(
        bytes,
        ("checkpoint", &CHECKPOINT_MAGIC, CHECKPOINT_VERSION),
        agent,
        scenario,
    )?;
    Ok(Checkpoint {
        step,
        state: state.to_vec(),
    })
}

/// Writes agent i's checkpoint (see the module documentation) atomically, owner-only.
pub fn write_checkpoint(
    path: &Path,
    agent: usize,
    scenario: u64,
    c: &Checkpoint,
) -> io::Result<()> {
    if let Some(parent) = path.parent() {
        super::files::ensure_private_dir(parent)?;
    }
    super::files::write_atomic(path, &encode_checkpoint(agent, scenario, c))
}

/// Reads agent i's checkpoint, refusing (with the file named and why) one that is not agent i's
/// of this run, damaged, or of another format.
pub fn read_checkpoint(path: &Path, agent: usize, scenario: u64) -> Result<Checkpoint, ReadError> {
    const WHAT: &str = "checkpoint";
    let bytes = read_nofollow(WHAT, path)?;
    decode_checkpoint(&bytes, agent, scenario).map_err(|why| ReadError::Refused {
        what: WHAT,
        path: path.to_path_buf(),
        why,
    })
}

/// What a new agent process rebuilds from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RejoinFile {
    /// Agent index (0-based).
    pub agent: usize,
    /// Restore this checkpoint step (warm) or none (cold).
    pub checkpoint: Option<u64>,
    /// First step the old process did not compute.
    pub down_from: u64,
    /// First step the new process computes.
    pub rejoin_at: u64,
    /// Step of `states[0]`.
    pub first: u64,
    /// Agents N (states are step-major: `states[(k - first) * n + j]`).
    pub n: usize,
    /// Recorded states of every quadrotor for steps [first, rejoin_at).
    pub states: Vec<VehicleState>,
    /// The agent's recorded (thrust, torque) for steps [first, down_from).
    pub commands: Vec<(f64, [f64; 3])>,
    /// Every runtime event published so far, in order (the new process's timeline).
    pub events: Vec<RuntimeEvent>,
    /// The (thrust, torque) quadrotor `agent` was flown with while its controller was down, steps
    /// [down_from, rejoin_at): its last command held, then the failsafe's (docs/failures.md). With
    /// `states`, what the returning controller reads the failsafe's observed disturbance from
    /// (`runtime.rejoin_reseed`).
    pub flown: Vec<(f64, [f64; 3])>,
}

impl RejoinFile {
    /// The state of quadrotor j at step k (within the window).
    pub fn state(&self, k: u64, j: usize) -> VehicleState {
        self.states[(k - self.first) as usize * self.n + j]
    }

    /// The agent's recorded command at step k (within [first, down_from)).
    pub fn command(&self, k: u64) -> (f64, [f64; 3]) {
        self.commands[(k - self.first) as usize]
    }

    /// What quadrotor `agent` was flown with at step k: its controller's recorded command before
    /// `down_from`, the held or failsafe command from then to `rejoin_at`.
    pub fn flown_command(&self, k: u64) -> (f64, [f64; 3]) {
        if k < self.down_from {
            self.command(k)
        } else {
            self.flown[(k - self.down_from) as usize]
        }
    }
}

/// The first bytes of every rejoin file.
pub const REJOIN_MAGIC: [u8; 8] = *b"FMREJN\r\n";
/// The rejoin file format [`encode_rejoin`] writes.
pub const REJOIN_VERSION: u32 = 1;

/// The bytes of a rejoin file: framed like a checkpoint (magic, version, agent, the run's scenario
/// hash, the step it rejoins at, checksum) around the bincode of `file`.
pub fn encode_rejoin(scenario: u64, file: &RejoinFile) -> io::Result<Vec<u8>> {
    Ok(encode_framed(
        &REJOIN_MAGIC,
        REJOIN_VERSION,
        file.agent,
        scenario,
        file.rejoin_at,
        &encode(file)?,
    ))
}

/// The rejoin file in `bytes` if it is agent i's of the run whose scenario hashes to `scenario`,
/// rejoining at `rejoin_at`, whole and self-consistent (its window holds every state and command
/// it announces); otherwise what failed. A file that arrives from elsewhere (a daemon's `Spawn`)
/// is checked with this before it is written or any process reads it.
pub fn decode_rejoin(
    bytes: &[u8],
    agent: usize,
    scenario: u64,
    rejoin_at: u64,
) -> Result<RejoinFile, Refusal> {
    let (step, body) = decode_framed(
        bytes,
        ("rejoin file", &REJOIN_MAGIC, REJOIN_VERSION),
        agent,
        scenario,
    )?;
    if step != rejoin_at {
        return Err(Refusal::Step { step, rejoin_at });
    }
    let f: RejoinFile = bincode::serde::decode_from_slice(body, bincode::config::standard())
        .map(|(v, _)| v)
        .map_err(|e| Refusal::Body(e.to_string()))?;
    let window = f.rejoin_at.checked_sub(f.first);
    let consistent = f.agent == agent
        && f.rejoin_at == rejoin_at
        && f.down_from <= f.rejoin_at
        && window.is_some_and(|w| Some(f.states.len()) == (w as usize).checked_mul(f.n))
        && f.commands.len() as u64 == f.down_from.saturating_sub(f.first)
        && f.flown.len() as u64 == f.rejoin_at - f.down_from
        && f.checkpoint.is_none_or(|c| c < f.rejoin_at);
    if !consistent {
        return Err(Refusal::Inconsistent);
    }
    Ok(f)
}

/// Writes agent i's rejoin file atomically, owner-only.
pub fn write_rejoin(path: &Path, scenario: u64, file: &RejoinFile) -> io::Result<()> {
    if let Some(parent) = path.parent() {
        super::files::ensure_private_dir(parent)?;
    }
    super::files::write_atomic(path, &encode_rejoin(scenario, file)?)
}

/// Reads agent i's rejoin file for step `rejoin_at`, refusing (with the file named and why) one
/// that fails [`decode_rejoin`].
pub fn read_rejoin(
    path: &Path,
    agent: usize,
    scenario: u64,
    rejoin_at: u64,
) -> Result<RejoinFile, ReadError> {
    const WHAT: &str = "rejoin file";
    let bytes = read_nofollow(WHAT, path)?;
    decode_rejoin(&bytes, agent, scenario, rejoin_at).map_err(|why| ReadError::Refused {
        what: WHAT,
        path: path.to_path_buf(),
        why,
    })
}

fn encode<T: Serialize>(v: &T) -> io::Result<Vec<u8>> {
    bincode::serde::encode_to_vec(v, bincode::config::standard()).map_err(io::Error::other)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_checkpoint_that_is_damaged_another_agents_or_another_runs_is_refused_naming_why() {
        let c = Checkpoint {
            step: 108,
            state: (0..200u8).collect(),
        };
        let good = encode_checkpoint(2, 77, &c);
        assert_eq!(decode_checkpoint(&good, 2, 77).unwrap(), c);
        let why =
            |b: &[u8], agent, hash| decode_checkpoint(b, agent, hash).unwrap_err().to_string();
        assert!(why(&good, 1, 77).contains("agent 3's"), "another agent's");
        assert!(why(&good, 2, 78).contains("scenario"), "another run's");
        for bit in [8 * 9, 8 * 30, 8 * 100, 8 * (good.len() - 3)] {
            let mut b = good.clone();
            b[bit / 8] ^= 1 << (bit % 8);
            let e = why(&b, 2, 77);
            assert!(
                e.contains("checksum") || e.contains("version") || e.contains("truncated"),
                "bit {bit}: {e}"
            );
        }
        assert!(why(&good[..good.len() - 1], 2, 77).contains("truncated"));
        let random: Vec<u8> = (0..500u32)
            .map(|k| ((k * 2_654_435_761u32) >> 13) as u8)
            .collect();
        assert!(why(&random, 2, 77).contains("magic"));
        // The file of the old format (bare bincode) decodes as nothing.
        let old = encode(&c).unwrap();
        assert!(decode_checkpoint(&old, 2, 77).is_err());
    }

    #[test]
    fn a_checkpoint_round_trips_and_a_planted_link_is_not_followed() {
        let dir = std::env::temp_dir().join(format!("fm-ckpt-test-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let path = dir.join("agent-1.ckpt");
        let c = Checkpoint {
            step: 1000,
            state: vec![1, 2, 3],
        };
        write_checkpoint(&path, 0, 5, &c).unwrap();
        assert_eq!(read_checkpoint(&path, 0, 5).unwrap(), c);
        let link = dir.join("agent-2.ckpt");
        std::os::unix::fs::symlink(&path, &link).unwrap();
        assert!(
            read_checkpoint(&link, 0, 5).is_err(),
            "reading through a link is refused"
        );
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_rejoin_file_that_is_damaged_another_agents_or_inconsistent_is_refused_before_use() {
        let f = RejoinFile {
            agent: 3,
            checkpoint: Some(90),
            down_from: 100,
            rejoin_at: 102,
            first: 98,
            n: 2,
            states: vec![VehicleState::default(); 8],
            commands: vec![(1.0, [0.0; 3]); 2],
            events: Vec::new(),
            flown: vec![(2.0, [0.0; 3]); 2],
        };
        let good = encode_rejoin(55, &f).unwrap();
        assert_eq!(decode_rejoin(&good, 3, 55, 102).unwrap(), f);
        let why =
            |b: &[u8], agent, hash, at| decode_rejoin(b, agent, hash, at).unwrap_err().to_string();
        assert!(
            why(&good, 2, 55, 102).contains("agent 4's"),
            "another agent's"
        );
        assert!(why(&good, 3, 56, 102).contains("scenario"), "another run's");
        assert!(
            why(&good, 3, 55, 101).contains("step 102"),
            "another step's"
        );
        let mut flipped = good.clone();
        flipped[HEADER_LEN + 3] ^= 0x10;
        assert!(why(&flipped, 3, 55, 102).contains("checksum"));
        assert!(why(&good[..good.len() - 2], 3, 55, 102).contains("truncated"));
        // A checkpoint is not a rejoin file.
        let c = encode_checkpoint(
            3,
            55,
            &Checkpoint {
                step: 102,
                state: vec![1; 40],
            },
        );
        assert!(why(&c, 3, 55, 102).contains("magic"));
        // Well framed, but the window does not hold what it announces.
        let short = RejoinFile {
            states: vec![VehicleState::default(); 7],
            ..f.clone()
        };
        let bad = encode_rejoin(55, &short).unwrap();
        assert!(why(&bad, 3, 55, 102).contains("inconsistent"));
        let inner = RejoinFile { agent: 2, ..f };
        let bad = encode_framed(
            &REJOIN_MAGIC,
            REJOIN_VERSION,
            3,
            55,
            102,
            &encode(&inner).unwrap(),
        );
        assert!(why(&bad, 3, 55, 102).contains("inconsistent"));
    }
}
