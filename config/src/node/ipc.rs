//! Reusable iceoryx2 plumbing for formation processes.
//!
//! * [`config_for_prefix`] / [`node`]: a node under a per-run prefix, with an explicit in-memory
//!   config (iceoryx2 never reads `config/iceoryx2.toml`, which matters because this repository has a
//!   top-level `config/` directory) and a quiet log ([`quiet_log`]).
//! * [`Limits`], [`pubsub_with_limits`], [`event_with_limits`]: services sized for the number of
//!   processes (the defaults allow only 2 publishers and 8 subscribers per service). Limits are fixed
//!   by whichever process *creates* a service, so one process should create every service before the
//!   others open them.
//! * [`remove_residue`]: deletes the files a run leaves under its prefix in `/dev/shm` and under the
//!   iceoryx2 root directory ([`root_dir`]), even after a clean exit.
//! * [`root_dir`]: the iceoryx2 root of this user (`$XDG_RUNTIME_DIR/formation/iox2`, else
//!   `/tmp/formation-iox2-<uid>`), mode 0700 and checked like the runs folder, instead of iceoryx2's
//!   shared `/tmp/iceoryx2` (which the first user creates 0750, locking every other user out): two
//!   users run side by side and nobody else can reach a run's node records or event sockets.
//! * [`node`] makes the run's `…global_mgmt` segment in `/dev/shm` owner-only: iceoryx2 0.10 creates
//!   it mode 0666 whatever the umask (`enable_global_access(true)` then an explicit `fchmod`), and
//!   16 bytes written into it by anyone make every later node creation of the prefix fail. A
//!   segment of the prefix owned by another user is refused.
//! * [`dead_prefixes`] and [`reap`]: the files of run prefixes whose nodes are all dead (an
//!   observer killed after its run ended), for `formation ps` and `formation run` to remove.

use core::fmt::Debug;
use iceoryx2::node::{NodeCreationFailure, NodeView};
use iceoryx2::prelude::*;
use iceoryx2::service::builder::{event, publish_subscribe};
use std::path::Path as StdPath;

/// Where POSIX shared memory objects live on Linux.
pub const SHM_DIR: &str = "/dev/shm";

/// File name ending of iceoryx2's per-prefix global management segment in `/dev/shm`.
pub const GLOBAL_MGMT_SUFFIX: &str = ".global_mgmt";

/// Longest prefix accepted by [`config_for_prefix`]; it becomes part of every file name.
pub const MAX_PREFIX_LEN: usize = 32;

/// Errors of the helpers in this module.
#[derive(Debug)]
pub enum IpcError {
    /// The prefix is empty, too long, or has characters other than `[A-Za-z0-9_-]`.
    BadPrefix(String),
    /// The service or node name is not valid for iceoryx2.
    BadName(String),
    /// iceoryx2 could not create the node.
    Node(NodeCreationFailure),
    /// The iceoryx2 root folder or a file of the prefix is not this user's alone.
    Unsafe(String),
}

impl core::fmt::Display for IpcError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            IpcError::BadPrefix(p) => write!(
                f,
                "invalid iceoryx2 prefix '{p}': use 1..={MAX_PREFIX_LEN} characters of [A-Za-z0-9_-]"
            ),
            IpcError::BadName(n) => write!(f, "invalid iceoryx2 name '{n}'"),
            IpcError::Node(e) => write!(
                f,
                "cannot create iceoryx2 node: {e:?} (iceoryx2 root {})",
                root_dir().display()
            ),
            IpcError::Unsafe(e) => write!(f, "{e}"),
        }
    }
}

impl std::error::Error for IpcError {}

/// Raises iceoryx2's log level to `Error` (overridable with the `IOX2_LOG_LEVEL` environment
/// variable), so processes do not print "No config file was loaded" and similar notices.
pub fn quiet_log() {
    set_log_level_from_env_or(LogLevel::Error);
}

