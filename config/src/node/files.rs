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
