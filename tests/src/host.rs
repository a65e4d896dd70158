//! `formation host` daemons started by the tests on this machine, and commands that find them
//! (their runtime folder, `XDG_RUNTIME_DIR`, holds each daemon's default socket).

use crate::bin;
use std::os::unix::fs::PermissionsExt;
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

/// Daemons started by this test process (each logs to a file of its own).
static STARTED: AtomicUsize = AtomicUsize::new(0);

/// A `formation host` started by a test; killed and reaped on drop.
pub struct Daemon {
    /// The daemon process.
    pub child: Child,
    /// Its standard error.
    pub log: PathBuf,
}

impl Daemon {
    /// Starts `formation host ARGS` with runtime folder `rt`; returns once it listens.
    pub fn start(rt: &Path, args: &[&str]) -> Daemon {
        Daemon::start_as(rt, args, None)
    }

    /// [`Daemon::start`] as user and group `uid` when given (the test runs as root).
    pub fn start_as(rt: &Path, args: &[&str], uid: Option<u32>) -> Daemon {
        let log = rt
            .parent()
            .expect("a runtime folder has a parent")
            .join(format!(
                "daemon-{}.log",
                STARTED.fetch_add(1, Ordering::Relaxed)
            ));
        let mut cmd = Command::new(bin("formation"));
        cmd.arg("host")
            .args(args)
            .env("XDG_RUNTIME_DIR", rt)
            .env_remove("CARGO")
            .stdout(Stdio::null())
            .stderr(std::fs::File::create(&log).unwrap());
        if let Some(u) = uid {
            cmd.env("HOME", rt).uid(u).gid(u);
        }
        let child = cmd.spawn().expect("formation host starts");
        let mut d = Daemon { child, log };
        crate::wait_until_listening(&mut d.child, &d.log, "the daemon", Duration::from_secs(30));
        d
    }

    /// What it wrote on its standard error so far.
    pub fn log_text(&self) -> String {
        std::fs::read_to_string(&self.log).unwrap_or_default()
    }

    /// The daemon's child processes (agents it spawned), as `/proc` lists them.
    pub fn children(&self) -> String {
        let pid = self.child.id();
        std::fs::read_to_string(format!("/proc/{pid}/task/{pid}/children")).unwrap_or_default()
    }

    /// Waits up to `timeout` for a line of its log containing `needle`.
    pub fn wait_for_line(&self, needle: &str, timeout: Duration) -> Option<String> {
        let t0 = Instant::now();
        loop {
            if let Some(l) = self.log_text().lines().find(|l| l.contains(needle)) {
                return Some(l.to_string());
            }
            if t0.elapsed() > timeout {
                return None;
            }
            std::thread::sleep(Duration::from_millis(50));
        }
    }
}

impl Drop for Daemon {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// A runtime folder `dir/rt` for one daemon and its clients (mode `mode`).
pub fn runtime(dir: &Path, mode: u32) -> PathBuf {
    let rt = dir.join("rt");
    std::fs::create_dir_all(&rt).unwrap();
    std::fs::set_permissions(&rt, std::fs::Permissions::from_mode(mode)).unwrap();
    rt
}

/// `formation ARGS` with runtime folder `rt`, to its end.
pub fn formation_rt<S: AsRef<std::ffi::OsStr>>(rt: &Path, args: &[S]) -> Output {
    Command::new(bin("formation"))
        .args(args)
        .env("XDG_RUNTIME_DIR", rt)
        .env_remove("CARGO")
        .output()
        .expect("formation starts")
}

/// A host name unique to this test process: `tag` and the pid.
pub fn unique(tag: &str) -> String {
    format!("{tag}{}", std::process::id() % 100_000)
}

/// Asserts that none of `pids` is alive within 5 s (the agents of a daemon killed, or of a run
/// ended).
pub fn assert_gone(pids: &[u32]) {
    let t0 = Instant::now();
    for p in pids {
        while Path::new(&format!("/proc/{p}")).exists() {
            assert!(
                t0.elapsed() < Duration::from_secs(5),
                "process {p} of the run is still alive"
            );
            std::thread::sleep(Duration::from_millis(20));
        }
    }
}

/// The folder of a daemon's run folders, as its log names it (`...; runs in ROOT`).
pub fn runs_root(daemon_log: &Path) -> Option<PathBuf> {
    let log = std::fs::read_to_string(daemon_log).ok()?;
    let root = log.lines().find_map(|l| l.split("; runs in ").nth(1))?;
    Some(PathBuf::from(root.trim()))
}

/// The step of agent 4's newest checkpoint in the first run folder under `runs` (a daemon's
/// [`runs_root`], seen from the test).
pub fn agent_4_checkpoint_step(runs: &Path) -> Option<u64> {
    let run = std::fs::read_dir(runs).ok()?.flatten().next()?;
    let bytes = std::fs::read(run.path().join("checkpoints/agent-4.ckpt")).ok()?;
    Some(u64::from_le_bytes(bytes.get(24..32)?.try_into().ok()?))
}
