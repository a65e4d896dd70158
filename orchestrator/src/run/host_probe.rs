//! The host's own timer noise, measured just before and just after a realtime run (and by
//! `formation bench --host`): a bare loop that sleeps to absolute 1 ms deadlines and does nothing
//! else. Its late wake-ups are what the machine (hypervisor, other programs, interrupts) costs any
//! periodic program; the run's deadline misses beside them tell the machine's noise from the
//! runtime's (docs/realtime.md, "The host's own limit").
//!
//! The loop runs under the scheduling the run's plant gets ([`super::rt::Scheduling`]): the same
//! 1 ns timer slack and, when the run uses it, `SCHED_FIFO` at the same priority; it never spins.

use serde::Serialize;
use std::sync::mpsc;
use std::time::Duration;

/// Period of the bare loop: 1 ms, the plant's period at the paper's step (dt = 1 ms).
pub const PERIOD: Duration = Duration::from_millis(1);

/// Length of one probe: 2 s, 2000 periods (a late fraction of 0.5 % is 10 wake-ups), short
/// against a run and long enough to see the host's periodic noise (its 1 s and faster ticks).
pub const DURATION: Duration = Duration::from_secs(2);

/// A wake-up this late counts as late: 500 µs, half the period (a step that starts this late has
/// less than half its period left before its deadline).
pub const LATE: Duration = Duration::from_micros(500);

/// What one or more probes measured.
#[derive(Debug, Clone, Copy, Serialize, PartialEq)]
pub struct ProbeStats {
    /// Periods measured.
    pub periods: u64,
    /// Mean lateness of a wake-up past its deadline, µs.
    pub mean_late_us: f64,
    /// Largest lateness, µs.
    pub max_late_us: f64,
    /// Wake-ups later than [`LATE`].
    pub late: u64,
    /// `late / periods` (0 without periods).
    pub late_fraction: f64,
}

/// The statistics of the lateness of every wake-up, ns.
pub fn stats(late_ns: &[u64]) -> ProbeStats {
    let periods = late_ns.len() as u64;
    let late = late_ns
        .iter()
        .filter(|&&l| l > LATE.as_nanos() as u64)
        .count() as u64;
    let sum: u128 = late_ns.iter().map(|&l| u128::from(l)).sum();
    ProbeStats {
        periods,
        mean_late_us: if periods > 0 {
            sum as f64 / periods as f64 / 1e3
        } else {
            0.0
        },
        max_late_us: late_ns.iter().copied().max().unwrap_or(0) as f64 / 1e3,
        late,
        late_fraction: if periods > 0 {
            late as f64 / periods as f64
        } else {
            0.0
        },
    }
}

/// Two probes pooled (before and after a run).
pub fn pooled(a: &ProbeStats, b: &ProbeStats) -> ProbeStats {
    let periods = a.periods + b.periods;
    let late = a.late + b.late;
    ProbeStats {
        periods,
        mean_late_us: if periods > 0 {
            (a.mean_late_us * a.periods as f64 + b.mean_late_us * b.periods as f64) / periods as f64
        } else {
            0.0
        },
        max_late_us: a.max_late_us.max(b.max_late_us),
        late,
        late_fraction: if periods > 0 {
            late as f64 / periods as f64
        } else {
            0.0
        },
    }
}

/// The run's deadline-miss fraction over the bare loop's late fraction (`None` when the loop
/// never woke late: no ratio to give).
pub fn miss_ratio(deadline_miss_fraction: f64, bare: &ProbeStats) -> Option<f64> {
    (bare.late_fraction > 0.0).then(|| deadline_miss_fraction / bare.late_fraction)
}

fn now_ns() -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: valid pointer to a timespec.
    unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
    ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64
}

fn sleep_until_ns(t: u64) {
    let ts = libc::timespec {
        tv_sec: (t / 1_000_000_000) as libc::time_t,
        tv_nsec: (t % 1_000_000_000) as libc::c_long,
    };
    // SAFETY: valid timespec; an interrupted sleep returns early and is measured as it is.
    unsafe {
        libc::clock_nanosleep(
            libc::CLOCK_MONOTONIC,
            libc::TIMER_ABSTIME,
            &ts,
            std::ptr::null_mut(),
        )
    };
}

