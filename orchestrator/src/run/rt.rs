//! The scheduling of a realtime run's plant and agents (`--rt-priority`, docs/realtime.md,
//! "Scheduling"): `SCHED_FIFO` by default when this process is allowed to use it, never with a
//! busy loop at that priority, the normal policy otherwise; the decision is pure ([`decide`]) and
//! said in the run's output.

use std::fmt;

/// The `SCHED_FIFO` priority of `--rt-priority auto`: 10, above every normal task (a realtime
/// step preempts them at once) and below the kernel's own realtime threads (threaded interrupt
/// handlers run at 50), so a run never starves the interrupts it waits for.
pub const AUTO_PRIORITY: u32 = 10;

/// Linux capability number of `CAP_SYS_NICE` (linux/capability.h).
const CAP_SYS_NICE: u32 = 23;

/// What `--rt-priority` asks.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Requested {
    /// `auto` (the default): [`AUTO_PRIORITY`] when allowed and the plant blocks.
    Auto,
    /// `0`: the normal policy; `1..=99`: `SCHED_FIFO` at that priority.
    Priority(u32),
}

/// `--rt-priority` is neither `auto` nor a priority 0..=99 (the text given).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("`{0}`: expected `auto` or a priority 0..=99")]
pub struct PriorityError(String);

/// Parses `--rt-priority`: `auto` or a whole number 0..=99.
pub fn parse(text: &str) -> Result<Requested, PriorityError> {
    if text == "auto" {
        return Ok(Requested::Auto);
    }
    match text.parse::<u32>() {
        Ok(p) if p <= 99 => Ok(Requested::Priority(p)),
        _ => Err(PriorityError(text.to_string())),
    }
}

/// Whether this process may use `SCHED_FIFO` at a priority (checked, not assumed).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Privilege {
    /// `CAP_SYS_NICE` is in the effective set (root has it unless a container dropped it).
    pub cap_sys_nice: bool,
    /// Soft `RLIMIT_RTPRIO`: an unprivileged process may use `SCHED_FIFO` up to it.
    pub rlimit_rtprio: u64,
}

impl Privilege {
    /// Whether `SCHED_FIFO` at `priority` is allowed.
    pub fn allows(self, priority: u32) -> bool {
        self.cap_sys_nice || self.rlimit_rtprio >= u64::from(priority)
    }

    /// What allows it, or why not.
    fn why(self, priority: u32) -> String {
        if self.cap_sys_nice {
            "CAP_SYS_NICE".into()
        } else if self.allows(priority) {
            format!("RLIMIT_RTPRIO {}", self.rlimit_rtprio)
        } else {
            format!(
                "not allowed: no CAP_SYS_NICE, RLIMIT_RTPRIO {}",
                self.rlimit_rtprio
            )
        }
    }

    /// This process's privilege, read from `/proc/self/status` and `getrlimit`.
    pub fn of_this_process() -> Privilege {
        let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
        let mut rl = libc::rlimit {
            rlim_cur: 0,
            rlim_max: 0,
        };
        // SAFETY: valid pointer to an rlimit.
        let rc = unsafe { libc::getrlimit(libc::RLIMIT_RTPRIO, &mut rl) };
        Privilege {
            cap_sys_nice: has_capability(&status, CAP_SYS_NICE),
            rlimit_rtprio: if rc == 0 { rl.rlim_cur } else { 0 },
        }
    }
}

/// Whether the `CapEff:` line of a `/proc/<pid>/status` text has capability `cap`.
pub fn has_capability(status: &str, cap: u32) -> bool {
    status
        .lines()
        .find_map(|l| l.strip_prefix("CapEff:"))
        .and_then(|hex| u64::from_str_radix(hex.trim(), 16).ok())
        .is_some_and(|mask| mask >> cap & 1 == 1)
}

/// The scheduling a realtime run's plant and agents get.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Scheduling {
    /// `SCHED_FIFO` priority (0: the normal policy).
    pub priority: u32,
    /// Why, in a few words (said in the run's output).
    pub why: String,
}

impl fmt::Display for Scheduling {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.priority > 0 {
            write!(f, "SCHED_FIFO {} ({})", self.priority, self.why)
        } else {
            write!(f, "normal policy ({})", self.why)
        }
    }
}

/// A refused `--rt-priority`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum RtError {
    /// `SCHED_FIFO` asked with `--wait spin-block`: the plant would busy-poll at a realtime
    /// priority, which starves everything else on its CPU.
    BusyLoop(u32),
}

