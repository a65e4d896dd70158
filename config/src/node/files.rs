//! Files in folders other users may reach (`/tmp`, runtime dirs, output folders): created with
//! owner-only modes and without following a symbolic link planted at their name, and advisory
//! locks (`flock`) on them.

use std::fs::{File, OpenOptions};
use std::io;
use std::os::unix::fs::{MetadataExt, OpenOptionsExt};
use std::os::unix::io::AsRawFd;
use std::path::Path;

/// Creates `path` for writing, mode `mode`: fails if anything (a file, a symbolic link) already has
/// that name (`O_CREAT | O_EXCL`, which never follows a link, plus `O_NOFOLLOW`).
pub fn create_new(path: &Path, mode: u32) -> io::Result<File> {
    OpenOptions::new()
        .write(true)
        .create_new(true)
        .mode(mode)
        .custom_flags(libc::O_NOFOLLOW)
        .open(path)
}

/// Creates `path` for writing (mode 0600) without following a symbolic link at its name: whatever
/// has that name (an earlier output, a planted link) is removed first, never written through, and
/// the file is created new (`O_CREAT | O_EXCL | O_NOFOLLOW`). For files written as they go (a CSV,
/// a recording, a log); whole files are better written with [`write_atomic`].
pub fn create_replacing(path: &Path) -> io::Result<File> {
    match std::fs::symlink_metadata(path) {
        Ok(m) if m.is_dir() => {
            return Err(io::Error::new(
                io::ErrorKind::AlreadyExists,
                format!("{} is a directory", path.display()),
            ))
        }
        Ok(_) => std::fs::remove_file(path)?,
        Err(e) if e.kind() == io::ErrorKind::NotFound => {}
        Err(e) => return Err(e),
    }
    create_new(path, 0o600)
}

/// Writes `bytes` to `path` whole: a new owner-only temporary file next to it (create-new, never
/// through a symbolic link) renamed over `path` (a link at `path` is replaced, not followed).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> io::Result<()> {
    use std::io::Write;
    let name = path
        .file_name()
        .ok_or_else(|| io::Error::other(format!("{} has no file name", path.display())))?;
    let mut tmp_name = std::ffi::OsString::from(".");
    tmp_name.push(name);
    tmp_name.push(format!(".tmp{}", std::process::id()));
    let tmp = path.with_file_name(tmp_name);
    // A leftover of a killed writer of this pid, or a planted link: removed, never followed.
    let _ = std::fs::remove_file(&tmp);
    let mut f = create_new(&tmp, 0o600)?;
    let written = f
        .write_all(bytes)
        .and_then(|_| f.flush())
        .and_then(|_| std::fs::rename(&tmp, path));
    if written.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    written
}

/// Opens `path` for appending (created with mode 0600 if missing) without following a symbolic
/// link at its name; refuses anything but a regular file owned by this user.
pub fn open_append(path: &Path) -> io::Result<File> {
    let f = OpenOptions::new()
        .append(true)
        .create(true)
        .mode(0o600)
        .custom_flags(libc::O_NOFOLLOW | libc::O_NONBLOCK)
        .open(path)?;
    owned_regular(&f, path)?;
    Ok(f)
}

fn owned_regular(f: &File, path: &Path) -> io::Result<()> {
    let m = f.metadata()?;
    if !m.file_type().is_file() {
        return Err(io::Error::other(format!(
            "{} is not a regular file",
            path.display()
        )));
    }
    if m.uid() != current_uid() {
        return Err(io::Error::new(
            io::ErrorKind::PermissionDenied,
            format!(
                "{} belongs to {}, not to {}",
                path.display(),
                user_label(m.uid()),
                user_label(current_uid())
            ),
        ));
    }
    Ok(())
}

/// Why a folder must not hold this user's files ([`check_private_dir`]).
#[derive(Debug, thiserror::Error)]
pub enum DirProblem {
    /// Its metadata cannot be read (it does not exist, or a parent is not searchable).
    #[error("{}: {source}", dir.display())]
    Unreadable {
        /// The folder.
        dir: std::path::PathBuf,
        /// What the system said.
        source: io::Error,
    },
    /// It is a symbolic link.
    #[error("it is a symbolic link")]
    Link,
    /// It is not a directory.
    #[error("it is not a directory")]
    NotDir,
    /// It belongs to another user.
    #[error("it belongs to {}, not to {}", user_label(*owner), user_label(*me))]
    Owner {
        /// Its owner's uid.
        owner: u32,
        /// This process's uid.
        me: u32,
    },
    /// Others (group or world) may write to it.
    #[error(
        "it is {}-writable (mode {mode:04o}): other users could plant files in it",
        if mode & 0o002 != 0 { "world" } else { "group" }
    )]
    Writable {
        /// Its permission bits.
        mode: u32,
    },
}

