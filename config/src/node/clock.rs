//! The time base of realtime runs: CLOCK_MONOTONIC, shared by every process of the machine, in
//! nanoseconds, and sleeping until an absolute time on it.

/// Now on CLOCK_MONOTONIC, ns.
pub fn now_ns() -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: valid pointer to a timespec; CLOCK_MONOTONIC always exists on Linux.
    unsafe {
        libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts);
    }
    ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64
}

/// Sleeps until CLOCK_MONOTONIC reaches `deadline_ns` (absolute, so that the errors of successive
/// sleeps do not add up). Returns at once if the deadline has passed; retries after a signal.
pub fn sleep_until_ns(deadline_ns: u64) {
    let ts = libc::timespec {
        tv_sec: (deadline_ns / 1_000_000_000) as libc::time_t,
        tv_nsec: (deadline_ns % 1_000_000_000) as libc::c_long,
    };
    loop {
        // SAFETY: valid timespec; a null remainder is allowed with TIMER_ABSTIME.
        let rc = unsafe {
            libc::clock_nanosleep(
                libc::CLOCK_MONOTONIC,
                libc::TIMER_ABSTIME,
                &ts,
                std::ptr::null_mut(),
            )
        };
        if rc != libc::EINTR {
            return;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sleeping_until_an_absolute_time_reaches_it() {
        let start = now_ns();
        sleep_until_ns(start + 2_000_000);
        assert!(now_ns() >= start + 2_000_000);
        let t = now_ns();
        sleep_until_ns(t.saturating_sub(1_000_000));
        assert!(now_ns() - t < 100_000_000);
    }
}
