//! CPU load read from /proc for the adaptive placement ([`super::governor`]): per-CPU busy and
//! total time from `/proc/stat`, the CPU time of a process from `/proc/<pid>/stat`, and the
//! affinity of every thread of a process (`/proc/<pid>/task/*`). A thin layer: parsing is pure
//! and tested on text, the rest is one read or one system call.

use std::fmt;
use std::io;

/// Time one CPU spent since boot, in clock ticks (`USER_HZ`, the unit of `/proc/stat` and of
/// `/proc/<pid>/stat`'s utime and stime alike).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct CpuTimes {
    /// Running tasks: user + nice + system + irq + softirq (guest time is already in user and
    /// nice). Steal (the hypervisor running another guest) is not busy: pinning cannot avoid it.
    pub busy: u64,
    /// busy + idle + iowait + steal: the time that passed for this CPU.
    pub total: u64,
}

/// A failure to read the load; the placement then stays as it is.
#[derive(Debug)]
pub enum LoadError {
    /// A /proc file could not be read.
    Read { path: String, error: io::Error },
    /// A /proc file did not have the expected form.
    Parse { path: String, what: String },
}

impl fmt::Display for LoadError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            LoadError::Read { path, error } => write!(f, "cannot read {path}: {error}"),
            LoadError::Parse { path, what } => write!(f, "cannot parse {path}: {what}"),
        }
    }
}

const PROC_STAT: &str = "/proc/stat";

/// Parses the `cpuN` lines of a `/proc/stat` text: (CPU number, its times), in file order.
pub fn parse_proc_stat(text: &str) -> Result<Vec<(usize, CpuTimes)>, LoadError> {
    let bad = |what: String| LoadError::Parse {
        path: PROC_STAT.into(),
        what,
    };
    let mut out = Vec::new();
    for line in text.lines() {
        let mut fields = line.split_ascii_whitespace();
        let Some(cpu) = fields
            .next()
            .and_then(|name| name.strip_prefix("cpu"))
            .filter(|n| !n.is_empty())
        else {
            continue;
        };
        let cpu: usize = cpu
            .parse()
            .map_err(|_| bad(format!("bad CPU name 'cpu{cpu}'")))?;
        let v: Vec<u64> = fields
            .take(8)
            .map(str::parse)
            .collect::<Result<_, _>>()
            .map_err(|_| bad(format!("bad number on the line of cpu{cpu}")))?;
        // user nice system idle iowait irq softirq steal; kernels before 2.6.11 have no steal.
        if v.len() < 7 {
            return Err(bad(format!(
                "cpu{cpu}: {} fields, expected 7 or more",
                v.len()
            )));
        }
        let busy = v[0] + v[1] + v[2] + v[5] + v[6];
        let total = busy + v[3] + v[4] + v.get(7).copied().unwrap_or(0);
        out.push((cpu, CpuTimes { busy, total }));
    }
    if out.is_empty() {
        return Err(bad("no cpuN line".into()));
    }
    Ok(out)
}

/// utime + stime of a `/proc/<pid>/stat` line, in clock ticks (all threads of the process). The
/// command name in parentheses may hold spaces and parentheses: the fields after it start after
/// the last `)`.
pub fn parse_pid_stat(line: &str) -> Option<u64> {
    let (_, rest) = line.rsplit_once(')')?;
    // rest: state (field 3) ppid pgrp ... utime (field 14) stime (field 15).
    let mut fields = rest.split_ascii_whitespace().skip(11);
    let utime: u64 = fields.next()?.parse().ok()?;
    let stime: u64 = fields.next()?.parse().ok()?;
    Some(utime + stime)
}

/// Every CPU's times now.
pub fn cpu_times() -> Result<Vec<(usize, CpuTimes)>, LoadError> {
    let text = std::fs::read_to_string(PROC_STAT).map_err(|error| LoadError::Read {
        path: PROC_STAT.into(),
        error,
    })?;
    parse_proc_stat(&text)
}

/// CPU time of process `pid` so far, in clock ticks; `None` when it has exited (or its stat
/// cannot be read or parsed: it then counts as load of others).
pub fn process_ticks(pid: u32) -> Option<u64> {
    parse_pid_stat(&std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?)
}

/// Restricts every thread of process `pid` to `cpus`. A thread created while the threads are
/// walked inherits the mask of its creator, so the walk is repeated until it finds no new thread.
/// A process or thread that exited meanwhile is not an error.
pub fn set_process_affinity(pid: u32, cpus: &[usize]) -> io::Result<()> {
    let set = crate::cpus::CpuSet::of(cpus)?;
    for_each_thread(pid, |tid| set.apply_to(tid))
}

/// The scheduling of a lockstep process, set on all its threads by [`set_process_sched`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Sched {
    /// `SCHED_BATCH`, nice 0: a woken process does not preempt the running one (an idle machine).
    Batch,
    /// `SCHED_OTHER` at nice `nice` (<= 0): a woken process preempts a program that computes.
    Other {
        /// Nice value; below 0 needs CAP_SYS_NICE (root has it).
        nice: i32,
    },
}

