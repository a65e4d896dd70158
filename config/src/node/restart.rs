//! The files behind a warm restart (`docs/failures.md`), in the run's `DIR/checkpoints/` folder
//! (owner-only, like every file of the run): each agent process writes its latest checkpoint
//! there (`agent-<id>.ckpt`, written to a temporary name and renamed, so a process killed mid-write
//! leaves the previous one whole); before starting a new agent process the orchestrator writes what
//! it must rebuild from (`agent-<id>.rejoin`: the recorded states and commands of the window, and
//! the runtime events so far). Ids in file names are 1-based. Both are bincode (serde).

use crate::protocol::messages::RuntimeEvent;
use crate::protocol::wire::VehicleState;
use serde::{Deserialize, Serialize};
use std::io::{self, Write};
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
        use std::os::unix::fs::DirBuilderExt;
        std::fs::DirBuilder::new()
            .recursive(true)
            .mode(0o700)
            .create(parent)?;
    }
    let tmp = path.with_extension(format!("tmp{}", std::process::id()));
    let _ = std::fs::remove_file(&tmp);
    let mut f = super::files::create_new(&tmp, 0o600)?;
    f.write_all(&bytes)?;
    drop(f);
    std::fs::rename(&tmp, path)
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
    fn a_checkpoint_round_trips_and_a_planted_link_is_not_followed() {
        let dir = std::env::temp_dir().join(format!("fm-ckpt-test-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let path = dir.join("agent-1.ckpt");
        let c = Checkpoint {
            step: 1000,
            state: vec![1, 2, 3],
        };
        write_atomic(&path, &c).unwrap();
        assert_eq!(read::<Checkpoint>(&path).unwrap(), c);
        let link = dir.join("agent-2.ckpt");
        std::os::unix::fs::symlink(&path, &link).unwrap();
        assert!(
            read::<Checkpoint>(&link).is_err(),
            "reading through a link is refused"
        );
        let _ = std::fs::remove_dir_all(&dir);
    }
}
