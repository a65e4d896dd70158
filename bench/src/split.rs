//! The lockstep split case of `formation bench --transports zenoh` (cargo feature `multihost`):
//! `formation run` of the paper scenario in lockstep with agents 4 and 5 on a second host, timed
//! per step by its own orchestrator, so that it can be set against the bare Zenoh fan-out of the
//! same placement (`bench::zenoh`) in the same round.
//!
//! The second host is a `formation host` daemon the bench starts on a free port of 127.0.0.1.
//! A daemon sharing the launcher's `/dev/shm` would be co-located and bridge nothing
//! (`formation_net::colocate`), so the daemon runs in a mount namespace of its own (`unshare --mount`,
//! with `--user --map-root-user` when not root) with a fresh tmpfs on /dev/shm, and with its own
//! runtime folder (`XDG_RUNTIME_DIR`: its iceoryx2 root and its run folders). No shared memory
//! crosses between the two "hosts"; every cross-host message goes through the bridges and Zenoh
//! over loopback, TCP with a user and password or mutual TLS over TCP or QUIC (`--zenoh-link`, credentials made for
//! the bench: [`super::secure`]). They still share one kernel and its CPUs, and the link has no
//! latency of its own.

use super::lockstep::{self, row_as};
use super::row::Row;
use super::secure::Secured;
use crate::error::{CaseError, ResultExt};
use formation_net::bench::{SPLIT_AGENTS, SPLIT_HOST};
use formation_runtime::WARMUP_STEPS;
use std::ffi::OsString;
use std::io::Read;
use std::os::unix::fs::{DirBuilderExt, PermissionsExt};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// Expected pace of the split run, steps per wall-clock second, to size it to the time budget
/// (1.6 k steps/s measured on a quiet 2-vCPU VM, docs/multi-host.md). A slower machine just
/// takes longer.
const EXPECTED_SPLIT_STEPS_PER_S: f64 = 2_000.0;

/// Longest the daemon may take to listen.
const DAEMON_START: Duration = Duration::from_secs(20);

/// Longest the daemon gets to exit after SIGTERM before SIGKILL.
const DAEMON_STOP: Duration = Duration::from_secs(10);

/// Run in the daemon's new mount namespace before it starts: its own /dev/shm.
const PRIVATE_SHM: &str = "mount -t tmpfs -o mode=1777 tmpfs /dev/shm || exit 97\nexec \"$@\"";

/// The placement as `formation run --place` takes it (`4,5@b`).
pub fn place_arg() -> String {
    let ids: Vec<String> = SPLIT_AGENTS.iter().map(|a| a.to_string()).collect();
    format!("{}@{SPLIT_HOST}", ids.join(","))
}

/// What [`run`] measured.
pub struct Split {
    /// The run's step timing.
    pub row: Row,
    /// The launcher's iceoryx2 prefix of the run (from its stderr).
    pub prefix: Option<String>,
}

/// A `formation host` daemon in its own mount namespace; stopped (SIGTERM, then SIGKILL) and
/// reaped on drop.
struct Daemon {
    child: Child,
    log: PathBuf,
}

