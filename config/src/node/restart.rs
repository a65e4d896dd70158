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
/// Bytes before the state: magic, version, agent id, scenario hash, step, state length.
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

/// The bytes of agent i's checkpoint `c` in a run whose scenario hashes to `scenario`.
pub fn encode_checkpoint(agent: usize, scenario: u64, c: &Checkpoint) -> Vec<u8> {
    let mut out = Vec::with_capacity(HEADER_LEN + c.state.len() + 8);
    out.extend_from_slice(&CHECKPOINT_MAGIC);
    out.extend_from_slice(&CHECKPOINT_VERSION.to_le_bytes());
    out.extend_from_slice(&((agent + 1) as u32).to_le_bytes());
    out.extend_from_slice(&scenario.to_le_bytes());
    out.extend_from_slice(&c.step.to_le_bytes());
    out.extend_from_slice(&(c.state.len() as u64).to_le_bytes());
    out.extend_from_slice(&c.state);
    let sum = fnv1a(&out);
    out.extend_from_slice(&sum.to_le_bytes());
    out
}

/// The checkpoint in `bytes` if it is agent i's of the run whose scenario hashes to `scenario`;
/// otherwise what failed.
pub fn decode_checkpoint(bytes: &[u8], agent: usize, scenario: u64) -> Result<Checkpoint, String> {
    let u32_at = |o: usize| u32::from_le_bytes(bytes[o..o + 4].try_into().expect("4 bytes"));
    let u64_at = |o: usize| u64::from_le_bytes(bytes[o..o + 8].try_into().expect("8 bytes"));
    if bytes.len() < HEADER_LEN + 8 {
        return Err(format!("truncated ({} bytes)", bytes.len()));
    }
    if bytes[..8] != CHECKPOINT_MAGIC {
        return Err("not a checkpoint (wrong magic number)".into());
    }
    let version = u32_at(8);
    if version != CHECKPOINT_VERSION {
        return Err(format!(
            "format version {version}, this build reads {CHECKPOINT_VERSION}"
        ));
    }
    let len = u64_at(32);
    if len != (bytes.len() - HEADER_LEN - 8) as u64 {
        return Err(format!(
            "truncated or padded: {len} state bytes announced, {} present",
            bytes.len() - HEADER_LEN - 8
        ));
    }
    let body = bytes.len() - 8;
    if fnv1a(&bytes[..body]) != u64_at(body) {
        return Err("checksum mismatch (the file was altered or damaged)".into());
    }
    let id = u32_at(12) as usize;
    if id != agent + 1 {
        return Err(format!(
            "it is agent {id}'s checkpoint, not agent {}'s",
            agent + 1
        ));
    }
    if u64_at(16) != scenario {
        return Err(
            "it belongs to another scenario (its scenario hash differs from this run's)".into(),
        );
    }
    Ok(Checkpoint {
        step: u64_at(24),
        state: bytes[HEADER_LEN..body].to_vec(),
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
pub fn read_checkpoint(path: &Path, agent: usize, scenario: u64) -> Result<Checkpoint, String> {
    use std::io::Read;
    use std::os::unix::fs::OpenOptionsExt;
    let mut bytes = Vec::new();
    std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NOFOLLOW | libc::O_NONBLOCK)
        .open(path)
        .and_then(|mut f| f.read_to_end(&mut bytes))
        .map_err(|e| format!("checkpoint {}: {e}", path.display()))?;
    decode_checkpoint(&bytes, agent, scenario)
        .map_err(|why| format!("checkpoint {} refused: {why}", path.display()))
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
    #[serde(default)]
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

fn encode<T: Serialize>(v: &T) -> io::Result<Vec<u8>> {
    bincode::serde::encode_to_vec(v, bincode::config::standard()).map_err(io::Error::other)
}

fn decode<T: for<'de> Deserialize<'de>>(bytes: &[u8], path: &Path) -> io::Result<T> {
    bincode::serde::decode_from_slice(bytes, bincode::config::standard())
        .map(|(v, _)| v)
        .map_err(|e| {
            io::Error::new(
                io::ErrorKind::InvalidData,
                format!("{}: {e}", path.display()),
            )
        })
}

/// Writes `value` to `path` atomically: a new owner-only temporary file (never through a symbolic
/// link), then a rename over `path`. The folder is created owner-only if missing.
pub fn write_atomic<T: Serialize>(path: &Path, value: &T) -> io::Result<()> {
    let bytes = encode(value)?;
    if let Some(parent) = path.parent() {
        super::files::ensure_private_dir(parent)?;
    }
    super::files::write_atomic(path, &bytes)
}

/// Reads a file [`write_atomic`] wrote.
pub fn read<T: for<'de> Deserialize<'de>>(path: &Path) -> io::Result<T> {
    use std::io::Read;
    use std::os::unix::fs::OpenOptionsExt;
    let mut f = std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NOFOLLOW)
        .open(path)?;
    let mut bytes = Vec::new();
    f.read_to_end(&mut bytes)?;
    decode(&bytes, path)
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
        let why = |b: &[u8], agent, hash| decode_checkpoint(b, agent, hash).unwrap_err();
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
}
