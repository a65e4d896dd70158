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

/// Deletes the run's files in /dev/shm and /tmp/iceoryx2, once no outside node is attached any
/// more (waiting up to `grace`); errors name what is left.
pub fn remove(prefix: &str, grace: Duration) -> Result<Cleaned, String> {
    let start = Instant::now();
    loop {
        let outside = ipc::alive_nodes(prefix).map_err(|e| e.to_string())?;
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
fn remove_all(prefix: &str) -> Result<(), String> {
    ipc::remove_residue(prefix).map_err(|e| format!("cannot remove the files of {prefix}: {e}"))?;
    match ipc::residue(prefix) {
        Ok(left) if left.is_empty() => Ok(()),
        Ok(left) => Err(format!(
            "files of run prefix {prefix} are left behind: {}",
            left.iter()
                .map(|p| p.display().to_string())
                .collect::<Vec<_>>()
                .join(", ")
        )),
        Err(e) => Err(format!("cannot list the files of {prefix}: {e}")),
    }
}

/// Writes `<run dir>/iox2/config/iceoryx2.toml`: the iceoryx2 config of the run (its prefix), so that
/// `cd <run dir>/iox2 && iox2 service list` (iceoryx2 looks for `./config/iceoryx2.toml`) shows the
/// run's nodes and services while it is running.
pub fn write_iox2_config(run_dir: &std::path::Path, prefix: &str) -> Result<(), String> {
    let cfg = ipc::config_for_prefix(prefix).map_err(|e| e.to_string())?;
    let text =
        toml::to_string(&cfg).map_err(|e| format!("cannot serialise the iceoryx2 config: {e}"))?;
    let dir = run_dir.join("iox2").join("config");
    formation_config::node::files::ensure_private_dir(&run_dir.join("iox2"))
        .and_then(|()| formation_config::node::files::ensure_private_dir(&dir))
        .map_err(std::io::Error::from)
        .and_then(|()| {
            formation_config::node::files::write_atomic(&dir.join("iceoryx2.toml"), text.as_bytes())
        })
        .map_err(|e| format!("cannot write {}: {e}", dir.display()))
}