/// Puts every thread of process `pid` under `sched`. Returns whether the nice value was granted:
/// without the privilege to lower it, the threads get the policy at nice 0 (`Ok(false)`).
pub fn set_process_sched(pid: u32, sched: Sched) -> io::Result<bool> {
    let (policy, nice) = match sched {
        Sched::Batch => (libc::SCHED_BATCH, 0),
        Sched::Other { nice } => (libc::SCHED_OTHER, nice),
    };
    let mut granted = true;
    for_each_thread(pid, |tid| {
        let param = libc::sched_param { sched_priority: 0 };
        // SAFETY: a valid sched_param for a normal policy; tid is a thread of our child.
        if unsafe { libc::sched_setscheduler(tid, policy, &param) } != 0 {
            return Err(io::Error::last_os_error());
        }
        let want = if granted { nice } else { 0 };
        // SAFETY: setpriority on one thread (Linux: nice is per thread) with a valid nice value.
        if unsafe { libc::setpriority(libc::PRIO_PROCESS, tid as libc::id_t, want) } != 0 {
            let e = io::Error::last_os_error();
            if !matches!(e.raw_os_error(), Some(libc::EACCES) | Some(libc::EPERM)) {
                return Err(e);
            }
            granted = false;
            // SAFETY: as above, nice 0 (never refused for one's own child).
            unsafe { libc::setpriority(libc::PRIO_PROCESS, tid as libc::id_t, 0) };
        }
        Ok(())
    })?;
    Ok(granted)
}

/// Applies `f` to every thread of process `pid`. A thread created while the threads are walked
/// inherits the settings of its creator, so the walk is repeated until it finds no new thread. A
/// process or thread that exited meanwhile is not an error.
fn for_each_thread(pid: u32, mut f: impl FnMut(i32) -> io::Result<()>) -> io::Result<()> {
    let mut done: Vec<i32> = Vec::new();
    for _ in 0..3 {
        let tasks = match std::fs::read_dir(format!("/proc/{pid}/task")) {
            Ok(t) => t,
            Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(()),
            Err(e) => return Err(e),
        };
        let mut new = 0;
        for tid in tasks
            .flatten()
            .filter_map(|e| e.file_name().to_str()?.parse::<i32>().ok())
        {
            if done.contains(&tid) {
                continue;
            }
            match f(tid) {
                Ok(()) => {}
                Err(e) if e.raw_os_error() == Some(libc::ESRCH) => {}
                Err(e) => return Err(e),
            }
            done.push(tid);
            new += 1;
        }
        if new == 0 {
            break;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn proc_stat_gives_each_cpus_busy_and_total_ticks_without_steal_as_busy() {
        let text = "cpu  585546 1415167 233211 402860 5393 0 6618 49306 0 0\n\
                    cpu0 100 20 30 400 5 1 2 40 7 0\n\
                    cpu1 10 0 5 900 0 0 0 0 0 0\n\
                    intr 16817237 0 0\nctxt 68871561\n";
        let cpus = parse_proc_stat(text).unwrap();
        assert_eq!(
            cpus,
            [
                (
                    0,
                    CpuTimes {
                        busy: 100 + 20 + 30 + 1 + 2,
                        total: 153 + 400 + 5 + 40
                    }
                ),
                (
                    1,
                    CpuTimes {
                        busy: 15,
                        total: 915
                    }
                )
            ]
        );
    }

    #[test]
    fn a_proc_stat_without_cpu_lines_or_with_a_bad_number_is_an_error() {
        assert!(parse_proc_stat("intr 1 2 3\n").is_err());
        let e = parse_proc_stat("cpu0 1 2 x 4 5 6 7 8\n").unwrap_err();
        assert!(e.to_string().contains("cpu0"), "{e}");
        assert!(parse_proc_stat("cpu0 1 2 3\n").is_err());
    }

    #[test]
    fn a_pid_stat_with_spaces_and_parentheses_in_its_command_name_gives_utime_plus_stime() {
        let line = "4242 (fm agent) (2)) S 1 4242 4242 0 -1 4194304 100 0 0 0 \
                    170 30 0 0 20 0 3 0 1347836 3133440 362";
        assert_eq!(parse_pid_stat(line), Some(200));
        assert_eq!(parse_pid_stat("4242 (cut"), None);
        assert_eq!(parse_pid_stat("4242 (x) S 1 2"), None);
    }

    #[test]
    fn cpu_times_are_read_and_every_thread_of_a_process_takes_an_affinity() {
        assert!(!cpu_times().unwrap().is_empty());
        assert!(process_ticks(std::process::id()).is_some());
        let allowed = crate::cpus::allowed();
        let mut child = std::process::Command::new("sleep")
            .arg("10")
            .spawn()
            .unwrap();
        set_process_affinity(child.id(), &allowed[..1]).unwrap();
        let status = std::fs::read_to_string(format!("/proc/{}/status", child.id())).unwrap();
        let _ = child.kill();
        let _ = child.wait();
        let list = status
            .lines()
            .find_map(|l| l.strip_prefix("Cpus_allowed_list:"))
            .unwrap();
        assert_eq!(list.trim(), allowed[0].to_string());
        // An exited process is not an error.
        set_process_affinity(u32::MAX - 1, &allowed).unwrap();
    }
}
