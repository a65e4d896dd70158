//! Process plumbing of the role processes: names visible in `ps`, parent-death detection, and
//! SIGTERM as a polite stop request.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

/// [`Lifeline::must_stop`] asks the kernel for the parent pid at most this often: the parent's
/// death also arrives as SIGTERM (`PR_SET_PDEATHSIG`), which interrupts any wait, so the `getppid`
/// check is a backstop and need not cost a system call per loop iteration (reading the monotonic
/// clock does not enter the kernel).
const PARENT_CHECK_EVERY: Duration = Duration::from_millis(20);

static TERMINATED: AtomicBool = AtomicBool::new(false);

extern "C" fn on_term(_sig: libc::c_int) {
    TERMINATED.store(true, Ordering::SeqCst);
}

/// Asks the kernel for SIGTERM when the parent dies (`PR_SET_PDEATHSIG`) and ignores SIGINT (a
/// Ctrl-C is the parent's to handle). Async-signal-safe: a spawner calls it between fork and exec
/// (`Command::pre_exec`), so the child is covered before its first instruction; the role process
/// sets it again in [`Lifeline::install`].
pub fn die_with_parent_ignore_sigint() {
    // SAFETY: two plain syscalls with valid arguments.
    unsafe {
        libc::prctl(
            libc::PR_SET_PDEATHSIG,
            libc::SIGTERM as libc::c_ulong,
            0,
            0,
            0,
        );
        libc::signal(libc::SIGINT, libc::SIG_IGN);
    }
}

/// Watches the conditions under which a role process must stop on its own.
#[derive(Debug)]
pub struct Lifeline {
    parent: libc::pid_t,
    /// Time base of `next_check_ns`.
    born: Instant,
    /// When the parent pid is checked next, ns after `born`.
    next_check_ns: AtomicU64,
}

impl Lifeline {
    /// Names the process (`prctl(PR_SET_NAME)`, at most 15 bytes, e.g. `fm-agent-3`), asks the kernel
    /// for SIGTERM when the parent dies, turns SIGTERM/SIGHUP into a stop request and ignores SIGINT
    /// (the orchestrator decides how a Ctrl-C ends the run).
    pub fn install(name: &str) -> Lifeline {
        let mut buf = [0u8; 16];
        let bytes = name.as_bytes();
        let len = bytes.len().min(15);
        buf[..len].copy_from_slice(&bytes[..len]);
        die_with_parent_ignore_sigint();
        // SAFETY: plain syscalls with valid arguments; the handler only stores to an atomic.
        unsafe {
            libc::prctl(libc::PR_SET_NAME, buf.as_ptr() as libc::c_ulong, 0, 0, 0);
            libc::signal(libc::SIGTERM, on_term as *const () as libc::sighandler_t);
            libc::signal(libc::SIGHUP, on_term as *const () as libc::sighandler_t);
        }
        Lifeline {
            // SAFETY: getppid cannot fail.
            parent: unsafe { libc::getppid() },
            born: Instant::now(),
            next_check_ns: AtomicU64::new(0),
        }
    }

    /// Why the process must stop now, if it must: its parent is gone or it was asked to terminate.
    pub fn must_stop(&self) -> Option<&'static str> {
        if TERMINATED.load(Ordering::SeqCst) {
            return Some("terminated");
        }
        let now = self.born.elapsed().as_nanos() as u64;
        if now < self.next_check_ns.load(Ordering::Relaxed) {
            return None;
        }
        self.next_check_ns.store(
            now + PARENT_CHECK_EVERY.as_nanos() as u64,
            Ordering::Relaxed,
        );
        // SAFETY: getppid cannot fail.
        if unsafe { libc::getppid() } != self.parent || self.parent == 1 {
            return Some("the orchestrator is gone");
        }
        None
    }
}

/// Whether a `/proc/<pid>/stat` line says the process is stopped (state `T`, SIGSTOP, or `t`, a
/// debugger): the state follows the parenthesised command name.
pub fn stat_says_stopped(stat: &str) -> bool {
    stat.rsplit_once(')')
        .and_then(|(_, rest)| rest.split_whitespace().next())
        .is_some_and(|st| st == "T" || st == "t")
}

/// Whether process `pid` of this machine is stopped ([`stat_says_stopped`]; false if it is gone).
pub fn is_stopped(pid: u32) -> bool {
    stat_says_stopped(&std::fs::read_to_string(format!("/proc/{pid}/stat")).unwrap_or_default())
}

#[cfg(test)]
mod stat_tests {
    use super::stat_says_stopped;

    #[test]
    fn a_stopped_process_is_told_by_its_state_after_the_command_name() {
        assert!(stat_says_stopped("1234 (fm-agent-4) T 1 2 3"));
        assert!(stat_says_stopped("1234 (a) b) t 1"));
        assert!(!stat_says_stopped("1234 (fm T x) S 1 2"));
        assert!(!stat_says_stopped(""));
    }
}
