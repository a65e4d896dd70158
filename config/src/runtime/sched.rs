//! Scheduling of the role processes in realtime mode: a 1 ns timer slack (the default 50 µs slack
//! would delay every absolute sleep by up to 50 µs) and, on request, the `SCHED_FIFO` policy.

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
