//! Discoverable runs: `formation run` writes `<runs dir>/<id>.json` when it starts, refreshes its
//! progress about twice a second, and removes it at the end. `ps`, `run`, `inspect` and `inject` read
//! the folder and delete the records of runs that are provably over (see [`list`]).
//!
//! The runs directory is `$FORMATION_RUNS_DIR` if set, else `$XDG_RUNTIME_DIR/formation/runs`,
//! else `/tmp/formation-runs-<uid>`. It is created with mode 0700; one that is a symbolic link, is
//! not owned by the user or is group- or world-writable is refused (exit 2), since whoever can
//! write to it could plant files there. Records are written with mode 0600 into a new file
//! (`O_CREAT | O_EXCL | O_NOFOLLOW`: a planted symbolic link is never followed) and renamed over
//! the record.

use super::procstat;
use formation_config::node::files;
use serde::{Deserialize, Serialize};
use std::io::Write;
use std::os::unix::fs::{DirBuilderExt, MetadataExt};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

/// The `format` of every record this program writes: with the file name (`<id>.json`) and the
/// owner, what makes a file of the runs folder recognisably ours.
pub const RECORD_FORMAT: &str = "formation-run-record/1";

/// Largest record read (a record of N = 64 agents is ~8 KiB).
const MAX_RECORD_BYTES: u64 = 1 << 20;

/// The host of a process on the launching machine (`formation_net::cluster::LAUNCHER`): what
/// `--place IDS@local` names and what a record written without hosts means.
pub const LOCAL_HOST: &str = "local";

fn local_host() -> String {
    LOCAL_HOST.to_string()
}

/// One process of a run.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct ProcessEntry {
    /// orchestrator, plant, leader or agent.
    pub role: String,
    /// Agent id, 1-based (agents only).
    pub agent: Option<usize>,
    /// Process id on its host (for a process on another host, the pid its daemon reported).
    pub pid: u32,
    /// The host it runs on: [`LOCAL_HOST`] for the launching machine, else the name of the
    /// `formation host` daemon that started it. Records written without the field are read as
    /// [`LOCAL_HOST`].
    #[serde(default = "local_host")]
    pub host: String,
}

impl ProcessEntry {
    /// True when it runs on the launching machine, where `/proc` tells its state and CPU time.
    pub fn is_local(&self) -> bool {
        self.host == LOCAL_HOST
    }
}

/// The registry file of a run.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct RunRecord {
    /// [`RECORD_FORMAT`].
    #[serde(default)]
    pub format: String,
    /// Run id.
    pub id: String,
    /// iceoryx2 prefix.
    pub prefix: String,
    /// Output directory (absolute).
    pub out_dir: PathBuf,
    /// Scenario name.
    pub scenario: String,
    /// Controller variant.
    pub variant: String,
    /// Number of agents N.
    pub n_agents: usize,
    /// Steps of the whole run.
    pub steps: u64,
    /// Step, s.
    pub dt_s: f64,
    /// Start of the orchestrator after boot, clock ticks (guards against pid reuse).
    pub orchestrator_start_ticks: u64,
    /// Wall-clock start, seconds since the Unix epoch.
    pub started_unix_s: f64,
    /// Every process of the run, orchestrator first.
    pub processes: Vec<ProcessEntry>,
    /// Steps recorded so far (lockstep: every process is within a few dozen steps of it).
    pub last_step: u64,
    /// Recorded steps per wall-clock second over the last refresh interval.
    pub steps_per_s: f64,
    /// Owner of the record file (not stored: read from the file).
    #[serde(skip)]
    pub owner_uid: u32,
}

impl RunRecord {
    /// Pid of the orchestrator.
    pub fn orchestrator_pid(&self) -> u32 {
        self.processes.first().map_or(0, |p| p.pid)
    }

    /// True while the orchestrator that wrote the record is running: its pid exists, is not a
    /// zombie, started at the recorded time (not a reused pid) and belongs to the record's owner.
    pub fn is_live(&self) -> bool {
        let pid = self.orchestrator_pid();
        let same_owner =
            std::fs::metadata(format!("/proc/{pid}")).is_ok_and(|m| m.uid() == self.owner_uid);
        same_owner
            && procstat::read(pid)
                .is_some_and(|s| s.alive() && s.start_ticks == self.orchestrator_start_ticks)
    }

    /// True when the record belongs to another user.
    pub fn is_foreign(&self) -> bool {
        self.owner_uid != files::current_uid()
    }

