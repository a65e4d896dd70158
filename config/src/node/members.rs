//! Who is still in a run, for the cleanup of its iceoryx2 files when the orchestrator is gone.
//!
//! Every process of a run holds a shared `flock` on `<run dir>/iox2/members.lock` while it may have
//! files of the run's prefix open: the orchestrator from before it starts the role processes until
//! it has removed the run's files itself, each role process from before it creates its node until
//! the node is dropped. A role process that leaves releases its lock and then tries to take it
//! exclusively: only the last process of the run can, and only when the orchestrator is gone (it
//! holds its shared lock until its own cleanup). That process removes every file of the run's
//! prefix from /dev/shm and /tmp/iceoryx2 ([`crate::node::ipc::remove_residue`]), so a SIGKILLed
//! orchestrator leaves nothing behind.

use super::error::NodeError;
use super::files::{self, Lock};
use std::fs::File;
use std::path::{Path, PathBuf};

/// The lock file of the run in `run_dir`.
pub fn lock_path(run_dir: &Path) -> PathBuf {
    run_dir.join("iox2").join("members.lock")
}

/// A process's membership of a run (see the module documentation).
#[derive(Debug)]
pub struct Membership {
    file: File,
    prefix: String,
}

impl Membership {
    /// Creates the lock file (orchestrator, before any role process starts) and joins.
    pub fn create(run_dir: &Path, prefix: &str) -> Result<Membership, NodeError> {
        let path = lock_path(run_dir);
        if let Some(dir) = path.parent() {
            files::ensure_private_dir(dir)
                .map_err(|e| file_error(dir, "cannot create", std::io::Error::from(e)))?;
        }
        Membership::open(&path, prefix, true)
    }

    /// Joins the run whose lock file the orchestrator created (role processes).
    pub fn join(run_dir: &Path, prefix: &str) -> Result<Membership, NodeError> {
        Membership::open(&lock_path(run_dir), prefix, false)
    }

    /// Joins the run of the lock file `lock` (an agent started by a daemon that shares the
    /// orchestrator's `/dev/shm` joins the orchestrator's run this way).
    pub fn join_file(lock: &Path, prefix: &str) -> Result<Membership, NodeError> {
        Membership::open(lock, prefix, false)
    }

    fn open(path: &Path, prefix: &str, create: bool) -> Result<Membership, NodeError> {
        let file =
            files::open_lock_file(path, create).map_err(|e| file_error(path, "cannot open", e))?;
        files::lock(&file, Lock::Shared).map_err(|e| file_error(path, "cannot lock", e))?;
        Ok(Membership {
            file,
            prefix: prefix.to_string(),
        })
    }

    /// Leaves the run; the last process to leave removes the run's iceoryx2 files and returns how
    /// many it removed (`None`: another process of the run is still in it).
    pub fn leave_last(self) -> Option<std::io::Result<usize>> {
        files::unlock(&self.file);
        match files::try_lock(&self.file, Lock::Exclusive) {
            Ok(true) => Some(crate::node::ipc::remove_residue(&self.prefix)),
            _ => None,
        }
    }
}

fn file_error(path: &Path, what: &str, e: std::io::Error) -> NodeError {
    NodeError::File {
        path: path.to_path_buf(),
        detail: format!("{what}: {e}"),
    }
}

/// Leaves on drop (role processes), after the node: see [`Membership::leave_last`].
#[derive(Debug)]
pub struct LeaveOnDrop(pub Option<Membership>);

impl Drop for LeaveOnDrop {
    fn drop(&mut self) {
        if let Some(m) = self.0.take() {
            if let Some(result) = m.leave_last() {
                match result {
                    Ok(n) => tracing::info!(
                        files = n,
                        "last process of a run whose orchestrator is gone: its iceoryx2 files removed"
                    ),
                    Err(e) => tracing::warn!("cannot remove the run's iceoryx2 files: {e}"),
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_the_last_member_to_leave_cleans_up_and_never_while_the_orchestrator_is_in() {
        let dir = std::env::temp_dir().join(format!("fm-members-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let prefix = format!("fmm{}_", std::process::id());
        let orchestrator = Membership::create(&dir, &prefix).unwrap();
        let a = Membership::join(&dir, &prefix).unwrap();
        let b = Membership::join(&dir, &prefix).unwrap();
        // The orchestrator is in: nobody else cleans up.
        assert!(a.leave_last().is_none());
        drop(orchestrator);
        let c = Membership::join(&dir, &prefix).unwrap();
        assert!(b.leave_last().is_none(), "c is still in");
        assert!(c.leave_last().is_some(), "c is the last one");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
