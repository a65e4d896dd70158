//! The scheduling of the cross-host message path in a realtime run (docs/multi-host.md,
//! "Realtime across hosts").
//!
//! A remote agent's step crosses about eight wake-ups: plant, this host's bridge (`bridge-out`),
//! Zenoh's sending and receiving threads, the other host's Zenoh threads and bridge, the agent,
//! and back. Plant and agents run under `SCHED_FIFO` in a realtime run (`--rt-priority`); under
//! the normal policy beside CPU-bound work every other hop waits up to a scheduler slice, and the
//! agents' effective delays pass τ_M. While a realtime bridge runs, its own sending thread and
//! every thread of this process's Zenoh runtimes (`tx-*`, `rx-*`, `net-*`, `app-*`, `acc-*`) run
//! under `SCHED_FIFO` at the run's priority. The accepting runtime is on the path too: a link a
//! listener accepted (a daemon's link to the orchestrator) is read there, and left under the
//! normal policy it alone kept the launcher → host direction's p99 at 4-5 ms beside two
//! CPU-bound loops (1.1 ms raised). None of these threads spins: each blocks on a socket, a
//! channel or an iceoryx2 wait set between messages.
//!
//! A daemon serves several runs with one Zenoh session: the threads are raised while at least one
//! realtime bridge runs (at the highest priority among them) and go back to the normal policy
//! when the last one stops ([`LinkPriority`] counts them).

use std::collections::BTreeMap;
use std::sync::Mutex;

/// Name prefixes of the Zenoh runtime threads on a link's path (Zenoh names each runtime's
/// threads `<runtime>-<n>`, `ZenohRuntime` in zenoh-runtime 1.10): `tx` sends, `rx` receives and
/// runs callback subscribers (the bridge's receiving side, which publishes into iceoryx2 there),
/// `acc` accepts connections and reads the links a listener accepted, `net` and `app` run the
/// session's routing and application tasks.
pub const LINK_RUNTIMES: [&str; 5] = ["tx", "rx", "acc", "net", "app"];

/// Name of the bridge's sending thread (`crate::bridge`).
pub const BRIDGE_THREAD: &str = "bridge-out";

/// True for a thread name (`/proc/self/task/*/comm`) of a Zenoh runtime on the link path:
/// `<runtime>-<digits>` with `<runtime>` in [`LINK_RUNTIMES`].
pub fn is_link_thread(comm: &str) -> bool {
    let Some((runtime, n)) = comm.trim_end().split_once('-') else {
        return false;
    };
    LINK_RUNTIMES.contains(&runtime) && !n.is_empty() && n.bytes().all(|b| b.is_ascii_digit())
}

/// The priority the link threads should have with these realtime bridges running (priority →
/// count): the highest, or 0 (normal policy) when none runs.
pub fn wanted(active: &BTreeMap<u32, usize>) -> u32 {
    active
        .iter()
        .rev()
        .find(|(_, &n)| n > 0)
        .map_or(0, |(&p, _)| p)
}

/// Realtime bridges running in this process: priority → count.
static ACTIVE: Mutex<BTreeMap<u32, usize>> = Mutex::new(BTreeMap::new());

/// Held by a realtime bridge: this process's link threads run under `SCHED_FIFO` while any is
/// held (see the module docs). Dropping the last one puts them back under the normal policy.
#[derive(Debug)]
pub struct LinkPriority {
    priority: u32,
}

/// What raising the link threads did.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Raised {
    /// The priority the link threads now have.
    pub priority: u32,
    /// Link threads set to it.
    pub threads: usize,
    /// The first failure (e.g. no `CAP_SYS_NICE`): those threads stay under the normal policy.
    pub failed: Option<String>,
}