    /// The refusal of a client command (`inspect`, `inject`) on another user's run: its iceoryx2
    /// files are not this user's to open.
    pub fn permission_error(&self, what: &str) -> String {
        format!(
            "permission denied: run {} belongs to {}, not to {}; only its owner can {what} it",
            self.id,
            files::user_label(self.owner_uid),
            files::user_label(files::current_uid())
        )
    }
}

/// Seconds since the Unix epoch.
pub fn unix_now() -> f64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0.0, |d| d.as_secs_f64())
}

/// The runs directory (see the module documentation), unchecked.
pub fn runs_dir() -> PathBuf {
    if let Some(d) = std::env::var_os("FORMATION_RUNS_DIR").filter(|d| !d.is_empty()) {
        return PathBuf::from(d);
    }
    if let Some(d) = std::env::var_os("XDG_RUNTIME_DIR").filter(|d| !d.is_empty()) {
        if Path::new(&d).is_dir() {
            return Path::new(&d).join("formation").join("runs");
        }
    }
    PathBuf::from(format!("/tmp/formation-runs-{}", files::current_uid()))
}

/// Why the runs folder or a run's record cannot be used, or which run is meant is unclear.
#[derive(Debug, thiserror::Error)]
pub enum RegistryError {
    /// The runs folder cannot be created.
    #[error("cannot create the runs folder {}: {source}", dir.display())]
    Create {
        /// The runs folder.
        dir: PathBuf,
        /// The file system's error.
        source: std::io::Error,
    },
    /// The runs folder cannot be looked at.
    #[error("cannot use the runs folder {}: {source}", dir.display())]
    Unusable {
        /// The runs folder.
        dir: PathBuf,
        /// The file system's error.
        source: std::io::Error,
    },
    /// The runs folder is not this user's alone.
    #[error(
        "refusing the runs folder {}: {why} (set FORMATION_RUNS_DIR to a folder of your own \
         with mode 0700)",
        dir.display()
    )]
    Refused {
        /// The runs folder.
        dir: PathBuf,
        /// Why.
        why: files::DirProblem,
    },
    /// The runs folder cannot be listed.
    #[error("cannot read {}: {source}", dir.display())]
    Read {
        /// The runs folder.
        dir: PathBuf,
        /// The file system's error.
        source: std::io::Error,
    },
    /// A run's record cannot be written.
    #[error("cannot write {}: {source}", path.display())]
    Write {
        /// The record.
        path: PathBuf,
        /// The file system's error.
        source: std::io::Error,
    },
    /// `--run ID` names no running run.
    #[error("no running run with id '{0}' (see `formation ps`)")]
    NoSuchRun(String),
    /// No run is running.
    #[error("no run is running (start one with `formation run`)")]
    NoRun,
    /// Several runs are running and none was chosen (their ids).
    #[error("{} runs are running ({}): choose one with --run ID", .0.len(), .0.join(", "))]
    Several(Vec<String>),
}

/// Why `dir` must not be used as the runs folder, if it must not: it is not a directory (a
/// symbolic link counts as not one), belongs to another user, or others may write to it.
pub fn check_dir(dir: &Path) -> Result<(), RegistryError> {
    std::fs::symlink_metadata(dir).map_err(|source| RegistryError::Unusable {
        dir: dir.to_path_buf(),
        source,
    })?;
    files::check_private_dir(dir).map_err(|why| RegistryError::Refused {
        dir: dir.to_path_buf(),
        why,
    })
}

/// The runs directory, checked ([`check_dir`]); created with mode 0700 when `create` is set,
/// else `None` when it does not exist.
pub fn checked_runs_dir(create: bool) -> Result<Option<PathBuf>, RegistryError> {
    let dir = runs_dir();
    if create {
        std::fs::DirBuilder::new()
            .recursive(true)
            .mode(0o700)
            .create(&dir)
            .map_err(|source| RegistryError::Create {
                dir: dir.clone(),
                source,
            })?;
    } else if std::fs::symlink_metadata(&dir).is_err() {
        return Ok(None);
    }
    check_dir(&dir)?;
    Ok(Some(dir))
}

/// Writes `rec` to `path` through a new file `<path>.tmp` (create-new, no symbolic link followed,
/// mode 0600) renamed over `path`.
fn write_atomically(path: &Path, rec: &RunRecord) -> std::io::Result<()> {
    let mut tmp_name = path.as_os_str().to_os_string();
    tmp_name.push(".tmp");
    let tmp = PathBuf::from(tmp_name);
    let text = serde_json::to_string_pretty(rec).map_err(std::io::Error::other)?;
    let mut f = files::create_new(&tmp, 0o600)?;
    let written = f
        .write_all(text.as_bytes())
        .and_then(|_| f.flush())
        .and_then(|_| std::fs::rename(&tmp, path));
    if written.is_err() {
        // The file was created above by this process (create-new), so it is ours to remove.
        let _ = std::fs::remove_file(&tmp);
    }
    written
}