/// True when `prefix` is usable as an iceoryx2 global prefix by [`config_for_prefix`].
pub fn is_valid_prefix(prefix: &str) -> bool {
    !prefix.is_empty()
        && prefix.len() <= MAX_PREFIX_LEN
        && prefix
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b == b'_' || b == b'-')
}

/// The iceoryx2 root folder of this user: `$XDG_RUNTIME_DIR/formation/iox2` when that runtime
/// folder exists, else `/tmp/formation-iox2-<uid>` (unchecked; see [`checked_root_dir`]).
pub fn root_dir() -> std::path::PathBuf {
    if let Some(d) = std::env::var_os("XDG_RUNTIME_DIR").filter(|d| !d.is_empty()) {
        if StdPath::new(&d).is_dir() {
            return StdPath::new(&d).join("formation").join("iox2");
        }
    }
    std::path::PathBuf::from(format!(
        "/tmp/formation-iox2-{}",
        super::files::current_uid()
    ))
}

/// [`root_dir`], created with mode 0700 if missing, refused when it is a link, another user's or
/// writable by others.
pub fn checked_root_dir() -> Result<std::path::PathBuf, IpcError> {
    let dir = root_dir();
    super::files::ensure_private_dir(&dir).map_err(|e| {
        IpcError::Unsafe(format!(
            "iceoryx2 root: {e} (it must be a folder of yours with mode 0700)"
        ))
    })?;
    Ok(dir)
}

/// The default iceoryx2 config with `global.prefix = prefix` and this user's root folder
/// ([`checked_root_dir`]), built in memory (no config file is read). Nodes created with it only
/// see services of the same prefix.
pub fn config_for_prefix(prefix: &str) -> Result<Config, IpcError> {
    if !is_valid_prefix(prefix) {
        return Err(IpcError::BadPrefix(prefix.to_string()));
    }
    let root = checked_root_dir()?;
    let mut cfg = Config::default();
    cfg.global.prefix =
        FileName::new(prefix.as_bytes()).map_err(|_| IpcError::BadPrefix(prefix.to_string()))?;
    let mut root_text = root.to_string_lossy().into_owned();
    root_text.push('/');
    let root_path = Path::new(root_text.as_bytes())
        .map_err(|_| IpcError::Unsafe(format!("iceoryx2 root {root_text}: not a usable path")))?;
    cfg.global.set_root_path(&root_path);
    Ok(cfg)
}

/// Makes every `…global_mgmt` segment of `prefix` in `/dev/shm` owner-only (iceoryx2 creates it
/// mode 0666); refuses one that belongs to another user (planted before the run created it).
/// Never follows a link. Returns how many it changed.
pub fn protect_global_mgmt(prefix: &str) -> Result<usize, IpcError> {
    use std::os::unix::fs::{MetadataExt, OpenOptionsExt, PermissionsExt};
    let entries = match std::fs::read_dir(SHM_DIR) {
        Ok(e) => e,
        Err(e) => return Err(IpcError::Unsafe(format!("cannot list {SHM_DIR}: {e}"))),
    };
    let mut changed = 0;
    for entry in entries.flatten() {
        let name = entry.file_name();
        let name = name.to_string_lossy();
        if !(name.starts_with(prefix) && name.ends_with(GLOBAL_MGMT_SUFFIX)) {
            continue;
        }
        let path = entry.path();
        let f = std::fs::OpenOptions::new()
            .read(true)
            .custom_flags(libc::O_NOFOLLOW | libc::O_NONBLOCK)
            .open(&path)
            .map_err(|e| IpcError::Unsafe(format!("cannot open {}: {e}", path.display())))?;
        let m = f
            .metadata()
            .map_err(|e| IpcError::Unsafe(format!("{}: {e}", path.display())))?;
        let me = super::files::current_uid();
        if !m.is_file() || m.uid() != me {
            return Err(IpcError::Unsafe(format!(
                "refusing {}: it belongs to {}, not to {} (planted under this run's prefix)",
                path.display(),
                super::files::user_label(m.uid()),
                super::files::user_label(me)
            )));
        }
        if m.mode() & 0o077 != 0 {
            f.set_permissions(std::fs::Permissions::from_mode(0o600))
                .map_err(|e| IpcError::Unsafe(format!("cannot chmod {}: {e}", path.display())))?;
            changed += 1;
        }
    }
    Ok(changed)
}

