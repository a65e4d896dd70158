//! Fencing the agents of a lost host that shares this machine's kernel (a co-located daemon,
//! docs/multi-host.md "Fencing a lost host"). A daemon declared lost after its lease may only be
//! paused (SIGSTOP, a swapped-out machine): its agents then still run, hold their ports and send
//! commands. Before their successors start here, the orchestrator ends them itself: it pins each
//! process with a pidfd, checks through /proc that it is the lost agent of this run (its command
//! line names the run's iceoryx2 prefix and the agent, and it is this user's), SIGKILLs it through
//! the pidfd (no pid reuse can redirect the signal) and waits, blocked on the pidfd, until it has
//! exited. A returning daemon then finds its agents dead.

use std::os::fd::{AsRawFd, FromRawFd, OwnedFd};
use std::time::Duration;

/// How long the orchestrator waits for a fenced agent to exit after its SIGKILL.
pub const FENCE_TIMEOUT: Duration = Duration::from_secs(2);

/// What fencing one process did.
#[derive(Debug, PartialEq, Eq)]
pub enum Fenced {
    /// It was the lost agent, was killed and has exited.
    Ended,
    /// No such process any more (it died with its daemon, or was reaped).
    Gone,
    /// The pid belongs to another process (reused) or another user: left alone.
    NotOurs,
    /// Killed, but it had not exited within [`FENCE_TIMEOUT`].
    StillRunning,
    /// The kernel refused (no pidfd support, no permission).
    Failed(std::io::ErrorKind),
}

/// Whether a process whose NUL-separated command line is `cmdline` and whose `/proc/PID/status`
/// is `status` is agent `agent` (0-based) of the run with iceoryx2 prefix `prefix`, run by `uid`
/// (real uid). Pure: the rule the fence applies.
pub fn is_agent_of(cmdline: &[u8], status: &str, prefix: &str, agent: usize, uid: u32) -> bool {
    let args: Vec<&[u8]> = cmdline.split(|&b| b == 0).collect();
    let value_of = |flag: &str| {
        args.windows(2)
            .find(|w| w[0] == flag.as_bytes())
            .map(|w| w[1])
    };
    let real_uid = status
        .lines()
        .find_map(|l| l.strip_prefix("Uid:"))
        .and_then(|rest| rest.split_whitespace().next())
        .and_then(|u| u.parse::<u32>().ok());
    value_of("--prefix") == Some(prefix.as_bytes())
        && value_of("--agent") == Some(agent.to_string().as_bytes())
        && real_uid == Some(uid)
}