/// True for a run id as `formation run` makes them (a valid part of an iceoryx2 prefix).
fn is_run_id(id: &str) -> bool {
    !id.is_empty()
        && id.len() <= 24
        && id
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b == b'_' || b == b'-')
}

/// What a file of the runs folder is.
#[derive(Debug)]
enum Entry {
    /// A record of ours (or, owned by another user, a record of theirs) whose run is live.
    Live(Box<RunRecord>),
    /// A record or temporary record this program wrote, of a run that is over: safe to delete.
    Stale,
    /// Anything else: never touched.
    Foreign,
}

/// Classifies `path`: a record is recognised by its name (`<id>.json` or `<id>.json.tmp`), its
/// content (a [`RunRecord`] of [`RECORD_FORMAT`] whose id is that of the name) and, to be
/// deleted, its owner (this user) and a dead orchestrator.
fn classify(path: &Path) -> Entry {
    let Some(name) = path.file_name().and_then(|n| n.to_str()) else {
        return Entry::Foreign;
    };
    let (stem, tmp) = if let Some(s) = name.strip_suffix(".json.tmp") {
        (s, true)
    } else if let Some(s) = name.strip_suffix(".json") {
        (s, false)
    } else {
        return Entry::Foreign;
    };
    if !is_run_id(stem) {
        return Entry::Foreign;
    }
    let Ok(m) = std::fs::symlink_metadata(path) else {
        return Entry::Foreign;
    };
    if !m.file_type().is_file() || m.len() > MAX_RECORD_BYTES {
        return Entry::Foreign;
    }
    let rec: Option<RunRecord> = files::open_read_nofollow(path)
        .ok()
        .and_then(|t| serde_json::from_str(&t).ok());
    let Some(mut rec) = rec else {
        return Entry::Foreign;
    };
    if rec.format != RECORD_FORMAT || rec.id != stem {
        return Entry::Foreign;
    }
    rec.owner_uid = m.uid();
    match (rec.is_live(), tmp, rec.is_foreign()) {
        (true, false, _) => Entry::Live(Box::new(rec)),
        (true, true, _) | (false, _, true) => Entry::Foreign,
        (false, _, false) => Entry::Stale,
    }
}

/// Every live run, sorted by start time. Records of runs that are over (orchestrator gone) which
/// this program wrote are deleted; nothing else in the folder is touched. Fails (exit 2) on a
/// runs folder that must not be used ([`check_dir`]).
pub fn list() -> Result<Vec<RunRecord>, RegistryError> {
    let Some(dir) = checked_runs_dir(false)? else {
        return Ok(Vec::new());
    };
    let entries = std::fs::read_dir(&dir).map_err(|source| RegistryError::Read {
        dir: dir.clone(),
        source,
    })?;
    let mut runs = Vec::new();
    for e in entries.flatten() {
        let path = e.path();
        match classify(&path) {
            Entry::Live(r) => runs.push(*r),
            Entry::Stale => {
                let _ = std::fs::remove_file(&path);
            }
            Entry::Foreign => {}
        }
    }
    runs.sort_by(|a, b| a.started_unix_s.total_cmp(&b.started_unix_s));
    Ok(runs)
}

/// The record of run `id` as it is now (its processes may have moved or been replaced since it
/// was found), `None` once the run is over. Reads that one record only.
pub fn reload(id: &str) -> Option<RunRecord> {
    if !is_run_id(id) {
        return None;
    }
    match classify(&runs_dir().join(format!("{id}.json"))) {
        Entry::Live(r) => Some(*r),
        _ => None,
    }
}

/// The run `id`, or the only live run when `id` is `None`; a clear error otherwise.
pub fn find(id: Option<&str>) -> Result<RunRecord, RegistryError> {
    let runs = list()?;
    match id {
        Some(id) => runs
            .into_iter()
            .find(|r| r.id == id)
            .ok_or_else(|| RegistryError::NoSuchRun(id.to_string())),
        None => match runs.len() {
            0 => Err(RegistryError::NoRun),
            1 => Ok(runs.into_iter().next().expect("one run")),
            _ => Err(RegistryError::Several(
                runs.into_iter().map(|r| r.id).collect(),
            )),
        },
    }
}

