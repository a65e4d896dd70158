//! A `formation run` started by a test: its stderr is collected as it arrives, and dropping it kills
//! the orchestrator and every process of the run and removes the run's iceoryx2 files, so a failing
//! test leaves nothing behind.

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// A running `formation run`.
pub struct RunningRun {
    child: Option<Child>,
    /// Output directory (also a marker in every role process's command line).
    pub out: PathBuf,
    lines: Arc<Mutex<Vec<String>>>,
}

impl RunningRun {
    /// Starts `formation run <args...> --out <out>` (no `CARGO` in its environment, so it never
    /// builds anything).
    pub fn start(args: &[&str], out: &Path) -> RunningRun {
        RunningRun::start_with_env(args, out, &[])
    }

    /// Like [`RunningRun::start`], with extra environment variables (e.g. `FORMATION_RUNS_DIR`).
    pub fn start_with_env(args: &[&str], out: &Path, env: &[(&str, &Path)]) -> RunningRun {
        let _ = std::fs::remove_dir_all(out);
        let mut child = Command::new(crate::bin("formation"))
            .envs(env.iter().map(|(k, v)| (*k, v.as_os_str())))
            .arg("run")
            .args(args)
            .arg("--out")
            .arg(out)
            .env_remove("CARGO")
            .current_dir(std::env::temp_dir())
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .expect("formation starts");
        let lines = Arc::new(Mutex::new(Vec::new()));
        let stderr = child.stderr.take().expect("stderr is piped");
        let sink = lines.clone();
        std::thread::spawn(move || {
            for line in BufReader::new(stderr).split(b'\n').map_while(Result::ok) {
                let text = String::from_utf8_lossy(&line).into_owned();
                for part in text.split('\r') {
                    sink.lock().unwrap().push(part.to_string());
                }
            }
        });
        RunningRun {
            child: Some(child),
            out: out.to_path_buf(),
            lines,
        }
    }

    /// Orchestrator pid.
    pub fn pid(&self) -> u32 {
        self.child.as_ref().map_or(0, |c| c.id())
    }

    /// Everything written to stderr so far.
    pub fn stderr(&self) -> String {
        self.lines.lock().unwrap().join("\n")
    }

    /// Waits until a stderr line contains `needle` (or `timeout`); returns that line.
    pub fn wait_for_line(&self, needle: &str, timeout: Duration) -> Option<String> {
        let start = Instant::now();
        while start.elapsed() < timeout {
            if let Some(l) = self
                .lines
                .lock()
                .unwrap()
                .iter()
                .find(|l| l.contains(needle))
            {
                return Some(l.clone());
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        None
    }

    /// The iceoryx2 prefix the run announced on stderr.
    pub fn prefix(&self) -> Option<String> {
        let line = self.wait_for_line("iceoryx2 prefix ", Duration::from_secs(30))?;
        let rest = line.split("iceoryx2 prefix ").nth(1)?;
        Some(rest.split([',', ' ']).next()?.to_string())
    }

    /// The run id of the start line (`formation run: id <id>, ...`).
    pub fn id(&self) -> Option<String> {
        let line = self.wait_for_line("formation run: id ", Duration::from_secs(30))?;
        let rest = line.split("formation run: id ").nth(1)?;
        Some(rest.split(',').next()?.to_string())
    }

    /// Waits for the orchestrator to exit (or `timeout`); returns its status and the time it took.
    pub fn wait(&mut self, timeout: Duration) -> Option<(ExitStatus, Duration)> {
        let start = Instant::now();
        let child = self.child.as_mut()?;
        while start.elapsed() < timeout {
            if let Ok(Some(st)) = child.try_wait() {
                // Let the reader thread catch the last lines.
                std::thread::sleep(Duration::from_millis(50));
                return Some((st, start.elapsed()));
            }
            std::thread::sleep(Duration::from_millis(5));
        }
        None
    }

    /// Sends `signal` to the orchestrator.
    pub fn signal(&self, signal: i32) {
        // SAFETY: kill with a valid pid of our own child.
        unsafe {
            libc::kill(self.pid() as i32, signal);
        }
    }

    /// Pid of the agent process started with `--agent index` (0-based), if it is alive.
    pub fn agent_pid(&self, index: usize) -> Option<u32> {
        let needle = format!("--agent\u{0}{index}\u{0}");
        self.role_processes().into_iter().find(|pid| {
            std::fs::read(format!("/proc/{pid}/cmdline"))
                .is_ok_and(|c| String::from_utf8_lossy(&c).contains(&needle))
        })
    }

    /// Role processes of this run still alive (by their `--run-dir`).
    pub fn role_processes(&self) -> Vec<u32> {
        processes_mentioning(&self.out)
    }
}

impl Drop for RunningRun {
    fn drop(&mut self) {
        if let Some(mut c) = self.child.take() {
            let _ = c.kill();
            let _ = c.wait();
        }
        for pid in processes_mentioning(&self.out) {
            // SAFETY: kill with a pid we just read; at worst it has exited.
            unsafe {
                libc::kill(pid as i32, libc::SIGKILL);
            }
        }
        if let Some(prefix) = self
            .lines
            .lock()
            .unwrap()
            .iter()
            .find_map(|l| l.split("iceoryx2 prefix ").nth(1).map(str::to_string))
        {
            let prefix = prefix.split([',', ' ']).next().unwrap_or("").to_string();
            if !prefix.is_empty() {
                std::thread::sleep(Duration::from_millis(100));
                let _ = formation_config::node::ipc::remove_residue(&prefix);
            }
        }
    }
}

/// The pids of a run's start line (`formation run: id ID, ...; pids P L A1 ...; ...`): plant,
/// leader, then the agents in order.
pub fn start_line_pids(line: &str) -> Vec<u32> {
    line.split("pids ")
        .nth(1)
        .and_then(|r| r.split(';').next())
        .map(|p| {
            p.split_whitespace()
                .filter_map(|x| x.parse().ok())
                .collect()
        })
        .unwrap_or_default()
}

/// Pids of the processes whose command line mentions `marker` (e.g. a run directory).
pub fn processes_mentioning(marker: &Path) -> Vec<u32> {
    let canonical = std::fs::canonicalize(marker).unwrap_or_else(|_| marker.to_path_buf());
    let needles = [
        marker.to_string_lossy().into_owned(),
        canonical.to_string_lossy().into_owned(),
    ];
    let mut out = Vec::new();
    let Ok(entries) = std::fs::read_dir("/proc") else {
        return out;
    };
    for e in entries.flatten() {
        let Some(pid) = e.file_name().to_str().and_then(|s| s.parse::<u32>().ok()) else {
            continue;
        };
        let Ok(cmdline) = std::fs::read(e.path().join("cmdline")) else {
            continue;
        };
        let text = String::from_utf8_lossy(&cmdline).replace('\0', " ");
        if needles.iter().any(|n| text.contains(n.as_str())) && text.contains("--run-dir") {
            out.push(pid);
        }
    }
    out
}