impl Daemon {
    fn start(
        exe: &Path,
        endpoint: &str,
        creds: &[String],
        dir: &Path,
    ) -> Result<Daemon, CaseError> {
        let runtime = dir.join("runtime");
        std::fs::DirBuilder::new()
            .recursive(true)
            .mode(0o700)
            .create(&runtime)
            .map_err(|e| CaseError::file(&runtime, e))?;
        std::fs::set_permissions(&runtime, std::fs::Permissions::from_mode(0o700))
            .map_err(|e| CaseError::file(&runtime, e))?;
        let log = dir.join("daemon.log");
        let file = std::fs::File::create(&log).map_err(|e| CaseError::file(&log, e))?;
        let mut cmd = Command::new("unshare");
        // SAFETY: geteuid has no preconditions.
        if unsafe { libc::geteuid() } != 0 {
            cmd.args(["--user", "--map-root-user"]);
        }
        cmd.args([
            "--mount",
            "--propagation",
            "private",
            "sh",
            "-c",
            PRIVATE_SHM,
            "sh",
        ])
        .arg(exe)
        .args(["host", "--name", SPLIT_HOST, "--listen", endpoint])
        .args(creds)
        .env("XDG_RUNTIME_DIR", &runtime)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(file);
        super::procs::die_with_bench(&mut cmd, std::process::id() as i32);
        let child = cmd
            .spawn()
            .ctx("cannot start `unshare` for the host daemon")?;
        let mut d = Daemon { child, log };
        let t0 = Instant::now();
        loop {
            let text = std::fs::read_to_string(&d.log).unwrap_or_default();
            if text.contains("listening on") {
                return Ok(d);
            }
            let last = || text.lines().last().unwrap_or("").trim().to_string();
            if let Ok(Some(st)) = d.child.try_wait() {
                let why = if st.code() == Some(97) {
                    "cannot mount a private /dev/shm".to_string()
                } else {
                    last()
                };
                return Err(CaseError::DaemonExited { status: st, why });
            }
            if t0.elapsed() > DAEMON_START || super::procs::aborted() {
                return Err(CaseError::DaemonSlow(last()));
            }
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// The files in the daemon's own /dev/shm (seen through /proc/<pid>/root).
    fn shm_files(&self) -> Vec<String> {
        let dir = PathBuf::from(format!("/proc/{}/root/dev/shm", self.child.id()));
        std::fs::read_dir(dir)
            .map(|rd| {
                rd.flatten()
                    .map(|e| e.file_name().to_string_lossy().into_owned())
                    .collect()
            })
            .unwrap_or_default()
    }
}

impl Drop for Daemon {
    fn drop(&mut self) {
        // SAFETY: kill(2) on our own child, not reaped yet.
        unsafe { libc::kill(self.child.id() as libc::pid_t, libc::SIGTERM) };
        let t0 = Instant::now();
        while t0.elapsed() < DAEMON_STOP {
            if let Ok(Some(_)) = self.child.try_wait() {
                return;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// The iceoryx2 prefix `formation run` names on its stderr.
fn prefix_of(stderr: &str) -> Option<String> {
    let rest = stderr.split("iceoryx2 prefix ").nth(1)?;
    Some(rest.split([',', ' ', '\n']).next()?.trim().to_string())
}

/// Runs the split lockstep for about `seconds` of steady state (plus the warm-up) in `scratch`.
pub fn run(seconds: f64, scratch: &Path, sec: &Secured) -> Result<Split, CaseError> {
    let exe = std::env::current_exe().ctx("cannot locate formation")?;
    let dir = scratch.join("split");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).map_err(|e| CaseError::file(&dir, e))?;
    let result = run_in(&exe, seconds, &dir, sec);
    let _ = std::fs::remove_dir_all(&dir);
    result
}

fn run_in(exe: &Path, seconds: f64, dir: &Path, sec: &Secured) -> Result<Split, CaseError> {
    let endpoint = sec.free_endpoint()?;
    let daemon = Daemon::start(exe, &endpoint, &sec.args(SPLIT_HOST), dir)?;
    let out = dir.join("run");
    let args: Vec<OsString> = [
        "--hosts".to_string(),
        SPLIT_HOST.to_string(),
        "--place".to_string(),
        place_arg(),
        "--connect".to_string(),
        endpoint,
    ]
    .into_iter()
    .chain(sec.args(formation_net::cluster::LAUNCHER))
    .map(OsString::from)
    .collect();
    let steps = WARMUP_STEPS as f64 + seconds * EXPECTED_SPLIT_STEPS_PER_S;
    let result = lockstep::run_formation(args, steps, &out);
    let left = daemon.shm_files();
    let (summary, stderr) = result.map_err(|e| {
        let mut log = String::new();
        let _ = std::fs::File::open(&daemon.log).and_then(|mut f| f.read_to_string(&mut log));
        let last = log.lines().last().unwrap_or("").trim().to_string();
        CaseError::Split {
            run: Box::new(e),
            last,
        }
    })?;
    drop(daemon);
    if !left.is_empty() {
        return Err(CaseError::Residue(left));
    }
    let n = formation_net::bench::paper_split().agent_hosts.len();
    let wait = format!("{}{}", super::versus::SPLIT_WAIT, place_arg());
    let row = row_as((super::versus::ZENOH, &wait), n, &summary["timing"]).ok_or_else(|| {
        CaseError::NoTiming {
            what: "the split run's summary.json".to_string(),
        }
    })?;
    Ok(Split {
        row,
        prefix: prefix_of(&stderr),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_placement_argument_names_the_split_agents_and_host() {
        assert_eq!(place_arg(), "4,5@b");
    }

    #[test]
    fn the_run_prefix_is_read_from_the_run_line() {
        let err = "x\nformation run: id 1a2b, iceoryx2 prefix fm1a2b_, 5 agents, 3000 steps\n";
        assert_eq!(prefix_of(err).as_deref(), Some("fm1a2b_"));
        assert_eq!(prefix_of("nothing"), None);
    }
}