/// The registration of the running run: refreshed by [`Registration::update`], removed on drop.
pub struct Registration {
    path: PathBuf,
    rec: RunRecord,
    last: Instant,
    last_step: u64,
}

/// How often the progress in the record is refreshed.
const REFRESH: Duration = Duration::from_millis(500);

impl Registration {
    /// Writes the record of this run (the orchestrator must be the first process).
    pub fn create(mut rec: RunRecord) -> Result<Registration, RegistryError> {
        let dir = checked_runs_dir(true)?.unwrap_or_else(runs_dir);
        rec.format = RECORD_FORMAT.to_string();
        rec.owner_uid = files::current_uid();
        rec.orchestrator_start_ticks = procstat::read(std::process::id())
            .map(|s| s.start_ticks)
            .unwrap_or(0);
        let path = dir.join(format!("{}.json", rec.id));
        write_atomically(&path, &rec).map_err(|source| RegistryError::Write {
            path: path.clone(),
            source,
        })?;
        Ok(Registration {
            path,
            rec,
            last: Instant::now(),
            last_step: 0,
        })
    }

    /// Path of the record.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Keeps the record's pids and hosts those of the running children (`(pid, host)` of child
    /// k, in the order after the orchestrator; host `None`: this machine): a replaced agent
    /// process is listed with its new pid and host at once.
    pub fn follow_processes<'a>(&mut self, procs: impl Iterator<Item = (u32, Option<&'a str>)>) {
        let mut changed = false;
        for (entry, (pid, host)) in self.rec.processes.iter_mut().skip(1).zip(procs) {
            let host = host.unwrap_or(LOCAL_HOST);
            if entry.pid != pid || entry.host != host {
                entry.pid = pid;
                entry.host = host.to_string();
                changed = true;
            }
        }
        if changed {
            // Best effort, as for the progress.
            let _ = write_atomically(&self.path, &self.rec);
        }
    }

    /// Refreshes the progress (at most every 500 ms; cheap otherwise).
    pub fn update(&mut self, recorded: u64) {
        let dt = self.last.elapsed();
        if dt < REFRESH {
            return;
        }
        self.rec.steps_per_s = (recorded - self.last_step.min(recorded)) as f64 / dt.as_secs_f64();
        self.rec.last_step = recorded;
        self.last_step = recorded;
        self.last = Instant::now();
        // Best effort: a missing refresh only makes `ps` show older progress.
        let _ = write_atomically(&self.path, &self.rec);
    }
}

