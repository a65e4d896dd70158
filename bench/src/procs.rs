//! Peer processes of the bench: spawning (`formation bench-peer ...`), CPU pinning, reaping, and
//! killing them on failure or Ctrl-C.
//!
//! Children die with the parent (`PR_SET_PDEATHSIG` = SIGKILL, set before `exec`), ignore SIGINT
//! (the parent decides), and time out by themselves if no step arrives.

use crate::error::CaseError;
use std::io;
use std::os::unix::process::CommandExt;
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Mutex;
use std::time::{Duration, Instant};

static ABORTED: AtomicBool = AtomicBool::new(false);
static LIVE_PIDS: Mutex<Vec<i32>> = Mutex::new(Vec::new());

/// True once Ctrl-C (SIGINT/SIGTERM) was received.
pub fn aborted() -> bool {
    ABORTED.load(Ordering::Relaxed)
}

/// Installs the Ctrl-C / SIGTERM handler: it marks the run as aborted and kills every live peer.
pub fn install_interrupt_handler() {
    let _ = ctrlc::set_handler(|| {
        ABORTED.store(true, Ordering::SeqCst);
        if let Ok(pids) = LIVE_PIDS.lock() {
            for &pid in pids.iter() {
                // SAFETY: kill(2) with a pid of a child we spawned and have not reaped yet.
                unsafe {
                    libc::kill(pid, libc::SIGKILL);
                }
            }
        }
    });
}

/// The parent process id of this process.
pub fn parent_pid() -> i32 {
    // SAFETY: getppid(2) cannot fail.
    unsafe { libc::getppid() }
}

/// The CPUs this process may use ([`formation_runtime::cpus::allowed`]).
pub fn allowed_cpus() -> Vec<usize> {
    formation_runtime::cpus::allowed()
}

/// Restricts the calling thread to `cpus`.
pub fn set_affinity(cpus: &[usize]) -> io::Result<()> {
    formation_runtime::cpus::CpuSet::of(cpus)?.apply()
}

/// The peer processes of one case. Dropping it kills and reaps whatever is still running.
pub struct Peers {
    children: Vec<Child>,
}

/// Makes the child of `cmd` die (SIGKILL) with the bench process `parent` (this process's pid),
/// also when the bench died between the fork and this call (then the child exits at once).
pub fn die_with_bench(cmd: &mut Command, parent: i32) {
    // SAFETY: only async-signal-safe calls (prctl, getppid, _exit) between fork and exec.
    unsafe {
        cmd.pre_exec(move || {
            libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGKILL);
            if libc::getppid() != parent {
                libc::_exit(1);
            }
            Ok(())
        });
    }
}

impl Peers {
    /// Spawns one `formation bench-peer` per argument list.
    pub fn spawn(arg_lists: Vec<Vec<String>>) -> io::Result<Peers> {
        let exe = std::env::current_exe()?;
        let parent = std::process::id() as i32;
        let mut peers = Peers {
            children: Vec::new(),
        };
        for args in arg_lists {
            let mut cmd = Command::new(&exe);
            cmd.arg("bench-peer")
                .args(&args)
                .stdin(Stdio::null())
                .stdout(Stdio::null())
                .stderr(Stdio::inherit());
            die_with_bench(&mut cmd, parent);
            // SAFETY: signal(2) is async-signal-safe.
            unsafe {
                cmd.pre_exec(|| {
                    libc::signal(libc::SIGINT, libc::SIG_IGN);
                    Ok(())
                });
            }
            let child = cmd.spawn()?; // on error, Drop reaps the ones already started
            if let Ok(mut pids) = LIVE_PIDS.lock() {
                pids.push(child.id() as i32);
            }
            peers.children.push(child);
            if aborted() {
                break;
            }
        }
        Ok(peers)
    }

    /// True while every peer is still running.
    pub fn all_alive(&mut self) -> bool {
        let mut alive = true;
        for c in &mut self.children {
            if !matches!(c.try_wait(), Ok(None)) {
                // Reaped now: never signal this pid again (it may be reused).
                forget_pid(c.id() as i32);
                alive = false;
            }
        }
        alive
    }

    /// Waits up to `timeout` for every peer to exit by itself, then kills the rest. Returns an
    /// error naming the peers that failed or had to be killed.
    pub fn finish(mut self, timeout: Duration) -> Result<(), CaseError> {
        let deadline = Instant::now() + timeout;
        let mut failures = Vec::new();
        for (i, c) in std::mem::take(&mut self.children).into_iter().enumerate() {
            match reap(c, deadline) {
                Ok(status) if status.success() => {}
                Ok(status) => failures.push(format!("peer {i} exited with {status}")),
                Err(e) => failures.push(format!("peer {i}: {e}")),
            }
        }
        if failures.is_empty() {
            Ok(())
        } else {
            Err(CaseError::Peers(failures))
        }
    }
}

/// Waits for `child` until `deadline`, then kills it; always reaps it.
fn reap(mut child: Child, deadline: Instant) -> io::Result<std::process::ExitStatus> {
    let pid = child.id() as i32;
    let result = loop {
        match child.try_wait() {
            Ok(Some(status)) => break Ok(status),
            Ok(None) if Instant::now() < deadline && !aborted() => {
                std::thread::sleep(Duration::from_millis(2))
            }
            Ok(None) => {
                let _ = child.kill();
                let _ = child.wait();
                break Err(io::Error::new(
                    io::ErrorKind::TimedOut,
                    "killed (did not exit)",
                ));
            }
            Err(e) => {
                let _ = child.kill();
                let _ = child.wait();
                break Err(e);
            }
        }
    };
    forget_pid(pid);
    result
}

fn forget_pid(pid: i32) {
    if let Ok(mut pids) = LIVE_PIDS.lock() {
        pids.retain(|&p| p != pid);
    }
}

impl Drop for Peers {
    fn drop(&mut self) {
        for c in std::mem::take(&mut self.children) {
            let _ = reap(c, Instant::now());
        }
    }
}
