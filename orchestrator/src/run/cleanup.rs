//! Removing what a run leaves under its iceoryx2 prefix (after every process of the run has exited).

use formation_config::ipc;

/// Deletes the run's files in /dev/shm and /tmp/iceoryx2; errors name what is left.
pub fn remove(prefix: &str) -> Result<(), String> {
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
