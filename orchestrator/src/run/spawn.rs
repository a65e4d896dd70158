//! Locating, spawning, supervising and stopping the role processes.

use crate::cpus::CpuSet;
use formation_config::runtime::args::ChildArgs;
use std::os::unix::process::{CommandExt, ExitStatusExt};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

/// The role binaries, in the directory of the running `formation`.
pub const ROLE_BINARIES: [&str; 3] = ["formation-plant", "formation-leader", "formation-agent"];

/// Directory holding the role binaries: the one of the running executable. When they are missing and
/// `formation` was started by `cargo run` (the `CARGO` variable is set), builds them for the same
/// profile first.
pub fn role_binary_dir() -> Result<PathBuf, String> {
    let exe = std::env::current_exe().map_err(|e| format!("cannot locate formation: {e}"))?;
    let dir = exe
        .parent()
        .ok_or("cannot locate formation's directory")?
        .to_path_buf();
    let missing = || ROLE_BINARIES.iter().any(|b| !dir.join(b).is_file());
    if !missing() {
        return Ok(dir);
    }
    let profile = match dir.file_name().and_then(|s| s.to_str()) {
        Some("debug") => "dev".to_string(),
        Some(p) => p.to_string(),
        None => "release".to_string(),
    };
    let hint = format!(
        "cargo build --profile {profile} -p formation-plant -p formation-leader -p formation-agent"
    );
    let Some(cargo) = std::env::var_os("CARGO") else {
        return Err(format!(
            "the role binaries ({}) are not next to {}: build them with `{hint}`",
            ROLE_BINARIES.join(", "),
            exe.display()
        ));
    };
    eprintln!("building the role binaries: {hint}");
    let status = Command::new(cargo)
        .args(["build", "--profile", &profile])
        .args([
            "-p",
            "formation-plant",
            "-p",
            "formation-leader",
            "-p",
            "formation-agent",
        ])
        .status()
        .map_err(|e| format!("cannot run cargo ({hint}): {e}"))?;
    if !status.success() || missing() {
        return Err(format!("building the role binaries failed: `{hint}`"));
    }
    Ok(dir)
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
}

/// Starts `binary` with `args`, pinned to `cpu` if given; it gets SIGTERM when the orchestrator
/// dies and ignores SIGINT.
pub fn spawn(
    dir: &Path,
    binary: &str,
    label: String,
    args: &ChildArgs,
    cpu: Option<usize>,
) -> Result<RoleProcess, String> {
    let mut cmd = Command::new(dir.join(binary));
    cmd.args(args.to_args()).stdin(Stdio::null());
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
        .map_err(|e| format!("cannot start {label} ({}): {e}", dir.join(binary).display()))?;
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
    let mut first = None;
    for c in children.iter_mut() {
        if c.status.is_some() {
            continue;
        }
        if let Ok(Some(st)) = c.child.try_wait() {
            c.status = Some(st);
            if first.is_none() {
                first = Some(format!(
                    "{} (pid {}) {}",
                    c.label,
                    c.child.id(),
                    describe(st)
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