/// Runs the bare loop on the calling thread for `duration` (periods of `period`); the lateness of
/// every wake-up, ns.
fn bare_loop(period: Duration, duration: Duration) -> Vec<u64> {
    let p = period.as_nanos() as u64;
    let n = (duration.as_nanos() / period.as_nanos().max(1)) as usize;
    let mut late = Vec::with_capacity(n);
    let mut next = now_ns() + p;
    for _ in 0..n {
        sleep_until_ns(next);
        let woke = now_ns();
        late.push(woke.saturating_sub(next));
        // A loop that fell more than a period behind restarts from now, as the plant does.
        next = (next + p).max(woke + p / 2);
    }
    late
}

/// A thread that probes on request, created before the orchestrator lowers its own priority
/// (threads inherit it): it keeps the normal nice value of the run's role processes.
pub struct Prober {
    ask: mpsc::Sender<()>,
    answer: mpsc::Receiver<ProbeStats>,
}

/// The probe's thread cannot be started.
#[derive(Debug, thiserror::Error)]
#[error("host probe: cannot start a thread: {0}")]
pub struct ProbeError(std::io::Error);

impl Prober {
    /// Starts the thread; `fifo` is the `SCHED_FIFO` priority the run's plant gets (0: none).
    pub fn start(fifo: u32) -> Result<Prober, ProbeError> {
        let (ask, asked) = mpsc::channel::<()>();
        let (tell, answer) = mpsc::channel::<ProbeStats>();
        std::thread::Builder::new()
            .name("host-probe".into())
            .spawn(move || {
                for () in asked {
                    let s = probe(fifo, DURATION);
                    if tell.send(s).is_err() {
                        break;
                    }
                }
            })
            .map_err(ProbeError)?;
        Ok(Prober { ask, answer })
    }

    /// Probes for [`DURATION`]; `None` if the thread is gone.
    pub fn measure(&self) -> Option<ProbeStats> {
        self.ask.send(()).ok()?;
        self.answer.recv().ok()
    }
}

/// One probe on the calling thread under the plant's scheduling: 1 ns timer slack, and
/// `SCHED_FIFO` at `fifo` for the probe's length when `fifo` > 0 (back to the normal policy
/// after). A refused `SCHED_FIFO` leaves the normal policy (the run would get the same).
pub fn probe(fifo: u32, duration: Duration) -> ProbeStats {
    let warning = formation_config::node::sched::realtime_setup(fifo);
    let late = bare_loop(PERIOD, duration);
    if fifo > 0 && warning.is_none() {
        let _ = formation_config::node::sched::other_policy();
    }
    stats(&late)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_wake_up_counts_as_late_past_half_the_period_and_the_fraction_is_of_all_periods() {
        let s = stats(&[10_000, 500_000, 500_001, 2_000_000]);
        assert_eq!(s.periods, 4);
        assert_eq!(s.late, 2);
        assert_eq!(s.late_fraction, 0.5);
        assert_eq!(s.max_late_us, 2000.0);
        assert!((s.mean_late_us - 752.50025).abs() < 1e-9);
        assert_eq!(stats(&[]).late_fraction, 0.0);
    }

    #[test]
    fn probes_pool_by_their_periods_and_the_ratio_needs_a_late_wake_up() {
        let a = stats(&[0; 1000]);
        let mut b_late = vec![0; 1000];
        b_late[..4].fill(600_000);
        let b = stats(&b_late);
        let p = pooled(&a, &b);
        assert_eq!((p.periods, p.late), (2000, 4));
        assert_eq!(p.late_fraction, 0.002);
        assert_eq!(miss_ratio(0.006, &p), Some(3.0));
        assert_eq!(miss_ratio(0.006, &a), None);
    }

    #[test]
    fn the_bare_loop_measures_every_period() {
        let late = bare_loop(Duration::from_millis(1), Duration::from_millis(20));
        assert_eq!(late.len(), 20);
    }
}
