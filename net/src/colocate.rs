//! A host whose daemon runs on the launching machine, as the orchestrator's user, with the
//! orchestrator's `/dev/shm` and iceoryx2 root: a *co-located* host.
//!
//! A run's iceoryx2 services have the same names on every host, so such a daemon cannot create
//! them or bridge them (they exist already, in the very same `/dev/shm`). Its agents open the
//! orchestrator's services directly instead; the daemon still starts, signals and reports them
//! (its role in the run is unchanged, and authenticated as for any host), and no bridge forwards
//! anything to or from it: data-plane wise it is the launcher ([`crate::plan::Placement::data_plane`]).
//!
//! The decisions are pure functions of facts gathered elsewhere: [`data_plane`] (the orchestrator,
//! from the daemon's [`crate::proto::HostInfo`]) and [`check_services`] (the daemon, from its own
//! `/dev/shm`, before it accepts a co-located run).

use serde::{Deserialize, Serialize};

/// Where a process's POSIX shared memory lives: the kernel it runs on and the file system of its
/// `/dev/shm`. Two processes with equal places share `/dev/shm` (a mount namespace with a tmpfs
/// of its own has another device).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct ShmPlace {
    /// `/proc/sys/kernel/random/boot_id`: the running kernel (device numbers are compared only
    /// within one kernel).
    pub boot_id: String,
    /// Device of `/dev/shm`.
    pub dev: u64,
    /// Inode of `/dev/shm`.
    pub ino: u64,
}

impl ShmPlace {
    /// This process's place; `None` when the boot id or `/dev/shm` cannot be read.
    pub fn here() -> Option<ShmPlace> {
        use std::os::unix::fs::MetadataExt;
        let boot_id = std::fs::read_to_string("/proc/sys/kernel/random/boot_id").ok()?;
        let m = std::fs::metadata(formation_config::node::ipc::SHM_DIR).ok()?;
        Some(ShmPlace {
            boot_id: boot_id.trim().to_string(),
            dev: m.dev(),
            ino: m.ino(),
        })
    }
}

/// What the co-location decision needs to know of one process (the orchestrator, or a daemon as
/// its [`crate::proto::HostInfo`] says).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Facts {
    /// Its shared memory place, if known.
    pub shm: Option<ShmPlace>,
    /// Its effective user id, if known.
    pub uid: Option<u32>,
    /// Its iceoryx2 root folder (`formation_config::node::ipc::root_dir`), if known.
    pub iox2_root: Option<String>,
}

impl Facts {
    /// This process's facts.
    pub fn here() -> Facts {
        Facts {
            shm: ShmPlace::here(),
            uid: Some(euid()),
            iox2_root: Some(
                formation_config::node::ipc::root_dir()
                    .to_string_lossy()
                    .into_owned(),
            ),
        }
    }
}

/// This process's effective user id.
pub fn euid() -> u32 {
    // SAFETY: geteuid has no preconditions and cannot fail.
    unsafe { libc::geteuid() }
}

/// How a host's data reaches the launcher.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DataPlane {
    /// Another `/dev/shm` (another machine, or a mount namespace): its daemon creates the run's
    /// services there and bridges them over Zenoh.
    Remote,
    /// The launcher's own `/dev/shm`, user and iceoryx2 root: its agents use the orchestrator's
    /// services directly; no services, no bridge on that host.
    Colocated,
}

/// Why a daemon that shares this orchestrator's `/dev/shm` cannot take part in a run.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ColocationError {
    /// It runs as another user: its agents could not open the orchestrator's services, and the
    /// services it would create collide with them.
    OtherUser {
        /// The host.
        host: String,
        /// The daemon's effective uid.
        daemon_uid: u32,
        /// The orchestrator's.
        uid: u32,
    },
    /// It runs as this user with another iceoryx2 root (another `XDG_RUNTIME_DIR`): its agents
    /// would not find the orchestrator's services.
    OtherRoot {
        /// The host.
        host: String,
        /// The daemon's iceoryx2 root.
        daemon_root: String,
        /// The orchestrator's.
        root: String,
    },
}