/// Creates an inter-process node named `name` under `prefix`, with a quiet log and without
/// iceoryx2's own SIGINT/SIGTERM handling (the process decides how to react to signals).
pub fn node(prefix: &str, name: &str) -> Result<Node<ipc::Service>, IpcError> {
    quiet_log();
    let cfg = config_for_prefix(prefix)?;
    let node_name = NodeName::new(name).map_err(|_| IpcError::BadName(name.to_string()))?;
    let node = NodeBuilder::new()
        .config(&cfg)
        .name(&node_name)
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<ipc::Service>()
        .map_err(IpcError::Node)?;
    protect_global_mgmt(prefix)?;
    Ok(node)
}

/// Converts a string into a [`ServiceName`].
pub fn service_name(name: &str) -> Result<ServiceName, IpcError> {
    ServiceName::new(name).map_err(|_| IpcError::BadName(name.to_string()))
}

pub use crate::protocol::services::Limits;

/// Applies `limits` to a publish-subscribe builder (any payload and user header).
pub fn pubsub_with_limits<P, H>(
    builder: publish_subscribe::Builder<P, H, ipc::Service>,
    limits: &Limits,
) -> publish_subscribe::Builder<P, H, ipc::Service>
where
    P: Debug + IceoryxSend + ?Sized,
    H: Debug + ZeroCopySend,
{
    builder
        .max_nodes(limits.nodes)
        .max_publishers(limits.senders)
        .max_subscribers(limits.receivers)
        .subscriber_max_buffer_size(limits.buffer)
        .history_size(0)
}

/// Largest event id our event services carry. Every notification is a plain wake-up with the
/// default id 0. iceoryx2's default (255) makes every listener wake-up sweep 256 counters with
/// atomic swaps (`CountingBitSet::reset_all`): with 0 the sweep is one counter (measured with
/// `perf record`: the sweep was the single largest user-space cost of an agent process).
pub const WAKE_EVENT_ID_MAX: usize = 0;

/// Applies `limits` to an event builder (and [`WAKE_EVENT_ID_MAX`]).
pub fn event_with_limits(
    builder: event::Builder<ipc::Service>,
    limits: &Limits,
) -> event::Builder<ipc::Service> {
    builder
        .max_nodes(limits.nodes)
        .max_notifiers(limits.senders)
        .max_listeners(limits.receivers)
        .event_id_max_value(WAKE_EVENT_ID_MAX)
}

/// Deletes every file of this user whose name starts with `prefix` directly in `/dev/shm` and
/// anywhere below the iceoryx2 root directory ([`root_dir`]). Directories are left alone
/// (they are shared by all runs). Call it after every node of the run has been dropped and every
/// process of the run has exited. Returns the number of files removed; missing directories are not
/// an error.
pub fn remove_residue(prefix: &str) -> std::io::Result<usize> {
    if !is_valid_prefix(prefix) {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            IpcError::BadPrefix(prefix.to_string()).to_string(),
        ));
    }
    let root = root_dir();
    let mut removed = remove_prefixed(StdPath::new(SHM_DIR), prefix, false)?;
    removed += remove_prefixed(StdPath::new(&root), prefix, true)?;
    Ok(removed)
}

/// A node under a prefix whose process is alive.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct AliveNode {
    /// Its name (not unique; empty when it has none).
    pub name: String,
    /// Its process id.
    pub pid: i32,
}

