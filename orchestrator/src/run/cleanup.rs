//! Removing what a run leaves under its iceoryx2 prefix (after every process of the run has exited).

use formation_config::node::ipc;
use std::time::{Duration, Instant};

/// How long the clean-up waits for outside nodes (observers, `formation inspect`) to detach: they
/// see the stop on `formation/run/control`, published before the role processes exit.
pub const OUTSIDE_GRACE: Duration = Duration::from_secs(2);

/// Poll interval while waiting for outside nodes to detach.
const POLL: Duration = Duration::from_millis(20);

/// What the clean-up did.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Cleaned {
    /// Every file of the prefix is gone.
    All,
    /// Outside nodes were still attached after [`OUTSIDE_GRACE`]: their files and those of the
    /// services they hold are left to them (iceoryx2 removes a service with its last user, and
    /// the next `formation run` or `remove_residue` of the prefix the rest).
    LeftTo(Vec<ipc::AliveNode>),
}

/// Why the files of a run's prefix could not all be removed, or its iceoryx2 configuration
/// written; each names the prefix or file.
#[derive(Debug, thiserror::Error)]
pub enum CleanupError {
    /// The prefix's nodes cannot be listed, or its configuration made.
    #[error("{0}")]
    Ipc(#[from] ipc::IpcError),
    /// The prefix's files cannot be removed.
    #[error("cannot remove the files of {prefix}: {source}")]
    Remove {
        /// The run's prefix.
        prefix: String,
        /// The file system's error.
        source: std::io::Error,
    },
    /// Files of the prefix are still there after their removal (their paths).
    #[error(
        "files of run prefix {prefix} are left behind: {}",
        left.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(", ")
    )]
    LeftBehind {
        /// The run's prefix.
        prefix: String,
        /// The files left.
        left: Vec<std::path::PathBuf>,
    },
    /// The prefix's files cannot be listed.
    #[error("cannot list the files of {prefix}: {source}")]
    List {
        /// The run's prefix.
        prefix: String,
        /// The file system's error.
        source: std::io::Error,
    },
    /// The iceoryx2 configuration cannot be written as TOML.
    #[error("cannot serialise the iceoryx2 config: {0}")]
    Serialise(#[from] toml::ser::Error),
    /// The iceoryx2 configuration cannot be written into the run's folder.
    #[error("cannot write {}: {source}", dir.display())]
    Write {
        /// The folder.
        dir: std::path::PathBuf,
        /// The file system's error.
        source: std::io::Error,
    },
}

/// Deletes the run's files in /dev/shm and /tmp/iceoryx2, once no outside node is attached any
/// more (waiting up to `grace`); errors name what is left.
pub fn remove(prefix: &str, grace: Duration) -> Result<Cleaned, CleanupError> {
    let start = Instant::now();
    loop {
        let outside = ipc::alive_nodes(prefix)?;
        if outside.is_empty() {
            break;
        }
        if start.elapsed() >= grace {
            return Ok(Cleaned::LeftTo(outside));
        }
        std::thread::sleep(POLL);
    }
    remove_all(prefix).map(|()| Cleaned::All)
}

/// Deletes every file of the prefix.
fn remove_all(prefix: &str) -> Result<(), CleanupError> {
    ipc::remove_residue(prefix).map_err(|source| CleanupError::Remove {
        prefix: prefix.to_string(),
        source,
    })?;
    match ipc::residue(prefix) {
        Ok(left) if left.is_empty() => Ok(()),
        Ok(left) => Err(CleanupError::LeftBehind {
            prefix: prefix.to_string(),
            left,
        }),
        Err(source) => Err(CleanupError::List {
            prefix: prefix.to_string(),
            source,
        }),
    }
}

/// Writes `<run dir>/iox2/config/iceoryx2.toml`: the iceoryx2 config of the run (its prefix), so that
/// `cd <run dir>/iox2 && iox2 service list` (iceoryx2 looks for `./config/iceoryx2.toml`) shows the
/// run's nodes and services while it is running.
pub fn write_iox2_config(run_dir: &std::path::Path, prefix: &str) -> Result<(), CleanupError> {
    let cfg = ipc::config_for_prefix(prefix)?;
    let text = toml::to_string(&cfg)?;
    let dir = run_dir.join("iox2").join("config");
    formation_config::node::files::ensure_private_dir(&run_dir.join("iox2"))
        .and_then(|()| formation_config::node::files::ensure_private_dir(&dir))
        .map_err(std::io::Error::from)
        .and_then(|()| {
            formation_config::node::files::write_atomic(&dir.join("iceoryx2.toml"), text.as_bytes())
        })
        .map_err(|source| CleanupError::Write {
            dir: dir.clone(),
            source,
        })
}