/// Ends process `pid` if it is agent `agent` of the run with prefix `prefix` (see the module
/// documentation), waiting up to `timeout` for it to exit.
pub fn end_agent(pid: u32, prefix: &str, agent: usize, timeout: Duration) -> Fenced {
    // SAFETY: pidfd_open(2) with a pid and no flags; the result is a new descriptor or -1.
    let fd = unsafe { libc::syscall(libc::SYS_pidfd_open, pid as libc::pid_t, 0) };
    if fd < 0 {
        let e = std::io::Error::last_os_error();
        return match e.raw_os_error() {
            Some(libc::ESRCH) => Fenced::Gone,
            _ => Fenced::Failed(e.kind()),
        };
    }
    // SAFETY: `fd` is a descriptor pidfd_open just returned, owned here only.
    let fd = unsafe { OwnedFd::from_raw_fd(fd as i32) };
    // With the process pinned by the pidfd, /proc/PID is that process (or it has exited).
    let proc_dir = std::path::Path::new("/proc").join(pid.to_string());
    let (Ok(cmdline), Ok(status)) = (
        std::fs::read(proc_dir.join("cmdline")),
        std::fs::read_to_string(proc_dir.join("status")),
    ) else {
        return Fenced::Gone;
    };
    // SAFETY: getuid(2) has no preconditions.
    let uid = unsafe { libc::getuid() };
    if !is_agent_of(&cmdline, &status, prefix, agent, uid) {
        return Fenced::NotOurs;
    }
    // SAFETY: pidfd_send_signal(2) on the pidfd above, no siginfo, no flags.
    let sent = unsafe {
        libc::syscall(
            libc::SYS_pidfd_send_signal,
            fd.as_raw_fd(),
            libc::SIGKILL,
            std::ptr::null::<libc::siginfo_t>(),
            0,
        )
    };
    if sent < 0 {
        let e = std::io::Error::last_os_error();
        return match e.raw_os_error() {
            Some(libc::ESRCH) => Fenced::Gone,
            _ => Fenced::Failed(e.kind()),
        };
    }
    // A pidfd is readable once its process has exited (a zombie its paused daemon has not
    // reaped yet has released its ports and locks).
    let mut p = libc::pollfd {
        fd: fd.as_raw_fd(),
        events: libc::POLLIN,
        revents: 0,
    };
    let ms = timeout.as_millis().min(i32::MAX as u128) as i32;
    // SAFETY: poll(2) on one valid pollfd.
    let n = unsafe { libc::poll(&mut p, 1, ms) };
    if n == 1 {
        Fenced::Ended
    } else {
        Fenced::StillRunning
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::process::Command;

    fn cmdline(args: &[&str]) -> Vec<u8> {
        args.iter().flat_map(|a| a.bytes().chain([0])).collect()
    }

    const STATUS: &str = "Name:\tfm-agent-4\nUid:\t1000\t1000\t1000\t1000\nGid:\t1000\n";

    #[test]
    fn only_the_lost_agent_of_this_run_and_this_user_is_fenced() {
        let me = cmdline(&[
            "fm-agent-4",
            "node",
            "agent",
            "--agent",
            "3",
            "--prefix",
            "fm1_",
        ]);
        assert!(is_agent_of(&me, STATUS, "fm1_", 3, 1000));
        // Another agent, another run, another user, a reused pid running something else.
        assert!(!is_agent_of(&me, STATUS, "fm1_", 4, 1000));
        assert!(!is_agent_of(&me, STATUS, "fm2_", 3, 1000));
        assert!(!is_agent_of(&me, STATUS, "fm1_", 3, 1001));
        assert!(!is_agent_of(
            &cmdline(&["sleep", "60"]),
            STATUS,
            "fm1_",
            3,
            1000
        ));
        // A prefix that is only the start of another argument is not the run's.
        let longer = cmdline(&["x", "--agent", "3", "--prefix", "fm1_x"]);
        assert!(!is_agent_of(&longer, STATUS, "fm1_", 3, 1000));
    }

    #[test]
    fn a_process_that_is_not_the_agent_is_left_alone_and_a_gone_one_is_named() {
        let mut sleeper = Command::new("sleep").arg("30").spawn().unwrap();
        let pid = sleeper.id();
        let cmdline = format!("/proc/{pid}/cmdline");
        while !std::fs::read(&cmdline).is_ok_and(|c| c.starts_with(b"sleep")) {
            std::thread::sleep(Duration::from_millis(1));
        }
        assert_eq!(end_agent(pid, "fm1_", 3, FENCE_TIMEOUT), Fenced::NotOurs);
        assert!(sleeper.try_wait().unwrap().is_none(), "still running");
        sleeper.kill().unwrap();
        sleeper.wait().unwrap();
        assert_eq!(end_agent(pid, "fm1_", 3, FENCE_TIMEOUT), Fenced::Gone);
    }

    #[test]
    fn the_lost_agent_is_killed_and_its_exit_awaited() {
        // A stand-in whose command line names the run and the agent: `sh -c 'sleep 30' --agent 3
        // --prefix fm1_` (sh passes the extra words as $0, $1, ...; the `; true` keeps sh from exec-ing sleep).
        let mut agent = Command::new("sh")
            .args(["-c", "sleep 30; true", "--agent", "3", "--prefix", "fm1_"])
            .spawn()
            .unwrap();
        let pid = agent.id();
        // Until it has exec'd, the child's command line is this test's.
        let cmdline = format!("/proc/{pid}/cmdline");
        while !std::fs::read(&cmdline).is_ok_and(|c| c.windows(4).any(|w| w == b"fm1_")) {
            std::thread::sleep(Duration::from_millis(1));
        }
        let t0 = std::time::Instant::now();
        assert_eq!(end_agent(pid, "fm1_", 3, FENCE_TIMEOUT), Fenced::Ended);
        assert!(t0.elapsed() < FENCE_TIMEOUT);
        let st = agent.wait().unwrap();
        use std::os::unix::process::ExitStatusExt;
        assert_eq!(st.signal(), Some(libc::SIGKILL));
    }
}