/// Why `dir` must not hold this user's files, if it must not: it is a symbolic link, not a
/// directory, belongs to another user, or others (group or world) may write to it.
pub fn check_private_dir(dir: &Path) -> Result<(), DirProblem> {
    let m = std::fs::symlink_metadata(dir).map_err(|source| DirProblem::Unreadable {
        dir: dir.to_path_buf(),
        source,
    })?;
    if m.file_type().is_symlink() {
        return Err(DirProblem::Link);
    }
    if !m.is_dir() {
        return Err(DirProblem::NotDir);
    }
    let me = current_uid();
    if m.uid() != me {
        return Err(DirProblem::Owner { owner: m.uid(), me });
    }
    let mode = m.mode() & 0o7777;
    if mode & 0o022 != 0 {
        return Err(DirProblem::Writable { mode });
    }
    Ok(())
}

/// A folder that failed [`ensure_private_dir`]: which one and why.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct UnsafeDir {
    /// The folder refused (`dir` itself or a parent created on the way).
    pub path: std::path::PathBuf,
    /// Why.
    pub why: String,
}

impl std::fmt::Display for UnsafeDir {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "refusing the folder {}: {}",
            self.path.display(),
            self.why
        )
    }
}

impl std::error::Error for UnsafeDir {}

impl From<UnsafeDir> for io::Error {
    fn from(e: UnsafeDir) -> io::Error {
        io::Error::new(io::ErrorKind::PermissionDenied, e.to_string())
    }
}

/// Makes `dir` a folder only this user can write to: every missing component is created with mode
/// 0700 (one `mkdir` each, never through a link) and checked, and `dir` itself, new or not, must
/// pass [`check_private_dir`]. Parents that already exist (`/tmp`, a home) are not judged.
pub fn ensure_private_dir(dir: &Path) -> Result<(), UnsafeDir> {
    use std::os::unix::fs::DirBuilderExt;
    let refuse = |path: &Path, why: String| UnsafeDir {
        path: path.to_path_buf(),
        why,
    };
    // The missing components, outermost first.
    let mut missing = Vec::new();
    let mut p = dir;
    loop {
        match std::fs::symlink_metadata(p) {
            Ok(_) => break,
            Err(e) if e.kind() == io::ErrorKind::NotFound => {
                missing.push(p.to_path_buf());
                match p.parent() {
                    Some(q) if !q.as_os_str().is_empty() => p = q,
                    _ => break,
                }
            }
            Err(e) => return Err(refuse(p, e.to_string())),
        }
    }
    for m in missing.iter().rev() {
        match std::fs::DirBuilder::new().mode(0o700).create(m) {
            Ok(()) => {}
            // Created meanwhile by someone: judged below like any existing folder.
            Err(e) if e.kind() == io::ErrorKind::AlreadyExists => {}
            Err(e) => return Err(refuse(m, format!("cannot create it: {e}"))),
        }
        check_private_dir(m).map_err(|why| refuse(m, why.to_string()))?;
    }
    check_private_dir(dir).map_err(|why| refuse(dir, why.to_string()))
}

/// Reads `path` as text without following a symbolic link at its name (nor blocking on a FIFO).
pub fn open_read_nofollow(path: &Path) -> io::Result<String> {
    use std::io::Read;
    let mut f = OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NOFOLLOW | libc::O_NONBLOCK)
        .open(path)?;
    let mut s = String::new();
    f.read_to_string(&mut s)?;
    Ok(s)
}

/// Opens `path` read-write without following a symbolic link at its name, creating it with mode
/// 0600 when `create` is set; refuses anything but a regular file owned by this user.
pub fn open_lock_file(path: &Path, create: bool) -> io::Result<File> {
    let f = OpenOptions::new()
        .read(true)
        .write(true)
        .create(create)
        .mode(0o600)
        .custom_flags(libc::O_NOFOLLOW | libc::O_NONBLOCK)
        .open(path)?;
    owned_regular(&f, path)?;
    Ok(f)
}

/// The real user id of this process.
pub fn current_uid() -> u32 {
    // SAFETY: getuid has no preconditions and cannot fail.
    unsafe { libc::getuid() }
}

/// `name (uid N)`, or `uid N` when the user has no name.
pub fn user_label(uid: u32) -> String {
    let mut buf = vec![0u8; 4096];
    // SAFETY: a zeroed passwd is valid; getpwuid_r writes into pwd and buf (of the length given)
    // and sets result to &pwd or null.
    let name = unsafe {
        let mut pwd: libc::passwd = std::mem::zeroed();
        let mut result: *mut libc::passwd = std::ptr::null_mut();
        let rc = libc::getpwuid_r(
            uid,
            &mut pwd,
            buf.as_mut_ptr().cast(),
            buf.len(),
            &mut result,
        );
        if rc == 0 && !result.is_null() && !pwd.pw_name.is_null() {
            Some(
                std::ffi::CStr::from_ptr(pwd.pw_name)
                    .to_string_lossy()
                    .into_owned(),
            )
        } else {
            None
        }
    };
    match name {
        Some(n) => format!("user {n} (uid {uid})"),
        None => format!("uid {uid}"),
    }
}

/// Kind of an advisory lock.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Lock {
    /// Many holders at once.
    Shared,
    /// One holder.
    Exclusive,
}