/// The nodes under `prefix` whose processes are alive. Once every process of a run has exited
/// and the orchestrator has dropped its node, these are outside nodes (an observer, `formation
/// inspect`) that still use the run's files.
pub fn alive_nodes(prefix: &str) -> Result<Vec<AliveNode>, IpcError> {
    let cfg = config_for_prefix(prefix)?;
    let mut out = Vec::new();
    let listed = Node::<ipc::Service>::list(&cfg, |state| {
        if let NodeState::Alive(view) = state {
            let (name, pid) = view.details().as_ref().map_or((String::new(), 0), |d| {
                (d.name().as_str().to_string(), d.process_id().value())
            });
            out.push(AliveNode { name, pid });
        }
        CallbackProgression::Continue
    });
    // A prefix without any node directory lists nothing; other failures are reported as such.
    listed.map_err(|e| IpcError::BadName(format!("cannot list the nodes of {prefix}: {e:?}")))?;
    Ok(out)
}

/// The files [`remove_residue`] would delete for `prefix` (for checks and diagnostics).
pub fn residue(prefix: &str) -> std::io::Result<Vec<std::path::PathBuf>> {
    let root = root_dir();
    let mut out = Vec::new();
    collect_prefixed(StdPath::new(SHM_DIR), prefix, false, &mut out)?;
    collect_prefixed(StdPath::new(&root), prefix, true, &mut out)?;
    Ok(out)
}

/// Whether this user owns the entry (another user's files of a colliding prefix are not ours).
fn is_mine(entry: &std::fs::DirEntry) -> bool {
    use std::os::unix::fs::MetadataExt;
    entry
        .metadata()
        .is_ok_and(|m| m.uid() == super::files::current_uid())
}

/// The run prefixes (`fm<hex>_`, [`crate::protocol::services::run_prefix`]) that have files of
/// this user in `/dev/shm` or the iceoryx2 root, with the age of their newest file.
pub fn run_prefixes_with_files() -> Vec<(String, std::time::Duration)> {
    let mut out: std::collections::BTreeMap<String, std::time::Duration> = Default::default();
    let mut visit = |dir: &StdPath| {
        let mut found = Vec::new();
        let _ = collect_matching(dir, 0, &mut found);
        for (name, age) in found {
            if let Some(p) = run_prefix_of(&name) {
                let e = out.entry(p).or_insert(age);
                *e = (*e).min(age);
            }
        }
    };
    visit(StdPath::new(SHM_DIR));
    visit(&root_dir());
    out.into_iter().collect()
}

/// `fm<hex>_` at the start of a file name.
fn run_prefix_of(name: &str) -> Option<String> {
    let rest = name.strip_prefix("fm")?;
    let end = rest.find('_')?;
    let id = &rest[..end];
    (!id.is_empty() && id.bytes().all(|b| b.is_ascii_hexdigit())).then(|| format!("fm{id}_"))
}

fn collect_matching(
    dir: &StdPath,
    depth: usize,
    out: &mut Vec<(String, std::time::Duration)>,
) -> std::io::Result<()> {
    for entry in std::fs::read_dir(dir)?.flatten() {
        let Ok(m) = entry.metadata() else { continue };
        if m.is_dir() {
            // /dev/shm is flat; the iceoryx2 root has `nodes/<id>/` and `services/`.
            if depth < 2 && dir != StdPath::new(SHM_DIR) {
                let _ = collect_matching(&entry.path(), depth + 1, out);
            }
        } else if is_mine(&entry) {
            let age = m
                .modified()
                .ok()
                .and_then(|t| t.elapsed().ok())
                .unwrap_or_default();
            out.push((entry.file_name().to_string_lossy().into_owned(), age));
        }
    }
    Ok(())
}

