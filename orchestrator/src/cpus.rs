//! CPU sets: which CPUs this process may run on, parsing CPU lists (`0,1`, `0-3`), and pinning a
//! process (Linux `sched_getaffinity` / `sched_setaffinity`).

use std::io;

/// The CPUs the calling thread may run on (its affinity mask), ascending; `[0]` if unknown.
pub fn allowed() -> Vec<usize> {
    // SAFETY: a zeroed cpu_set_t is a valid empty set; sched_getaffinity fills it.
    unsafe {
        let mut set: libc::cpu_set_t = std::mem::zeroed();
        if libc::sched_getaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &mut set) != 0 {
            return vec![0];
        }
        (0..libc::CPU_SETSIZE as usize)
            .filter(|&c| libc::CPU_ISSET(c, &set))
            .collect()
    }
}

/// Why a CPU list is refused ([`parse_list`]).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum CpuListError {
    /// A part that is no CPU number or range (the part).
    #[error("bad CPU '{0}'")]
    Bad(String),
    /// A range whose start is above its end (the part).
    #[error("bad CPU range '{0}'")]
    Range(String),
    /// A CPU this process may not run on.
    #[error("CPU {cpu} is not available (allowed: {allowed:?})")]
    NotAllowed {
        /// The CPU.
        cpu: usize,
        /// The CPUs this process may run on.
        allowed: Vec<usize>,
    },
    /// No CPU at all.
    #[error("empty CPU list")]
    Empty,
}

/// Parses a CPU list such as `0,1`, `0-3` or `2,0-1` (order kept, duplicates dropped); every CPU
/// must be in `allowed`.
pub fn parse_list(s: &str, allowed: &[usize]) -> Result<Vec<usize>, CpuListError> {
    let mut out = Vec::new();
    for part in s.split(',').map(str::trim).filter(|p| !p.is_empty()) {
        let (lo, hi) = match part.split_once('-') {
            Some((a, b)) => (a.trim(), b.trim()),
            None => (part, part),
        };
        let bad = |_| CpuListError::Bad(part.to_string());
        let lo: usize = lo.parse().map_err(bad)?;
        let hi: usize = hi.parse().map_err(bad)?;
        if lo > hi {
            return Err(CpuListError::Range(part.to_string()));
        }
        for c in lo..=hi {
            if !allowed.contains(&c) {
                return Err(CpuListError::NotAllowed {
                    cpu: c,
                    allowed: allowed.to_vec(),
                });
            }
            if !out.contains(&c) {
                out.push(c);
            }
        }
    }
    if out.is_empty() {
        return Err(CpuListError::Empty);
    }
    Ok(out)
}

/// A set of CPUs, ready to be applied (also between `fork` and `exec`: applying it allocates
/// nothing and makes one system call).
#[derive(Clone, Copy)]
pub struct CpuSet(libc::cpu_set_t);

impl CpuSet {
    /// The set holding exactly `cpus`; an error for a CPU beyond `CPU_SETSIZE`.
    pub fn of(cpus: &[usize]) -> io::Result<CpuSet> {
        // SAFETY: a zeroed cpu_set_t is a valid empty set; CPU_SET stays in bounds (checked).
        unsafe {
            let mut set: libc::cpu_set_t = std::mem::zeroed();
            for &c in cpus {
                if c >= libc::CPU_SETSIZE as usize {
                    return Err(io::Error::new(
                        io::ErrorKind::InvalidInput,
                        format!("CPU {c} out of range"),
                    ));
                }
                libc::CPU_SET(c, &mut set);
            }
            Ok(CpuSet(set))
        }
    }

    /// Restricts the calling thread (and what it later forks or execs) to this set.
    pub fn apply(&self) -> io::Result<()> {
        self.apply_to(0)
    }

    /// Restricts thread `tid` (0: the calling thread) to this set.
    pub fn apply_to(&self, tid: libc::pid_t) -> io::Result<()> {
        // SAFETY: a valid cpu_set_t of the size passed; sched_setaffinity only reads it.
        let rc = unsafe {
            libc::sched_setaffinity(tid, std::mem::size_of::<libc::cpu_set_t>(), &self.0)
        };
        if rc == 0 {
            Ok(())
        } else {
            Err(io::Error::last_os_error())
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cpu_lists_accept_ranges_and_reject_unavailable_cpus() {
        assert_eq!(parse_list("0-1", &[0, 1]), Ok(vec![0, 1]));
        assert_eq!(parse_list("1,0,1", &[0, 1]), Ok(vec![1, 0]));
        assert!(parse_list("7", &[0, 1]).is_err());
        assert!(parse_list("x", &[0, 1]).is_err());
        assert!(parse_list("1-0", &[0, 1]).is_err());
        assert!(parse_list("", &[0, 1]).is_err());
    }

    #[test]
    fn the_allowed_cpus_are_never_empty_and_a_thread_can_be_pinned_to_them() {
        let cpus = allowed();
        assert!(!cpus.is_empty());
        let handle = std::thread::spawn(move || {
            CpuSet::of(&cpus[..1]).unwrap().apply().unwrap();
            allowed()
        });
        assert_eq!(handle.join().unwrap().len(), 1);
    }
}