impl std::fmt::Display for ColocationError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ColocationError::OtherUser {
                host,
                daemon_uid,
                uid,
            } => write!(
                f,
                "host {host} is a daemon on this machine that shares this orchestrator's /dev/shm but runs as uid {daemon_uid}, this orchestrator as uid {uid}: a run's iceoryx2 services have the same names on every host and belong to one user, so they would collide. Start `formation host` as uid {uid} (then it runs this machine's agents of the run with this orchestrator's services), or give that daemon a /dev/shm of its own (docs/multi-host.md, \"One machine\"), or run without --hosts"
            ),
            ColocationError::OtherRoot {
                host,
                daemon_root,
                root,
            } => write!(
                f,
                "host {host} is a daemon of this user on this machine, sharing this orchestrator's /dev/shm, but its iceoryx2 root is {daemon_root} and this orchestrator's {root}: its agents would not find the run's services. Start `formation host` with this orchestrator's XDG_RUNTIME_DIR (docs/multi-host.md, \"One machine\")"
            ),
        }
    }
}

impl std::error::Error for ColocationError {}

/// How `host`'s daemon (`daemon`) exchanges data with this orchestrator (`me`): co-located when it
/// shares `/dev/shm` (same kernel, same file system), user and iceoryx2 root; remote when it does
/// not share `/dev/shm` or either side does not know where its own is. A daemon that shares
/// `/dev/shm` as another user or with another root cannot take part: `Err` says why and what to do.
pub fn data_plane(host: &str, me: &Facts, daemon: &Facts) -> Result<DataPlane, ColocationError> {
    let shares = matches!((&me.shm, &daemon.shm), (Some(a), Some(b)) if a == b);
    if !shares {
        return Ok(DataPlane::Remote);
    }
    match (me.uid, daemon.uid) {
        (Some(uid), Some(daemon_uid)) if uid == daemon_uid => {}
        (uid, daemon_uid) => {
            // Unknown counts as another user: nothing says the services would be reachable.
            return Err(ColocationError::OtherUser {
                host: host.to_string(),
                daemon_uid: daemon_uid.unwrap_or(u32::MAX),
                uid: uid.unwrap_or(u32::MAX),
            });
        }
    }
    match (&me.iox2_root, &daemon.iox2_root) {
        (Some(a), Some(b)) if a == b => Ok(DataPlane::Colocated),
        (root, daemon_root) => Err(ColocationError::OtherRoot {
            host: host.to_string(),
            daemon_root: daemon_root.clone().unwrap_or_else(|| "unknown".into()),
            root: root.clone().unwrap_or_else(|| "unknown".into()),
        }),
    }
}

/// One entry of a shared-memory folder, as [`check_services`] sees it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ShmEntry {
    /// File name.
    pub name: String,
    /// Owner.
    pub uid: u32,
    /// A regular file (not a link, folder, ...).
    pub regular: bool,
}

/// Why a daemon refuses a co-located run after looking at its own `/dev/shm` and folders.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ServicesError {
    /// No file of the run's prefix: the run's services are not in this daemon's `/dev/shm`.
    Missing {
        /// The run's prefix.
        prefix: String,
    },
    /// A file of the run's prefix is another user's, or not a regular file.
    Foreign {
        /// Its name.
        name: String,
        /// Its owner.
        uid: u32,
        /// This daemon's effective uid.
        euid: u32,
    },
    /// The iceoryx2 root the orchestrator uses is not this daemon's.
    OtherRoot {
        /// The orchestrator's.
        theirs: String,
        /// This daemon's.
        mine: String,
    },
    /// The run's membership lock the agents are to join is unusable.
    Members(String),
    /// `/dev/shm` could not be listed.
    Unreadable(String),
}

impl std::fmt::Display for ServicesError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ServicesError::Missing { prefix } => write!(
                f,
                "a co-located run, but no file of its prefix {prefix} in this host's /dev/shm: this daemon does not share the orchestrator's /dev/shm"
            ),
            ServicesError::Foreign { name, uid, euid } => write!(
                f,
                "a co-located run, but its shared memory file {name} belongs to uid {uid} or is not a regular file (this daemon runs as uid {euid})"
            ),
            ServicesError::OtherRoot { theirs, mine } => write!(
                f,
                "a co-located run whose iceoryx2 root is {theirs}, this daemon's {mine}: start it with the orchestrator's XDG_RUNTIME_DIR"
            ),
            ServicesError::Members(why) => write!(f, "a co-located run: {why}"),
            ServicesError::Unreadable(why) => write!(f, "a co-located run: {why}"),
        }
    }
}

impl std::error::Error for ServicesError {}