/// When no node of `prefix` is alive (none listed, or only dead ones), removes the records and
/// files of its dead nodes (iceoryx2's dead-node cleanup) and returns true; a prefix with a node
/// that is alive (or cannot be judged) is left untouched and gives false.
pub fn cleanup_dead_nodes(prefix: &str) -> Result<bool, IpcError> {
    let cfg = config_for_prefix(prefix)?;
    let list_err = |e| IpcError::BadName(format!("cannot list the nodes of {prefix}: {e:?}"));
    let mut alive = false;
    Node::<ipc::Service>::list(&cfg, |state| {
        if !matches!(state, NodeState::Dead(_)) {
            alive = true;
        }
        CallbackProgression::Continue
    })
    .map_err(list_err)?;
    if alive {
        return Ok(false);
    }
    Node::<ipc::Service>::list(&cfg, |state| {
        if let NodeState::Dead(view) = state {
            let _ = view.try_remove_stale_resources();
        }
        CallbackProgression::Continue
    })
    .map_err(list_err)?;
    Ok(true)
}

/// A prefix's files are reaped only once its newest file is this old: a run that is starting has
/// created files of its prefix but maybe not yet the node that marks it alive.
pub const REAP_MIN_AGE: std::time::Duration = std::time::Duration::from_secs(10);

/// Removes the files of every run prefix of this user (`fm<hex>_`) that is not in `live` (the
/// prefixes of runs whose orchestrator is alive), whose nodes are all dead and whose newest file is
/// older than `min_age`. Returns each prefix reaped with the number of files removed. Other users'
/// files are never touched (their iceoryx2 root is theirs; in `/dev/shm` only files of this user
/// are considered).
pub fn reap(live: &[String], min_age: std::time::Duration) -> Vec<(String, usize)> {
    let mut out = Vec::new();
    for (prefix, age) in run_prefixes_with_files() {
        if live.contains(&prefix) || age < min_age {
            continue;
        }
        // Counted as the files there were less those left: iceoryx2's own cleanup of the dead
        // nodes removes most of them before `remove_residue` sees the rest.
        let before = residue(&prefix).map_or(0, |v| v.len());
        if !matches!(cleanup_dead_nodes(&prefix), Ok(true)) {
            continue;
        }
        if remove_residue(&prefix).is_ok() {
            let left = residue(&prefix).map_or(0, |v| v.len());
            out.push((prefix, before.saturating_sub(left)));
        }
    }
    out
}

fn remove_prefixed(dir: &StdPath, prefix: &str, recurse: bool) -> std::io::Result<usize> {
    remove_prefixed_at(dir, prefix, recurse, 0)
}

/// Removes `prefix*` files below `dir`; a directory two or more levels below the starting one
/// (per-node directories such as `nodes/<node id>/`) is removed too once it is empty and something
/// of the prefix was removed from it. Shared top-level directories are never removed.
fn remove_prefixed_at(
    dir: &StdPath,
    prefix: &str,
    recurse: bool,
    depth: usize,
) -> std::io::Result<usize> {
    let entries = match std::fs::read_dir(dir) {
        Ok(e) => e,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(0),
        Err(e) => return Err(e),
    };
    let mut removed = 0;
    for entry in entries.flatten() {
        let Ok(ft) = entry.file_type() else { continue };
        let path = entry.path();
        if ft.is_dir() {
            if recurse {
                let inner = remove_prefixed_at(&path, prefix, recurse, depth + 1)?;
                if inner > 0 && depth >= 1 {
                    // Fails harmlessly when other runs' files are still in it.
                    let _ = std::fs::remove_dir(&path);
                }
                removed += inner;
            }
        } else if entry.file_name().to_string_lossy().starts_with(prefix) && is_mine(&entry) {
            match std::fs::remove_file(&path) {
                Ok(()) => removed += 1,
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
                Err(e) => return Err(e),
            }
        }
    }
    Ok(removed)
}

