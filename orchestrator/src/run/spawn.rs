//! Locating, spawning, supervising and stopping the role processes.

use crate::cpus::CpuSet;
use formation_config::node::args::ChildArgs;
use formation_config::protocol::messages::Role;
use std::os::unix::process::{CommandExt, ExitStatusExt};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::mpsc::{self, Sender, SyncSender};
use std::sync::{Mutex, OnceLock};
use std::time::{Duration, Instant};

/// A command to start and where its child goes.
type ForkRequest = (Command, SyncSender<std::io::Result<Child>>);

/// The thread that starts the role processes once the orchestrator's own thread runs at
/// `BACKGROUND_NICE` ([`keep_launch_priority`]).
static FORKER: OnceLock<Mutex<Sender<ForkRequest>>> = OnceLock::new();

/// From now on the role processes (the successors of a takeover) are started by a thread that
/// keeps the calling thread's priority: on Linux the nice value is per thread and a child inherits
/// its forking thread's, so a successor forked by the orchestrator's thread after
/// `sched::background_thread` would run `BACKGROUND_NICE` below the agents it flies beside (and
/// start, rebuild and compute ten times slower than them on a busy machine). Call it before the
/// priority is lowered; once.
pub fn keep_launch_priority() {
    let (tx, rx) = mpsc::channel::<ForkRequest>();
    let started = std::thread::Builder::new()
        .name("fm-forker".into())
        .spawn(move || {
            for (mut cmd, back) in rx {
                let _ = back.send(cmd.spawn());
            }
        });
    if started.is_ok() {
        let _ = FORKER.set(Mutex::new(tx));
    }
}

/// Starts `cmd` from the thread of the launch priority if there is one, else from this thread.
fn start(mut cmd: Command) -> std::io::Result<Child> {
    let Some(tx) = FORKER.get() else {
        return cmd.spawn();
    };
    let (back, child) = mpsc::sync_channel(1);
    let sent = tx
        .lock()
        .map_err(|_| std::io::Error::other("the forker thread panicked"))?;
    sent.send((cmd, back))
        .map_err(|_| std::io::Error::other("the forker thread is gone"))?;
    drop(sent);
    child
        .recv()
        .map_err(|_| std::io::Error::other("the forker thread is gone"))?
}

/// The executable the role processes are started from: the running `formation` itself, whose hidden
/// subcommand `formation node <role> ...` runs a role (one install, no second binary to find).
pub fn self_exe() -> Result<PathBuf, SpawnError> {
    std::env::current_exe().map_err(SpawnError::Exe)
}

/// Why a role process could not be started; each names the process (its label) or file.
#[derive(Debug, thiserror::Error)]
pub enum SpawnError {
    /// The running executable cannot be located.
    #[error("cannot locate the formation executable: {0}")]
    Exe(std::io::Error),
    /// The process's CPU set cannot be built.
    #[error("cannot pin {label}: {source}")]
    Pin {
        /// The process, e.g. `agent 2 (--agent 1)`.
        label: String,
        /// Why.
        source: std::io::Error,
    },
    /// The process cannot be started.
    #[error("cannot start {label} ({}): {source}", exe.display())]
    Start {
        /// The process, e.g. `agent 2 (--agent 1)`.
        label: String,
        /// The executable.
        exe: PathBuf,
        /// The system's error.
        source: std::io::Error,
    },
}

// The supervision's takeover and the remote layer still report their errors as text: a start
// that fails there is said with this message.
impl From<SpawnError> for String {
    fn from(e: SpawnError) -> String {
        e.to_string()
    }
}

/// A role process started on another host by its daemon (`formation host`, crate
/// `formation-net`): what the supervision needs of it.
pub trait RemoteProcess {
    /// Its process id on its host.
    fn pid(&self) -> u32;
    /// Its host's name.
    fn host(&self) -> &str;
    /// SIGKILLs it and waits until its daemon has reaped it.
    fn kill_and_reap(&mut self);
    /// Sends SIGSTOP or SIGCONT.
    fn signal(&self, signal: i32);
    /// How it ended, once its daemon reported its exit (or the host was lost).
    fn try_wait(&mut self) -> Option<String>;
    /// Whether it is stopped (SIGSTOP, a debugger), as its daemon sees it.
    fn is_stopped(&self) -> bool;
}

enum Proc {
    Local(Child, Option<ExitStatus>),
    #[cfg_attr(not(feature = "multihost"), allow(dead_code))]
    Remote(Box<dyn RemoteProcess>, Option<String>),
}

/// One role process of the run.
pub struct RoleProcess {
    /// "plant", "leader" or "agent i" (1-based, as in the paper and the CSV).
    pub label: String,
    proc: Proc,
}

impl RoleProcess {
    /// A process on another host.
    #[cfg_attr(not(feature = "multihost"), allow(dead_code))]
    pub fn remote(label: String, p: Box<dyn RemoteProcess>) -> RoleProcess {
        RoleProcess {
            label,
            proc: Proc::Remote(p, None),
        }
    }