impl Drop for Registration {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.path);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::os::unix::fs::PermissionsExt;

    fn temp(tag: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("fm-registry-{}-{tag}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::DirBuilder::new().mode(0o700).create(&d).unwrap();
        d
    }

    fn record(id: &str, pid: u32, start_ticks: u64) -> RunRecord {
        RunRecord {
            format: RECORD_FORMAT.into(),
            id: id.into(),
            prefix: format!("fm{id}_"),
            out_dir: PathBuf::from("/nonexistent"),
            scenario: "paper".into(),
            variant: "proposed".into(),
            n_agents: 1,
            steps: 1,
            dt_s: 0.001,
            orchestrator_start_ticks: start_ticks,
            started_unix_s: 0.0,
            processes: vec![ProcessEntry {
                role: "orchestrator".into(),
                agent: None,
                pid,
                host: LOCAL_HOST.into(),
            }],
            last_step: 0,
            steps_per_s: 0.0,
            owner_uid: files::current_uid(),
        }
    }

    #[test]
    fn a_record_written_without_hosts_lists_every_process_on_this_machine() {
        let mut v = serde_json::to_value(record("old1", 1, 0)).unwrap();
        v["processes"][0].as_object_mut().unwrap().remove("host");
        let back: RunRecord = serde_json::from_value(v).unwrap();
        assert_eq!(back.processes[0].host, LOCAL_HOST);
        assert!(back.processes[0].is_local());
    }

    #[test]
    fn a_replaced_process_is_followed_to_its_new_pid_and_host() {
        let d = temp("follow");
        let mut rec = record("fol1", std::process::id(), 0);
        rec.processes.push(ProcessEntry {
            role: "agent".into(),
            agent: Some(1),
            pid: 4242,
            host: "b".into(),
        });
        let path = d.join("fol1.json");
        write_atomically(&path, &rec).unwrap();
        let mut reg = Registration {
            path: path.clone(),
            rec,
            last: Instant::now(),
            last_step: 0,
        };
        // Agent 1 lost with host b, taken over on this machine as pid 77.
        reg.follow_processes([(77, None)].into_iter());
        let back: RunRecord =
            serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
        assert_eq!(back.processes[1].pid, 77);
        assert_eq!(back.processes[1].host, LOCAL_HOST);
        reg.follow_processes([(78, Some("c"))].into_iter());
        let back: RunRecord =
            serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
        assert_eq!(
            (back.processes[1].pid, back.processes[1].host.as_str()),
            (78, "c")
        );
        drop(reg);
        let _ = std::fs::remove_dir_all(&d);
    }

    #[cfg(feature = "multihost")]
    #[test]
    fn the_local_host_is_the_name_placements_give_the_launching_machine() {
        assert_eq!(LOCAL_HOST, formation_net::cluster::LAUNCHER);
    }

    #[test]
    fn a_symbolic_link_planted_at_the_temporary_name_is_not_followed() {
        let d = temp("symlink");
        let victim = d.join("victim");
        std::fs::write(&victim, "precious").unwrap();
        std::fs::set_permissions(&victim, std::fs::Permissions::from_mode(0o600)).unwrap();
        let path = d.join("abc1.json");
        std::os::unix::fs::symlink(&victim, d.join("abc1.json.tmp")).unwrap();
        assert!(write_atomically(&path, &record("abc1", 1, 0)).is_err());
        assert_eq!(std::fs::read_to_string(&victim).unwrap(), "precious");
        // Without the planted link the record is written, mode 0600.
        std::fs::remove_file(d.join("abc1.json.tmp")).unwrap();
        write_atomically(&path, &record("abc1", 1, 0)).unwrap();
        let m = std::fs::symlink_metadata(&path).unwrap();
        assert!(m.is_file());
        assert_eq!(m.mode() & 0o777, 0o600);
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn runs_folders_others_may_write_to_or_own_are_refused_naming_why() {
        let d = temp("dir");
        assert!(check_dir(&d).is_ok());
        std::fs::set_permissions(&d, std::fs::Permissions::from_mode(0o777)).unwrap();
        let e = check_dir(&d).unwrap_err().to_string();
        assert!(
            e.contains(&d.display().to_string()) && e.contains("world-writable"),
            "{e}"
        );
        std::fs::set_permissions(&d, std::fs::Permissions::from_mode(0o770)).unwrap();
        assert!(check_dir(&d)
            .unwrap_err()
            .to_string()
            .contains("group-writable"));
        std::fs::set_permissions(&d, std::fs::Permissions::from_mode(0o700)).unwrap();
        let link = d.with_extension("link");
        let _ = std::fs::remove_file(&link);
        std::os::unix::fs::symlink(&d, &link).unwrap();
        assert!(check_dir(&link)
            .unwrap_err()
            .to_string()
            .contains("symbolic link"));
        let _ = std::fs::remove_file(&link);
        // Another owner (needs root, as in CI's container; skipped otherwise).
        let c = std::ffi::CString::new(d.as_os_str().as_encoded_bytes()).unwrap();
        // SAFETY: chown on a valid C string path.
        if unsafe { libc::chown(c.as_ptr(), 65534, 65534) } == 0 {
            let e = check_dir(&d).unwrap_err().to_string();
            assert!(e.contains("uid 65534"), "{e}");
        }
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn only_our_records_of_dead_runs_are_stale_and_nothing_else_is_touched() {
        let d = temp("classify");
        std::fs::write(d.join("package.json"), r#"{"name":"x"}"#).unwrap();
        std::fs::write(d.join("other.json"), r#"{"id":"other"}"#).unwrap();
        std::fs::write(d.join("notes.txt"), "x").unwrap();
        let me = std::process::id();
        let ticks = procstat::read(me).unwrap().start_ticks;
        write_atomically(&d.join("live1.json"), &record("live1", me, ticks)).unwrap();
        write_atomically(&d.join("dead1.json"), &record("dead1", 4_194_300, 1)).unwrap();
        // Our pid but another start time: the pid was reused, the run is over.
        write_atomically(&d.join("reuse1.json"), &record("reuse1", me, ticks + 1)).unwrap();
        // A record whose name is not its id is not ours.
        write_atomically(&d.join("renamed.json"), &record("dead2", 4_194_300, 1)).unwrap();
        let kind = |n: &str| format!("{:?}", classify(&d.join(n)));
        assert!(kind("live1.json").starts_with("Live"));
        assert_eq!(kind("dead1.json"), "Stale");
        assert_eq!(kind("reuse1.json"), "Stale");
        for n in ["package.json", "other.json", "notes.txt", "renamed.json"] {
            assert_eq!(kind(n), "Foreign", "{n}");
        }
        let _ = std::fs::remove_dir_all(&d);
    }
}