/// Checks that the run of `prefix` exists in this daemon's `/dev/shm` (`entries`) and is its own
/// user's: at least one file of the prefix, every one a regular file owned by `euid`. Returns how
/// many there are.
pub fn check_services(
    entries: &[ShmEntry],
    prefix: &str,
    euid: u32,
) -> Result<usize, ServicesError> {
    let mut n = 0;
    for e in entries.iter().filter(|e| e.name.starts_with(prefix)) {
        if e.uid != euid || !e.regular {
            return Err(ServicesError::Foreign {
                name: e.name.clone(),
                uid: e.uid,
                euid,
            });
        }
        n += 1;
    }
    if n == 0 {
        return Err(ServicesError::Missing {
            prefix: prefix.to_string(),
        });
    }
    Ok(n)
}

/// The entries of this process's `/dev/shm` (never following a link).
pub fn shm_entries() -> Result<Vec<ShmEntry>, ServicesError> {
    use std::os::unix::fs::MetadataExt;
    let dir = formation_config::node::ipc::SHM_DIR;
    let rd = std::fs::read_dir(dir)
        .map_err(|e| ServicesError::Unreadable(format!("cannot list {dir}: {e}")))?;
    Ok(rd
        .flatten()
        .filter_map(|e| {
            let m = std::fs::symlink_metadata(e.path()).ok()?;
            Some(ShmEntry {
                name: e.file_name().to_string_lossy().into_owned(),
                uid: m.uid(),
                regular: m.file_type().is_file(),
            })
        })
        .collect())
}