    /// Process id (on its host).
    pub fn pid(&self) -> u32 {
        match &self.proc {
            Proc::Local(c, _) => c.id(),
            Proc::Remote(p, _) => p.pid(),
        }
    }

    /// The host it runs on (`None`: this one).
    pub fn host(&self) -> Option<&str> {
        match &self.proc {
            Proc::Local(..) => None,
            Proc::Remote(p, _) => Some(p.host()),
        }
    }

    /// Its exit code, once it has exited by itself (a process on this machine; `None` for one on
    /// another host, killed by a signal, or still running).
    pub fn exit_code(&self) -> Option<i32> {
        match &self.proc {
            Proc::Local(_, Some(st)) => st.code(),
            _ => None,
        }
    }

    fn done(&self) -> bool {
        match &self.proc {
            Proc::Local(_, st) => st.is_some(),
            Proc::Remote(_, st) => st.is_some(),
        }
    }

    /// Reaps it if it exited; how it ended (once).
    fn poll_exit(&mut self) -> Option<String> {
        match &mut self.proc {
            Proc::Local(c, st @ None) => match c.try_wait() {
                Ok(Some(s)) => {
                    *st = Some(s);
                    Some(describe(s))
                }
                _ => None,
            },
            Proc::Remote(p, st @ None) => {
                let how = p.try_wait()?;
                *st = Some(how.clone());
                Some(how)
            }
            _ => None,
        }
    }

    /// SIGKILLs the process (if it is still running) and reaps it.
    pub fn kill_and_reap(&mut self) {
        match &mut self.proc {
            Proc::Local(c, st @ None) => {
                let _ = c.kill();
                if let Ok(s) = c.wait() {
                    *st = Some(s);
                }
            }
            Proc::Remote(p, st @ None) => {
                p.kill_and_reap();
                *st = Some("was killed (SIGKILL)".into());
            }
            _ => {}
        }
    }

    /// Sends `signal` (SIGSTOP for a timeline hang) to the running process.
    pub fn signal(&self, signal: i32) {
        match &self.proc {
            // SAFETY: kill(2) on our own child's pid, which is not reaped yet (no reuse).
            Proc::Local(c, None) => unsafe {
                libc::kill(c.id() as libc::pid_t, signal);
            },
            Proc::Remote(p, None) => p.signal(signal),
            _ => {}
        }
    }

    /// Whether the process is stopped (state `T` in /proc/<pid>/stat: SIGSTOP, a debugger); a
    /// remote process as its daemon sees it (not stopped if its daemon does not answer).
    pub fn is_stopped(&self) -> bool {
        match &self.proc {
            Proc::Local(c, None) => formation_config::node::process::is_stopped(c.id()),
            Proc::Remote(p, None) => p.is_stopped(),
            _ => false,
        }
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
) -> Result<RoleProcess, SpawnError> {
    let mut cmd = Command::new(exe);
    cmd.arg0(role.process_name(args.agent))
        .args(["node", role.name()])
        .args(args.to_args())
        .stdin(Stdio::null());
    let pin = cpu
        .map(|c| CpuSet::of(&[c]))
        .transpose()
        .map_err(|source| SpawnError::Pin {
            label: label.clone(),
            source,
        })?;
    // SAFETY: only async-signal-safe calls (sched_setaffinity, prctl, signal) between fork and
    // exec; the CPU set was built before the fork.
    unsafe {
        cmd.pre_exec(move || {
            if let Some(set) = &pin {
                set.apply()?;
            }
            formation_config::node::process::die_with_parent_ignore_sigint();
            Ok(())
        });
    }
    let child = start(cmd).map_err(|source| SpawnError::Start {
        label: label.clone(),
        exe: exe.to_path_buf(),
        source,
    })?;
    Ok(RoleProcess {
        label,
        proc: Proc::Local(child, None),
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

/// [`check`], with the index of that child. It stops at the first: another child that died at
/// the same time (two agents lost with one host) is reported by the next call.
pub fn check_indexed(children: &mut [RoleProcess]) -> Option<(usize, String)> {
    children.iter_mut().enumerate().find_map(|(idx, c)| {
        let how = c.poll_exit()?;
        let on = c
            .host()
            .map(|h| format!(" on host {h}"))
            .unwrap_or_default();
        Some((idx, format!("{} (pid {}{on}) {how}", c.label, c.pid())))
    })
}

/// Waits up to `grace` for every child to exit by itself, then kills and reaps the rest.
pub fn stop_all(children: &mut [RoleProcess], grace: Duration) {
    let deadline = Instant::now() + grace;
    while children.iter().any(|c| !c.done()) && Instant::now() < deadline {
        check(children);
        std::thread::sleep(Duration::from_millis(5));
    }
    for c in children.iter_mut().filter(|c| !c.done()) {
        c.kill_and_reap();
    }
}
