//! The output-folder lock: `formation run` and `formation sim` hold an advisory lock (`flock`) on
//! `DIR/.formation.lock` for as long as they write into `DIR`, so a second run into the same folder
//! is refused at once (exit 2) instead of mixing its rows into the first one's CSV. The file holds
//! who has it (pid, run id, command); it is created with mode 0600 without following a symbolic
//! link, and removed by its holder at the end.
//!
//! The folder itself must be this user's alone ([`files::ensure_private_dir`]): created with mode
//! 0700 (and each parent created on the way), or refused (exit 2, naming it) when it is a symbolic
//! link, belongs to another user or others may write to it; so are the subfolders a run writes
//! into ([`SUBFOLDERS`]) when they already exist. Every file in it is then created without
//! following a symbolic link (`files::create_replacing`, `files::write_atomic`).

use formation_config::node::files::{self, Lock};
use std::fs::File;
use std::io::{Read, Seek, Write};
use std::path::{Path, PathBuf};

/// Name of the lock file in the output folder.
pub const LOCK_NAME: &str = ".formation.lock";

/// The subfolders `run` and `sweep` write into, checked like the folder when they exist (a planted
/// `checkpoints -> elsewhere` would let its owner swap an agent's checkpoint).
pub const SUBFOLDERS: [&str; 6] = [
    "logs",
    "checkpoints",
    "iox2",
    "iox2/config",
    "timing",
    "samples",
];

/// Why an output folder is refused or its lock cannot be taken; each names the folder or file.
#[derive(Debug, thiserror::Error)]
pub enum OutLockError {
    /// The folder cannot be created owner-only, or is not this user's alone.
    #[error("output folder: {0}")]
    Folder(files::UnsafeDir),
    /// A subfolder a run writes into is not this user's alone (why, as the check says it).
    #[error("output folder: refusing the folder {}: {why}", path.display())]
    Subfolder {
        /// The subfolder.
        path: PathBuf,
        /// Why it is refused.
        why: files::DirProblem,
    },
    /// The lock file cannot be opened.
    #[error("cannot lock the output folder {}: {source}", out.display())]
    Open {
        /// The output folder.
        out: PathBuf,
        /// The file system's error.
        source: std::io::Error,
    },
    /// The lock cannot be taken (an error, not another holder).
    #[error("cannot lock {}: {source}", path.display())]
    Lock {
        /// The lock file.
        path: PathBuf,
        /// The file system's error.
        source: std::io::Error,
    },
    /// Another command holds the folder.
    #[error("the output folder {} is in use by {holder}: choose another --out or wait for it to end", out.display())]
    InUse {
        /// The output folder.
        out: PathBuf,
        /// Who holds it, e.g. `` `formation run` (run 3d2cb2b7, pid 812) ``.
        holder: String,
    },
    /// The holder's line cannot be written into the lock file.
    #[error("cannot write {}: {source}", path.display())]
    Write {
        /// The lock file.
        path: PathBuf,
        /// The file system's error.
        source: std::io::Error,
    },
    /// The lock file was replaced every time it was locked.
    #[error("cannot lock the output folder {}: its lock file keeps changing", .0.display())]
    KeepsChanging(PathBuf),
}

/// Creates `out` owner-only or refuses it (see the module documentation).
pub fn check_folder(out: &Path) -> Result<(), OutLockError> {
    files::ensure_private_dir(out).map_err(OutLockError::Folder)?;
    for sub in SUBFOLDERS {
        let p = out.join(sub);
        if std::fs::symlink_metadata(&p).is_ok() {
            files::check_private_dir(&p).map_err(|why| OutLockError::Subfolder {
                path: p.clone(),
                why,
            })?;
        }
    }
    Ok(())
}

/// A held output-folder lock; released (and its file removed) on drop.
#[derive(Debug)]
pub struct OutLock {
    file: File,
    path: PathBuf,
}

/// Who holds the lock, as written in the file: `run <id> (pid <pid>, formation <command>)`.
fn holder_text(pid: u32, run_id: Option<&str>, command: &str) -> String {
    format!(
        "pid {pid}\nrun {}\ncommand {command}\n",
        run_id.unwrap_or("-")
    )
}

