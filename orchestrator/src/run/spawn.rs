//! Locating, spawning, supervising and stopping the role processes.

use crate::cpus::CpuSet;
use formation_config::node::args::ChildArgs;
use formation_config::protocol::messages::Role;
use std::os::unix::process::{CommandExt, ExitStatusExt};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

/// The executable the role processes are started from: the running `formation` itself, whose hidden
/// subcommand `formation node <role> ...` runs a role (one install, no second binary to find).
pub fn self_exe() -> Result<PathBuf, String> {
    std::env::current_exe().map_err(|e| format!("cannot locate the formation executable: {e}"))
}

/// One role process of the run.
pub struct RoleProcess {
    /// "plant", "leader" or "agent i" (1-based, as in the paper and the CSV).
    pub label: String,
    child: Child,
    status: Option<ExitStatus>,
}

impl RoleProcess {
    /// Process id.
    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    /// SIGKILLs the process (if it is still running) and reaps it.
    pub fn kill_and_reap(&mut self) {
        if self.status.is_none() {
            let _ = self.child.kill();
            if let Ok(st) = self.child.wait() {
                self.status = Some(st);
            }
        }
    }

    /// Sends `signal` (SIGSTOP for a timeline hang) to the running process.
    pub fn signal(&self, signal: i32) {
        if self.status.is_none() {
            // SAFETY: kill(2) on our own child's pid, which is not reaped yet (no reuse).
            unsafe {
                libc::kill(self.child.id() as libc::pid_t, signal);
            }
        }
    }

    /// Whether the process is stopped (state `T` in /proc/<pid>/stat: SIGSTOP, a debugger).
    pub fn is_stopped(&self) -> bool {
        let stat =
            std::fs::read_to_string(format!("/proc/{}/stat", self.child.id())).unwrap_or_default();
        // The state follows the parenthesised command name.
        stat.rsplit_once(')')
            .and_then(|(_, rest)| rest.split_whitespace().next())
            .is_some_and(|st| st == "T" || st == "t")
    }
}

/// Starts `formation node <role> <args>` (shown by `ps` as `fm-<role>[-<id>]`), pinned to `cpu` if given; it gets SIGTERM when the orchestrator
/// dies and ignores SIGINT.
pub fn spawn(
    exe: &Path,
    role: Role,
    label: String,
    args: &ChildArgs,
    cpu: Option<usize>,
) -> Result<RoleProcess, String> {
    let mut cmd = Command::new(exe);
    cmd.arg0(role.process_name(args.agent))
        .args(["node", role.name()])
        .args(args.to_args())
        .stdin(Stdio::null());
    let pin = cpu
        .map(|c| CpuSet::of(&[c]))
        .transpose()
        .map_err(|e| format!("cannot pin {label}: {e}"))?;
    // SAFETY: only async-signal-safe calls (sched_setaffinity, prctl, signal) between fork and
    // exec; the CPU set was built before the fork.
    unsafe {
        cmd.pre_exec(move || {
            if let Some(set) = &pin {
                set.apply()?;
            }
            libc::prctl(
                libc::PR_SET_PDEATHSIG,
                libc::SIGTERM as libc::c_ulong,
                0,
                0,
                0,
            );
            libc::signal(libc::SIGINT, libc::SIG_IGN);
            Ok(())
        });
    }
    let child = cmd
        .spawn()
        .map_err(|e| format!("cannot start {label} ({}): {e}", exe.display()))?;
    Ok(RoleProcess {
        label,
        child,
        status: None,
    })
}

fn describe(status: ExitStatus) -> String {
    match (status.code(), status.signal()) {
        (Some(c), _) => format!("exited with code {c}"),
        (None, Some(9)) => "was killed (SIGKILL)".to_string(),
        (None, Some(s)) => format!("was killed by signal {s}"),
        _ => "exited".to_string(),
    }
}

/// Reaps the children that have exited; returns a one-line description of the first one found
/// dead that had not been reported.
pub fn check(children: &mut [RoleProcess]) -> Option<String> {
    check_indexed(children).map(|(_, line)| line)
}

/// [`check`], with the index of that child.
pub fn check_indexed(children: &mut [RoleProcess]) -> Option<(usize, String)> {
    let mut first = None;
    for (idx, c) in children.iter_mut().enumerate() {
        if c.status.is_some() {
            continue;
        }
        if let Ok(Some(st)) = c.child.try_wait() {
            c.status = Some(st);
            if first.is_none() {
                first = Some((
                    idx,
                    format!("{} (pid {}) {}", c.label, c.child.id(), describe(st)),
                ));
            }
        }
    }
    first
}

/// Waits up to `grace` for every child to exit by itself, then kills and reaps the rest.
pub fn stop_all(children: &mut [RoleProcess], grace: Duration) {
    let deadline = Instant::now() + grace;
    while children.iter().any(|c| c.status.is_none()) && Instant::now() < deadline {
        check(children);
        std::thread::sleep(Duration::from_millis(5));
    }
    for c in children.iter_mut().filter(|c| c.status.is_none()) {
        let _ = c.child.kill();
        if let Ok(st) = c.child.wait() {
            c.status = Some(st);
        }
    }
}