/// Checks the run's membership lock file (`formation_config::node::members`) that a co-located
/// run's agents join instead of one of the daemon's: an absolute path named `members.lock`, a
/// regular file (not a link) of `euid`, in a folder of `euid` that nobody else may write to.
pub fn check_members(path: &std::path::Path, euid: u32) -> Result<(), ServicesError> {
    use std::os::unix::fs::MetadataExt;
    let bad = |why: &str| {
        ServicesError::Members(format!(
            "the run's membership lock {}: {why}",
            path.display()
        ))
    };
    if !path.is_absolute() || path.file_name() != Some(std::ffi::OsStr::new("members.lock")) {
        return Err(bad("not an absolute path to members.lock"));
    }
    let m = std::fs::symlink_metadata(path).map_err(|e| bad(&e.to_string()))?;
    if !m.file_type().is_file() || m.uid() != euid {
        return Err(bad("not a regular file of this user"));
    }
    let dir = path.parent().ok_or_else(|| bad("no folder"))?;
    let d = std::fs::symlink_metadata(dir).map_err(|e| bad(&e.to_string()))?;
    if !d.is_dir() || d.uid() != euid || d.mode() & 0o022 != 0 {
        return Err(bad(
            "its folder is not this user's or may be written by others",
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn place(dev: u64) -> Option<ShmPlace> {
        Some(ShmPlace {
            boot_id: "b00t".into(),
            dev,
            ino: 1,
        })
    }

    fn facts(dev: u64, uid: u32, root: &str) -> Facts {
        Facts {
            shm: place(dev),
            uid: Some(uid),
            iox2_root: Some(root.into()),
        }
    }

    #[test]
    fn a_daemon_of_this_user_sharing_dev_shm_and_root_is_co_located() {
        let me = facts(25, 1000, "/run/user/1000/formation/iox2");
        assert_eq!(data_plane("b", &me, &me.clone()), Ok(DataPlane::Colocated));
    }

    #[test]
    fn a_daemon_with_its_own_dev_shm_or_on_another_kernel_is_remote_whoever_runs_it() {
        let me = facts(25, 1000, "/r");
        // Another tmpfs (a mount namespace), even as root with another root folder.
        assert_eq!(
            data_plane("b", &me, &facts(26, 0, "/x")),
            Ok(DataPlane::Remote)
        );
        // The same device numbers on another machine are another /dev/shm.
        let mut other = me.clone();
        other.shm.as_mut().unwrap().boot_id = "other".into();
        assert_eq!(data_plane("b", &me, &other), Ok(DataPlane::Remote));
        // A side that does not know its /dev/shm is not judged co-located.
        let unknown = Facts {
            shm: None,
            ..me.clone()
        };
        assert_eq!(data_plane("b", &me, &unknown), Ok(DataPlane::Remote));
        assert_eq!(data_plane("b", &unknown, &me), Ok(DataPlane::Remote));
    }

    #[test]
    fn a_daemon_sharing_dev_shm_as_another_user_is_refused_saying_what_to_do() {
        let me = facts(25, 1000, "/r");
        let e = data_plane("b", &me, &facts(25, 0, "/r")).unwrap_err();
        assert_eq!(
            e,
            ColocationError::OtherUser {
                host: "b".into(),
                daemon_uid: 0,
                uid: 1000
            }
        );
        let text = e.to_string();
        assert!(text.contains("host b") && text.contains("uid 0") && text.contains("uid 1000"));
        assert!(
            text.contains("Start `formation host` as uid 1000"),
            "{text}"
        );
        // A daemon that does not say its user is not taken for this one.
        let mut unknown = me.clone();
        unknown.uid = None;
        assert!(matches!(
            data_plane("b", &me, &unknown),
            Err(ColocationError::OtherUser { .. })
        ));
    }

    #[test]
    fn a_daemon_of_this_user_with_another_iceoryx2_root_is_refused_naming_both() {
        let me = facts(25, 1000, "/run/user/1000/formation/iox2");
        let e = data_plane("b", &me, &facts(25, 1000, "/tmp/formation-iox2-1000")).unwrap_err();
        let text = e.to_string();
        assert!(text.contains("/tmp/formation-iox2-1000") && text.contains("/run/user/1000"));
        assert!(text.contains("XDG_RUNTIME_DIR"), "{text}");
    }

    fn entry(name: &str, uid: u32, regular: bool) -> ShmEntry {
        ShmEntry {
            name: name.into(),
            uid,
            regular,
        }
    }

    #[test]
    fn a_co_located_run_needs_files_of_its_prefix_all_of_the_daemons_user() {
        let mine = [
            entry("fm12ab_iox2_1.global_mgmt", 1000, true),
            entry("fm12ab_iox2_2.data", 1000, true),
            entry("fm99_other", 0, true),
        ];
        assert_eq!(check_services(&mine, "fm12ab_", 1000), Ok(2));
        assert_eq!(
            check_services(&mine, "fm34cd_", 1000),
            Err(ServicesError::Missing {
                prefix: "fm34cd_".into()
            })
        );
        assert!(check_services(&[], "fm12ab_", 1000)
            .unwrap_err()
            .to_string()
            .contains("does not share the orchestrator's /dev/shm"));
        // One file of another user (planted, or a root orchestrator's) or a link: refused.
        let planted = [
            entry("fm12ab_iox2_1.global_mgmt", 1000, true),
            entry("fm12ab_iox2_2.data", 0, true),
        ];
        assert!(matches!(
            check_services(&planted, "fm12ab_", 1000),
            Err(ServicesError::Foreign { uid: 0, .. })
        ));
        let link = [entry("fm12ab_iox2_1.global_mgmt", 1000, false)];
        assert!(matches!(
            check_services(&link, "fm12ab_", 1000),
            Err(ServicesError::Foreign { .. })
        ));
    }

    #[test]
    fn the_membership_lock_must_be_an_absolute_private_members_lock() {
        use std::os::unix::fs::PermissionsExt;
        let dir = std::env::temp_dir().join(format!("fm-colocate-{}", std::process::id()));
        let iox2 = dir.join("iox2");
        std::fs::create_dir_all(&iox2).unwrap();
        std::fs::set_permissions(&iox2, std::fs::Permissions::from_mode(0o700)).unwrap();
        let lock = iox2.join("members.lock");
        std::fs::write(&lock, b"").unwrap();
        assert_eq!(check_members(&lock, euid()), Ok(()));
        assert!(check_members(std::path::Path::new("iox2/members.lock"), euid()).is_err());
        assert!(check_members(&iox2.join("other"), euid()).is_err());
        assert!(check_members(&lock, euid().wrapping_add(1)).is_err());
        let link = dir.join("link");
        std::fs::create_dir_all(&link).unwrap();
        std::os::unix::fs::symlink(&lock, link.join("members.lock")).unwrap();
        assert!(check_members(&link.join("members.lock"), euid()).is_err());
        std::fs::set_permissions(&iox2, std::fs::Permissions::from_mode(0o777)).unwrap();
        assert!(check_members(&lock, euid()).is_err());
        let _ = std::fs::remove_dir_all(&dir);
    }
}