fn collect_prefixed(
    dir: &StdPath,
    prefix: &str,
    recurse: bool,
    out: &mut Vec<std::path::PathBuf>,
) -> std::io::Result<()> {
    let entries = match std::fs::read_dir(dir) {
        Ok(e) => e,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(()),
        Err(e) => return Err(e),
    };
    for entry in entries.flatten() {
        let Ok(ft) = entry.file_type() else { continue };
        if ft.is_dir() {
            if recurse {
                collect_prefixed(&entry.path(), prefix, recurse, out)?;
            }
        } else if entry.file_name().to_string_lossy().starts_with(prefix) && is_mine(&entry) {
            out.push(entry.path());
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn prefixes_with_path_characters_are_rejected() {
        assert!(config_for_prefix("fm1_").is_ok());
        assert!(config_for_prefix("").is_err());
        assert!(config_for_prefix("a/b").is_err());
        assert!(config_for_prefix(&"x".repeat(MAX_PREFIX_LEN + 1)).is_err());
    }

    #[test]
    fn the_global_mgmt_segment_of_a_prefix_is_owner_only_and_the_root_is_private() {
        use std::os::unix::fs::MetadataExt;
        let prefix = format!("fmg{}_", std::process::id());
        {
            let _node = node(&prefix, "mode-test").unwrap();
            let mgmt: Vec<_> = std::fs::read_dir(SHM_DIR)
                .unwrap()
                .flatten()
                .filter(|e| {
                    let n = e.file_name().to_string_lossy().into_owned();
                    n.starts_with(&prefix) && n.ends_with(GLOBAL_MGMT_SUFFIX)
                })
                .collect();
            assert_eq!(mgmt.len(), 1);
            assert_eq!(mgmt[0].metadata().unwrap().mode() & 0o777, 0o600);
            let root = std::fs::symlink_metadata(root_dir()).unwrap();
            assert_eq!(root.mode() & 0o777, 0o700);
        }
        remove_residue(&prefix).unwrap();
        assert!(residue(&prefix).unwrap().is_empty());
    }

    #[test]
    fn run_prefixes_are_recognised_by_their_pattern() {
        assert_eq!(run_prefix_of("fm1a2b_x.data"), Some("fm1a2b_".into()));
        assert_eq!(run_prefix_of("fmt12_x"), None);
        assert_eq!(run_prefix_of("fm_x"), None);
        assert_eq!(run_prefix_of("iox2_x"), None);
    }

    #[test]
    fn limits_scale_with_the_number_of_processes() {
        let l = Limits::for_processes(50);
        assert!(l.nodes > 50 && l.senders >= 50 && l.receivers >= 50 && l.buffer >= 50);
    }

    #[test]
    fn remove_residue_leaves_nothing_of_a_prefix_behind() {
        let prefix = format!("fmt{}_", std::process::id());
        {
            let node = node(&prefix, "residue-test").unwrap();
            let limits = Limits::for_processes(3);
            let svc = pubsub_with_limits(
                node.service_builder(&service_name("t/data").unwrap())
                    .publish_subscribe::<[u8]>(),
                &limits,
            )
            .create()
            .unwrap();
            let ev = event_with_limits(
                node.service_builder(&service_name("t/ev").unwrap()).event(),
                &limits,
            )
            .create()
            .unwrap();
            let publisher = svc
                .publisher_builder()
                .initial_max_slice_len(8)
                .create()
                .unwrap();
            let subscriber = svc.subscriber_builder().create().unwrap();
            let notifier = ev.notifier_builder().create().unwrap();
            let listener = ev.listener_builder().create().unwrap();
            publisher
                .loan_slice_uninit(8)
                .unwrap()
                .write_from_slice(&[1u8; 8])
                .send()
                .unwrap();
            notifier.notify().unwrap();
            assert!(subscriber.receive().unwrap().is_some());
            listener.try_wait(|_| {}).unwrap();
            eprintln!("while running: {:?}", residue(&prefix).unwrap());
        }
        eprintln!("after drop: {:?}", residue(&prefix).unwrap());
        remove_residue(&prefix).unwrap();
        assert!(residue(&prefix).unwrap().is_empty());
    }
}