impl Raised {
    /// One line for the run's output: what the message path runs under.
    pub fn describe(&self) -> String {
        match (&self.failed, self.priority) {
            (_, 0) => "the bridge and the Zenoh link threads under the normal policy".into(),
            (None, p) => format!(
                "the bridge and {} Zenoh link threads under SCHED_FIFO {p}",
                self.threads
            ),
            (Some(e), p) => format!(
                "{} Zenoh link threads under SCHED_FIFO {p}, the rest and possibly the bridge under the normal policy ({e})",
                self.threads
            ),
        }
    }
}

impl LinkPriority {
    /// Raises this process's link threads for a bridge of priority `priority` (1..=99; 0 holds
    /// nothing and changes nothing).
    pub fn raise(priority: u32) -> (Option<LinkPriority>, Raised) {
        if priority == 0 {
            let r = Raised {
                priority: 0,
                threads: 0,
                failed: None,
            };
            return (None, r);
        }
        let mut active = ACTIVE.lock().unwrap_or_else(|p| p.into_inner());
        *active.entry(priority).or_default() += 1;
        let r = apply(wanted(&active));
        (Some(LinkPriority { priority }), r)
    }
}

impl Drop for LinkPriority {
    fn drop(&mut self) {
        let mut active = ACTIVE.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(n) = active.get_mut(&self.priority) {
            *n = n.saturating_sub(1);
            if *n == 0 {
                active.remove(&self.priority);
            }
        }
        apply(wanted(&active));
    }
}

/// Sets every link thread of this process to `priority` (0: the normal policy).
fn apply(priority: u32) -> Raised {
    let mut r = Raised {
        priority,
        threads: 0,
        failed: None,
    };
    let Ok(tasks) = std::fs::read_dir("/proc/self/task") else {
        r.failed = Some("cannot read /proc/self/task".into());
        return r;
    };
    for task in tasks.flatten() {
        let Some(tid) = task
            .file_name()
            .to_str()
            .and_then(|s| s.parse::<i32>().ok())
        else {
            continue;
        };
        let comm = std::fs::read_to_string(task.path().join("comm")).unwrap_or_default();
        if !is_link_thread(&comm) {
            continue;
        }
        match formation_config::node::sched::set_thread_policy(tid, priority) {
            Ok(()) => r.threads += 1,
            Err(e) => {
                r.failed.get_or_insert(e.to_string());
            }
        }
    }
    r
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_zenoh_runtime_thread_is_a_link_thread_and_nothing_else_is() {
        for name in ["tx-0", "rx-0", "net-0", "app-0", "acc-1", "rx-12", "tx-1\n"] {
            assert!(is_link_thread(name), "{name}");
        }
        for name in [
            "bridge-out",
            "rx-",
            "rx",
            "rx-a",
            "formation",
            "ctrl-c",
            "csv-writer",
            "tx-0-x",
        ] {
            assert!(!is_link_thread(name), "{name}");
        }
    }

    #[test]
    fn the_link_threads_follow_the_highest_realtime_bridge_and_fall_back_when_none_runs() {
        let mut active = BTreeMap::new();
        assert_eq!(wanted(&active), 0);
        active.insert(10, 1);
        assert_eq!(wanted(&active), 10);
        active.insert(20, 1);
        assert_eq!(wanted(&active), 20);
        active.insert(20, 0);
        assert_eq!(wanted(&active), 10);
    }

    #[test]
    fn the_output_line_says_which_policy_the_message_path_runs_under() {
        let ok = Raised {
            priority: 10,
            threads: 4,
            failed: None,
        };
        assert_eq!(
            ok.describe(),
            "the bridge and 4 Zenoh link threads under SCHED_FIFO 10"
        );
        let refused = Raised {
            failed: Some("cannot use SCHED_FIFO 10 for thread 7: Operation not permitted".into()),
            threads: 0,
            ..ok
        };
        assert!(refused.describe().contains("Operation not permitted"));
    }

    #[test]
    fn a_bridge_of_priority_zero_holds_nothing_and_changes_nothing() {
        let (held, r) = LinkPriority::raise(0);
        assert!(held.is_none());
        assert_eq!(r.threads, 0);
        assert_eq!(r.priority, 0);
    }
}