/// Takes `kind` on `f` without waiting: `Ok(false)` when another open file holds a conflicting lock.
pub fn try_lock(f: &File, kind: Lock) -> io::Result<bool> {
    let op = match kind {
        Lock::Shared => libc::LOCK_SH,
        Lock::Exclusive => libc::LOCK_EX,
    };
    // SAFETY: flock on a valid open descriptor.
    if unsafe { libc::flock(f.as_raw_fd(), op | libc::LOCK_NB) } == 0 {
        return Ok(true);
    }
    let e = io::Error::last_os_error();
    if e.raw_os_error() == Some(libc::EWOULDBLOCK) {
        Ok(false)
    } else {
        Err(e)
    }
}

/// Takes `kind` on `f`, waiting for it.
pub fn lock(f: &File, kind: Lock) -> io::Result<()> {
    let op = match kind {
        Lock::Shared => libc::LOCK_SH,
        Lock::Exclusive => libc::LOCK_EX,
    };
    loop {
        // SAFETY: flock on a valid open descriptor.
        if unsafe { libc::flock(f.as_raw_fd(), op) } == 0 {
            return Ok(());
        }
        let e = io::Error::last_os_error();
        if e.kind() != io::ErrorKind::Interrupted {
            return Err(e);
        }
    }
}

/// Releases the lock held through `f`.
pub fn unlock(f: &File) {
    // SAFETY: flock on a valid open descriptor.
    unsafe {
        libc::flock(f.as_raw_fd(), libc::LOCK_UN);
    }
}

/// True when `f` is still the file at `path` (it was not replaced or removed since it was opened).
pub fn is_at(f: &File, path: &Path) -> bool {
    match (f.metadata(), std::fs::symlink_metadata(path)) {
        (Ok(a), Ok(b)) => a.dev() == b.dev() && a.ino() == b.ino(),
        _ => false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn temp(tag: &str) -> std::path::PathBuf {
        let d = std::env::temp_dir().join(format!("fm-files-{}-{tag}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn create_new_does_not_write_through_a_planted_symbolic_link() {
        let d = temp("symlink");
        let victim = d.join("victim");
        std::fs::write(&victim, "precious").unwrap();
        let planted = d.join("record.tmp");
        std::os::unix::fs::symlink(&victim, &planted).unwrap();
        assert!(create_new(&planted, 0o600).is_err());
        assert!(open_lock_file(&planted, true).is_err());
        assert_eq!(std::fs::read_to_string(&victim).unwrap(), "precious");
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn outputs_replace_a_planted_link_instead_of_writing_through_it() {
        let d = temp("outputs");
        let victim = d.join("victim");
        std::fs::write(&victim, "precious").unwrap();
        let out = d.join("out");
        ensure_private_dir(&out).unwrap();
        for name in ["summary.json", "trajectory.csv", "agent-1.log"] {
            std::os::unix::fs::symlink(&victim, out.join(name)).unwrap();
        }
        write_atomic(&out.join("summary.json"), b"{}").unwrap();
        use std::io::Write;
        create_replacing(&out.join("trajectory.csv"))
            .unwrap()
            .write_all(b"t")
            .unwrap();
        assert!(open_append(&out.join("agent-1.log")).is_err());
        assert_eq!(std::fs::read_to_string(&victim).unwrap(), "precious");
        assert_eq!(
            std::fs::read_to_string(out.join("summary.json")).unwrap(),
            "{}"
        );
        assert!(!std::fs::symlink_metadata(out.join("trajectory.csv"))
            .unwrap()
            .file_type()
            .is_symlink());
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn private_folders_are_created_0700_and_links_or_shared_ones_refused() {
        use std::os::unix::fs::PermissionsExt;
        let d = temp("private");
        let deep = d.join("a").join("b");
        ensure_private_dir(&deep).unwrap();
        for p in [d.join("a"), deep.clone()] {
            assert_eq!(std::fs::metadata(&p).unwrap().mode() & 0o777, 0o700);
        }
        let link = d.join("link");
        std::os::unix::fs::symlink(&deep, &link).unwrap();
        let e = ensure_private_dir(&link).unwrap_err();
        assert_eq!(e.path, link);
        assert!(e.why.contains("symbolic link"), "{e}");
        let shared = d.join("shared");
        std::fs::create_dir(&shared).unwrap();
        std::fs::set_permissions(&shared, std::fs::Permissions::from_mode(0o777)).unwrap();
        assert!(ensure_private_dir(&shared)
            .unwrap_err()
            .why
            .contains("world-writable"));
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn exclusive_locks_exclude_each_other_and_shared_ones_do_not() {
        let d = temp("locks");
        let p = d.join("x.lock");
        let a = open_lock_file(&p, true).unwrap();
        let b = open_lock_file(&p, false).unwrap();
        assert!(try_lock(&a, Lock::Shared).unwrap());
        assert!(try_lock(&b, Lock::Shared).unwrap());
        assert!(!try_lock(&b, Lock::Exclusive).unwrap());
        unlock(&a);
        unlock(&b);
        assert!(try_lock(&a, Lock::Exclusive).unwrap());
        assert!(!try_lock(&b, Lock::Shared).unwrap());
        assert!(is_at(&a, &p));
        let _ = std::fs::remove_dir_all(&d);
    }
}
