//! Scheduling of the role processes in realtime mode: a 1 ns timer slack (the default 50 µs slack
//! would delay every absolute sleep by up to 50 µs) and, on request, the `SCHED_FIFO` policy.

use super::error::NodeError;

/// Sets a 1 ns timer slack, and `SCHED_FIFO` at `priority` (1..=99) unless `priority` is 0.
/// Returns a warning when the policy cannot be set (e.g. without `CAP_SYS_NICE`); the run then
/// goes on under the normal policy.
pub fn realtime_setup(priority: u32) -> Option<String> {
    // SAFETY: plain syscalls with valid arguments.
    unsafe {
        libc::prctl(libc::PR_SET_TIMERSLACK, 1 as libc::c_ulong, 0, 0, 0);
    }
    if priority == 0 {
        return None;
    }
    let param = libc::sched_param {
        sched_priority: priority.clamp(1, 99) as libc::c_int,
    };
    // SAFETY: valid pointer to a sched_param; pid 0 is this process.
    let rc = unsafe { libc::sched_setscheduler(0, libc::SCHED_FIFO, &param) };
    (rc != 0).then(|| {
        format!(
            "cannot use SCHED_FIFO {priority}: {}; running under the normal policy",
            std::io::Error::last_os_error()
        )
    })
}

/// Nice value of the processes and threads that are off the per-step critical path (leader,
/// orchestrator and its CSV writer): they have slack (they run ahead or behind by up to a lead of
/// steps) and, at this weight, yield the CPU at once to a plant or agent that wakes up, instead of
/// making it wait for the end of their slice. Raising one's own nice needs no privilege.
pub const BACKGROUND_NICE: i32 = 10;

/// Lowers the calling thread's priority to [`BACKGROUND_NICE`] (Linux: nice is per thread; threads
/// and processes created afterwards inherit it). Failures are ignored: priority is an optimisation.
pub fn background_thread() {
    // SAFETY: setpriority on the calling thread (who = 0) with a valid nice value.
    unsafe {
        libc::setpriority(libc::PRIO_PROCESS, 0, BACKGROUND_NICE);
    }
}

/// Puts the calling thread under `SCHED_BATCH` (no privilege needed; threads and processes created
/// afterwards inherit it). A `SCHED_BATCH` task that wakes up does not preempt the running one: in
/// lockstep, where every process runs for a few µs and then blocks, this removes the context
/// switches of a plant that is preempted by the first agent it wakes while it still has agents to
/// wake (measured on the paper scenario, 2 vCPUs: 74 -> 65 µs per step, median of 6 alternated
/// runs, and 141 -> 129 µs of CPU per step; docs/runtime.md). Returns an error text on failure.
pub fn batch_policy() -> Result<(), NodeError> {
    set_normal_policy(libc::SCHED_BATCH, "SCHED_BATCH")
}

/// Puts the calling thread back under the default `SCHED_OTHER` policy.
pub fn other_policy() -> Result<(), NodeError> {
    set_normal_policy(libc::SCHED_OTHER, "SCHED_OTHER")
}

fn set_normal_policy(policy: libc::c_int, name: &str) -> Result<(), NodeError> {
    set_policy(0, policy, 0, name)
}

/// `sched_setscheduler(tid, policy, priority)`; an error names the policy (`name`) and the thread.
fn set_policy(
    tid: i32,
    policy: libc::c_int,
    priority: libc::c_int,
    name: &str,
) -> Result<(), NodeError> {
    let param = libc::sched_param {
        sched_priority: priority,
    };
    // SAFETY: valid pointer to a sched_param; a tid of this process or 0 (the calling thread).
    let rc = unsafe { libc::sched_setscheduler(tid, policy, &param) };
    if rc == 0 {
        Ok(())
    } else {
        let who = if tid == 0 {
            String::new()
        } else {
            format!(" for thread {tid}")
        };
        Err(NodeError::System(format!(
            "cannot use {name}{who}: {}",
            std::io::Error::last_os_error()
        )))
    }
}

/// Puts thread `tid` of this process (0: the calling thread) under `SCHED_FIFO` at `priority`
/// (1..=99), or back under `SCHED_OTHER` when `priority` is 0. Linux applies the policy to that
/// one thread; threads it creates afterwards inherit it.
pub fn set_thread_policy(tid: i32, priority: u32) -> Result<(), NodeError> {
    if priority == 0 {
        set_policy(tid, libc::SCHED_OTHER, 0, "SCHED_OTHER")
    } else {
        let p = priority.clamp(1, 99);
        set_policy(
            tid,
            libc::SCHED_FIFO,
            p as libc::c_int,
            &format!("SCHED_FIFO {p}"),
        )
    }
}
