//! Discoverable runs: `formation run` writes `<runs dir>/<id>.json` when it starts, refreshes its
//! progress about twice a second, and removes it at the end. `ps`, `inspect` and `inject` read it;
//! entries whose orchestrator is gone are deleted when listed.
//!
//! The runs directory is `$FORMATION_RUNS_DIR` if set, else `$XDG_RUNTIME_DIR/formation/runs`,
//! else `/tmp/formation-runs-<uid>`.

use super::procstat;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

/// One process of a run.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct ProcessEntry {
    /// orchestrator, plant, leader or agent.
    pub role: String,
    /// Agent id, 1-based (agents only).
    pub agent: Option<usize>,
    /// Process id.
    pub pid: u32,
}

/// The registry file of a run.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct RunRecord {
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
}

impl RunRecord {
    /// Pid of the orchestrator.
    pub fn orchestrator_pid(&self) -> u32 {
        self.processes.first().map_or(0, |p| p.pid)
    }

    /// True while the orchestrator that wrote the record is running.
    pub fn is_live(&self) -> bool {
        procstat::read(self.orchestrator_pid())
            .is_some_and(|s| s.alive() && s.start_ticks == self.orchestrator_start_ticks)
    }
}

/// Seconds since the Unix epoch.
pub fn unix_now() -> f64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0.0, |d| d.as_secs_f64())
}

/// The runs directory (see the module documentation).
pub fn runs_dir() -> PathBuf {
    if let Some(d) = std::env::var_os("FORMATION_RUNS_DIR").filter(|d| !d.is_empty()) {
        return PathBuf::from(d);
    }
    if let Some(d) = std::env::var_os("XDG_RUNTIME_DIR").filter(|d| !d.is_empty()) {
        if Path::new(&d).is_dir() {
            return Path::new(&d).join("formation").join("runs");
        }
    }
    // SAFETY: getuid has no preconditions.
    let uid = unsafe { libc::getuid() };
    PathBuf::from(format!("/tmp/formation-runs-{uid}"))
}

fn write_atomically(path: &Path, rec: &RunRecord) -> std::io::Result<()> {
    let tmp = path.with_extension("json.tmp");
    let text = serde_json::to_string_pretty(rec).map_err(std::io::Error::other)?;
    std::fs::write(&tmp, text)?;
    std::fs::rename(&tmp, path)
}

/// Every live run, sorted by start time; stale records (orchestrator gone) are deleted.
pub fn list() -> Vec<RunRecord> {
    let dir = runs_dir();
    let Ok(entries) = std::fs::read_dir(&dir) else {
        return Vec::new();
    };
    let mut runs = Vec::new();
    for e in entries.flatten() {
        let path = e.path();
        if path.extension().and_then(|x| x.to_str()) != Some("json") {
            continue;
        }
        let rec: Option<RunRecord> = std::fs::read_to_string(&path)
            .ok()
            .and_then(|t| serde_json::from_str(&t).ok());
        match rec {
            Some(r) if r.is_live() => runs.push(r),
            _ => {
                let _ = std::fs::remove_file(&path);
            }
        }
    }
    runs.sort_by(|a, b| a.started_unix_s.total_cmp(&b.started_unix_s));
    runs
}

/// The run `id`, or the only live run when `id` is `None`; a clear error otherwise.
pub fn find(id: Option<&str>) -> Result<RunRecord, String> {
    let runs = list();
    match id {
        Some(id) => runs
            .into_iter()
            .find(|r| r.id == id)
            .ok_or_else(|| format!("no running run with id '{id}' (see `formation ps`)")),
        None => match runs.len() {
            0 => Err("no run is running (start one with `formation run`)".into()),
            1 => Ok(runs.into_iter().next().expect("one run")),
            k => Err(format!(
                "{k} runs are running ({}): choose one with --run ID",
                runs.iter()
                    .map(|r| r.id.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
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
    pub fn create(mut rec: RunRecord) -> Result<Registration, String> {
        let dir = runs_dir();
        std::fs::create_dir_all(&dir)
            .map_err(|e| format!("cannot create {}: {e}", dir.display()))?;
        rec.orchestrator_start_ticks = procstat::read(std::process::id())
            .map(|s| s.start_ticks)
            .unwrap_or(0);
        let path = dir.join(format!("{}.json", rec.id));
        write_atomically(&path, &rec)
            .map_err(|e| format!("cannot write {}: {e}", path.display()))?;
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