impl fmt::Display for RtError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            RtError::BusyLoop(p) => write!(
                f,
                "--rt-priority {p}: SCHED_FIFO with --wait spin-block would busy-poll at a realtime \
                 priority; use --wait block or --rt-priority 0"
            ),
        }
    }
}

impl std::error::Error for RtError {}

/// The scheduling of a realtime run: `requested`, whether the plant busy-polls (`--wait
/// spin-block`), and what this process may do. `auto` takes [`AUTO_PRIORITY`] when allowed and the
/// plant blocks; an explicit priority that is not allowed falls back to the normal policy (said);
/// an explicit priority with a busy-polling plant is refused.
pub fn decide(
    requested: Requested,
    spins: bool,
    privilege: Privilege,
) -> Result<Scheduling, RtError> {
    let normal = |why: String| Ok(Scheduling { priority: 0, why });
    let priority = match requested {
        Requested::Priority(0) => return normal("--rt-priority 0".into()),
        Requested::Priority(p) if spins => return Err(RtError::BusyLoop(p)),
        Requested::Auto if spins => {
            return normal("--wait spin-block busy-polls: never under SCHED_FIFO".into())
        }
        Requested::Auto => AUTO_PRIORITY,
        Requested::Priority(p) => p,
    };
    if !privilege.allows(priority) {
        return normal(privilege.why(priority));
    }
    Ok(Scheduling {
        priority,
        why: privilege.why(priority),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    const ROOT: Privilege = Privilege {
        cap_sys_nice: true,
        rlimit_rtprio: 0,
    };
    const USER: Privilege = Privilege {
        cap_sys_nice: false,
        rlimit_rtprio: 0,
    };

    #[test]
    fn auto_takes_fifo_10_when_allowed_and_the_plant_blocks() {
        let s = decide(Requested::Auto, false, ROOT).unwrap();
        assert_eq!(s.priority, AUTO_PRIORITY);
        assert_eq!(s.to_string(), "SCHED_FIFO 10 (CAP_SYS_NICE)");
        let limited = Privilege {
            cap_sys_nice: false,
            rlimit_rtprio: 20,
        };
        assert_eq!(
            decide(Requested::Auto, false, limited).unwrap().to_string(),
            "SCHED_FIFO 10 (RLIMIT_RTPRIO 20)"
        );
    }

    #[test]
    fn without_the_privilege_or_with_a_busy_loop_auto_is_the_normal_policy_said_why() {
        let s = decide(Requested::Auto, false, USER).unwrap();
        assert_eq!(s.priority, 0);
        assert_eq!(
            s.to_string(),
            "normal policy (not allowed: no CAP_SYS_NICE, RLIMIT_RTPRIO 0)"
        );
        let s = decide(Requested::Auto, true, ROOT).unwrap();
        assert_eq!(s.priority, 0);
        assert!(s.why.contains("spin-block"), "{s}");
    }

    #[test]
    fn zero_turns_it_off_and_an_explicit_priority_with_a_busy_loop_is_refused() {
        assert_eq!(
            decide(Requested::Priority(0), true, ROOT).unwrap().priority,
            0
        );
        assert_eq!(
            decide(Requested::Priority(30), true, ROOT),
            Err(RtError::BusyLoop(30))
        );
        assert_eq!(
            decide(Requested::Priority(30), false, ROOT)
                .unwrap()
                .priority,
            30
        );
        // Asked but not allowed: the normal policy, said.
        assert_eq!(
            decide(Requested::Priority(30), false, USER)
                .unwrap()
                .priority,
            0
        );
    }

    #[test]
    fn the_flag_is_auto_or_a_priority_up_to_99() {
        assert_eq!(parse("auto"), Ok(Requested::Auto));
        assert_eq!(parse("0"), Ok(Requested::Priority(0)));
        assert_eq!(parse("99"), Ok(Requested::Priority(99)));
        assert!(parse("100").is_err());
        assert!(parse("-1").is_err());
    }

    #[test]
    fn cap_sys_nice_is_read_from_the_effective_set() {
        let root = "Name:\tx\nCapInh:\t0000000000000000\nCapEff:\t000001ffffffffff\n";
        assert!(has_capability(root, CAP_SYS_NICE));
        let user = "CapEff:\t0000000000000000\n";
        assert!(!has_capability(user, CAP_SYS_NICE));
        assert!(has_capability("CapEff:\t0000000000800000\n", CAP_SYS_NICE));
        assert!(!has_capability("", CAP_SYS_NICE));
    }
}