/// One line naming the holder from the file's text.
fn describe_holder(text: &str) -> String {
    let field = |key: &str| {
        text.lines()
            .find_map(|l| l.strip_prefix(key).map(|v| v.trim().to_string()))
            .filter(|v| !v.is_empty() && v != "-")
    };
    let command = field("command ").unwrap_or_else(|| "formation".into());
    match (field("run "), field("pid ")) {
        (Some(id), Some(pid)) => format!("`{command}` (run {id}, pid {pid})"),
        (None, Some(pid)) => format!("`{command}` (pid {pid})"),
        _ => format!("`{command}` (still starting)"),
    }
}

/// Takes the lock of `out` (creating the folder), or says which run holds it.
pub fn acquire(out: &Path, run_id: Option<&str>, command: &str) -> Result<OutLock, OutLockError> {
    check_folder(out)?;
    let path = out.join(LOCK_NAME);
    // The holder removes the file at its end: a file opened just before that is no longer the one
    // at the path once locked, so open again.
    for _ in 0..16 {
        let mut file = files::open_lock_file(&path, true).map_err(|source| OutLockError::Open {
            out: out.to_path_buf(),
            source,
        })?;
        let locked =
            files::try_lock(&file, Lock::Exclusive).map_err(|source| OutLockError::Lock {
                path: path.clone(),
                source,
            })?;
        if !locked {
            let mut text = String::new();
            let _ = file.read_to_string(&mut text);
            return Err(OutLockError::InUse {
                out: out.to_path_buf(),
                holder: describe_holder(&text),
            });
        }
        if !files::is_at(&file, &path) {
            continue;
        }
        file.set_len(0)
            .and_then(|_| file.rewind())
            .and_then(|_| {
                file.write_all(holder_text(std::process::id(), run_id, command).as_bytes())
            })
            .map_err(|source| OutLockError::Write {
                path: path.clone(),
                source,
            })?;
        return Ok(OutLock { file, path });
    }
    Err(OutLockError::KeepsChanging(out.to_path_buf()))
}

impl Drop for OutLock {
    fn drop(&mut self) {
        // Removed while still locked; whoever opened it meanwhile opens it again (see `acquire`).
        if files::is_at(&self.file, &self.path) {
            let _ = std::fs::remove_file(&self.path);
        }
        files::unlock(&self.file);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_second_holder_is_refused_naming_the_first_and_the_lock_frees_at_drop() {
        let d = std::env::temp_dir().join(format!("fm-outlock-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        let first = acquire(&d, Some("abc123"), "formation run").unwrap();
        let e = acquire(&d, None, "formation sim").unwrap_err().to_string();
        assert!(e.contains("run abc123"), "{e}");
        assert!(e.contains(&format!("pid {}", std::process::id())), "{e}");
        assert!(e.contains(&d.display().to_string()), "{e}");
        drop(first);
        assert!(!d.join(LOCK_NAME).exists());
        let again = acquire(&d, None, "formation sim").unwrap();
        drop(again);
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn an_output_folder_others_can_write_or_a_linked_subfolder_is_refused_naming_it() {
        use std::os::unix::fs::PermissionsExt;
        let d = std::env::temp_dir().join(format!("fm-outlock-shared-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        let out = d.join("a").join("out");
        drop(acquire(&out, None, "formation sim").unwrap());
        std::fs::set_permissions(&out, std::fs::Permissions::from_mode(0o777)).unwrap();
        let e = acquire(&out, None, "formation sim")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains(&out.display().to_string()) && e.contains("world-writable"),
            "{e}"
        );
        std::fs::set_permissions(&out, std::fs::Permissions::from_mode(0o700)).unwrap();
        let elsewhere = d.join("elsewhere");
        std::fs::create_dir(&elsewhere).unwrap();
        std::os::unix::fs::symlink(&elsewhere, out.join("checkpoints")).unwrap();
        let e = acquire(&out, None, "formation run")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("checkpoints") && e.contains("symbolic link"),
            "{e}"
        );
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn a_symbolic_link_at_the_lock_name_is_refused_and_not_followed() {
        let d = std::env::temp_dir().join(format!("fm-outlock-link-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        let victim = d.join("victim");
        std::fs::write(&victim, "precious").unwrap();
        std::os::unix::fs::symlink(&victim, d.join(LOCK_NAME)).unwrap();
        assert!(acquire(&d, None, "formation sim").is_err());
        assert_eq!(std::fs::read_to_string(&victim).unwrap(), "precious");
        let _ = std::fs::remove_dir_all(&d);
    }
}
