//! CPU placement of the role processes (`formation run --pin`).
//!
//! On a machine with fewer CPUs than processes the kernel places a woken agent next to the plant
//! that woke it (a Unix-socket wake-up is a "sync" wake-up), so on 2 vCPUs three of five agents
//! queued behind the plant while the other CPU idled for half of every step (seen with
//! `perf sched timehist`). Pinning spreads them: the plant gets the first CPU, the first agent it
//! wakes another one, so the agents the plant wakes first run at once on the other CPUs while it
//! finishes its step (docs/runtime.md, "Cost of a step"). The automatic layout gives the plant's
//! CPU fewer agents than the others ([`PLANT_CPU_SHARE`]): with many agents per CPU a step is
//! over when the busiest CPU is.
//! Leader and orchestrator are not pinned: they have slack and run wherever there is room.
//! With at least N + 1 CPUs every process of the step gets a CPU of its own.
//! Beside other programs that keep a CPU busy pinning costs far more than it gains: `--pin auto`
//! then leaves the layout while they run (`super::governor`); `--pin always` and CPU lists keep it.

use crate::cpus;
use formation_config::node::files::{self, Lock};
use std::path::Path;

/// Most concurrent runs told apart by [`claim_slot`] (beyond, the layout rotates from slot 0).
const MAX_SLOTS: usize = 256;

/// A rotation slot held for the run's lifetime: an exclusive `flock` on
/// `<runs dir>/cpu-slot-<k>.lock`, released by the kernel when the run ends or dies.
#[derive(Debug)]
pub struct Slot {
    /// Slot number: the automatic layout of the run is rotated by it.
    pub index: usize,
    _file: Option<std::fs::File>,
}

impl Slot {
    /// No slot (the layout is not rotated).
    pub fn none() -> Slot {
        Slot {
            index: 0,
            _file: None,
        }
    }
}

/// Claims the lowest free slot in `dir`. Two runs starting at the same moment get different slots
/// (each `flock` succeeds for one process only), so their plants go to different CPUs; a slot of a
/// run that ended is free again.
pub fn claim_slot(dir: &Path) -> Result<Slot, SlotError> {
    for index in 0..MAX_SLOTS {
        let path = dir.join(format!("cpu-slot-{index}.lock"));
        let file = files::open_lock_file(&path, true).map_err(SlotError::Open)?;
        if files::try_lock(&file, Lock::Exclusive).map_err(|source| SlotError::Lock {
            path: path.clone(),
            source,
        })? {
            return Ok(Slot {
                index,
                _file: Some(file),
            });
        }
    }
    Ok(Slot::none())
}

/// What `--pin` asked for.
#[derive(Debug, Clone, PartialEq)]
pub enum PinRequest {
    /// Lockstep: the automatic layout over the CPUs this process may use (when there are at
    /// least 2), left while other programs keep one of them busy (`super::governor`); realtime:
    /// do not pin.
    Auto,
    /// The automatic layout, lockstep or realtime, whatever the load.
    Always,
    /// Do not pin.
    Off,
    /// Pin over these CPUs (plant on the first).
    Cpus(Vec<usize>),
}

impl PinRequest {
    /// Parses `auto`, `off` or a CPU list (`0,1`, `0-3`) of CPUs in `allowed`.
    pub fn parse(s: &str, allowed: &[usize]) -> Result<PinRequest, PinError> {
        match s.trim() {
            "auto" => Ok(PinRequest::Auto),
            "always" => Ok(PinRequest::Always),
            "off" | "none" => Ok(PinRequest::Off),
            list => cpus::parse_list(list, allowed)
                .map(PinRequest::Cpus)
                .map_err(PinError),
        }
    }
}

/// Why `--pin` is refused: its CPU list is.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("--pin: {0} (expected auto, always, off or a CPU list like 0,1)")]
pub struct PinError(pub cpus::CpuListError);

/// Why no CPU slot could be claimed ([`claim_slot`]): the layout is then not rotated.
#[derive(Debug, thiserror::Error)]
pub enum SlotError {
    /// A slot's lock file cannot be opened.
    #[error("cannot claim a CPU slot: {0}")]
    Open(std::io::Error),
    /// A slot's lock file cannot be locked.
    #[error("cannot lock {}: {source}", path.display())]
    Lock {
        /// The slot's lock file.
        path: std::path::PathBuf,
        /// The file system's error.
        source: std::io::Error,
    },
}

/// Share of the agents the plant's CPU takes in the automatic layout, against an even share
/// (N / CPUs), as a fraction `PLANT_CPU_SHARE.0 / PLANT_CPU_SHARE.1` = 4/5. The plant's own work
/// per step (N state publishes and wake-ups, N command receives, N RK4s, the step record) costs
/// about what N / 5 agents do: 1.0 ms against 39 µs per agent at N = 128 (CPU per step from
/// `/proc/<pid>/task/*/schedstat`, docs/runtime.md, "Cost of a step at scale"). When the agents
/// must share CPUs, a step ends when the busiest CPU is done, so the plant's CPU gets fewer
/// agents. On 2 CPUs and N = 5 this is the alternating layout (agents 2 and 4 with the plant).
pub const PLANT_CPU_SHARE: (usize, usize) = (4, 5);

/// Where each role process runs.
#[derive(Debug, Clone, PartialEq)]
pub struct Placement {
    cpus: Vec<usize>,
    /// Rotation of the layout (concurrent runs start on different CPUs).
    offset: usize,
    /// The automatic layout: the plant's CPU takes [`PLANT_CPU_SHARE`] of an even share of the
    /// agents, the others go round-robin over the other CPUs. Otherwise (an explicit list) agent
    /// i takes the CPU `i + 1` places after the plant's in the list.
    weighted: bool,
}

impl Placement {
    /// Whether `request` adapts to the load of others (`auto` in lockstep, `super::governor`).
    pub fn adapts(request: &PinRequest, realtime: bool) -> bool {
        *request == PinRequest::Auto && !realtime
    }

    /// The automatic layout is rotated by the run's [`Slot`].
    pub fn rotates(request: &PinRequest, realtime: bool) -> bool {
        Placement::adapts(request, realtime) || *request == PinRequest::Always
    }

    /// The placement for `request`: `None` when nothing is pinned. `allowed` is this process's
    /// affinity; `others` the run's [`Slot`] (0 when it runs alone), which rotates an automatic
    /// layout so that concurrent runs do not stack their plants on the same CPU.
    pub fn resolve(
        request: &PinRequest,
        realtime: bool,
        allowed: &[usize],
        others: usize,
    ) -> Option<Placement> {
        match request {
            PinRequest::Off => None,
            PinRequest::Auto | PinRequest::Always if allowed.len() < 2 => None,
            PinRequest::Auto if realtime => None,
            PinRequest::Auto | PinRequest::Always => Some(Placement {
                cpus: allowed.to_vec(),
                offset: others % allowed.len(),
                weighted: true,
            }),
            PinRequest::Cpus(c) => Some(Placement {
                cpus: c.clone(),
                offset: 0,
                weighted: false,
            }),
        }
    }

    /// The CPUs of the layout, each once.
    pub fn cpus(&self) -> Vec<usize> {
        let mut cpus = self.cpus.clone();
        cpus.sort_unstable();
        cpus.dedup();
        cpus
    }

    /// CPU of the plant.
    pub fn plant(&self) -> usize {
        self.cpus[self.offset % self.cpus.len()]
    }

    /// CPU of agent `i` (0-based).
    pub fn agent(&self, i: usize) -> usize {
        let c = self.cpus.len();
        if !self.weighted || c < 2 {
            return self.cpus[(self.offset + i + 1) % c];
        }
        // Agent at position p = i + 1 joins the plant when floor(q p) steps up between p and
        // p + 1, q = (4/5) / c: evenly spread, q of all agents, never agent 1 (it starts at once
        // on another CPU). The j-th of the others takes the (j mod (c - 1))-th other CPU.
        let (num, den) = (PLANT_CPU_SHARE.0, PLANT_CPU_SHARE.1 * c);
        let p = i + 1;
        let with_plant_before = num * p / den;
        if num * (p + 1) / den > with_plant_before {
            return self.plant();
        }
        let j = i - with_plant_before;
        self.cpus[(self.offset + 1 + j % (c - 1)) % c]
    }

    /// One line for the log and the console, e.g. `plant cpu 0, agents 1 0 1 0 1`.
    pub fn describe(&self, n: usize) -> String {
        let agents: Vec<String> = (0..n).map(|i| self.agent(i).to_string()).collect();
        format!("plant cpu {}, agents {}", self.plant(), agents.join(" "))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn on_two_cpus_the_agents_alternate_starting_on_the_cpu_without_the_plant() {
        let p = Placement::resolve(&PinRequest::Auto, false, &[0, 1], 0).unwrap();
        assert_eq!(p.plant(), 0);
        let agents: Vec<usize> = (0..5).map(|i| p.agent(i)).collect();
        assert_eq!(agents, [1, 0, 1, 0, 1]);
        assert_eq!(p.describe(5), "plant cpu 0, agents 1 0 1 0 1");
    }

    #[test]
    fn on_two_cpus_the_plants_cpu_takes_two_fifths_of_many_agents() {
        let p = Placement::resolve(&PinRequest::Auto, false, &[0, 1], 0).unwrap();
        for n in [20usize, 50, 100, 128] {
            let with_plant = (0..n).filter(|&i| p.agent(i) == p.plant()).count();
            // 4/5 of an even share: 2/5 of the agents (rounded down), spread over the order.
            assert_eq!(with_plant, (2 * (n + 1)) / 5, "N = {n}");
            assert_ne!(p.agent(0), p.plant(), "the first agent woken runs at once");
            let first_half = (0..n / 2).filter(|&i| p.agent(i) == p.plant()).count();
            assert!(
                first_half.abs_diff(with_plant / 2) <= 1,
                "N = {n}: evenly spread"
            );
        }
        // An explicit list keeps its order: agent i on the CPU i + 1 places after the plant's.
        let listed = Placement::resolve(&PinRequest::Cpus(vec![0, 1]), false, &[0, 1], 0).unwrap();
        let agents: Vec<usize> = (0..6).map(|i| listed.agent(i)).collect();
        assert_eq!(agents, [1, 0, 1, 0, 1, 0]);
    }

    #[test]
    fn with_enough_cpus_every_process_of_a_step_has_its_own() {
        let cpus: Vec<usize> = (0..8).collect();
        let p = Placement::resolve(&PinRequest::Auto, false, &cpus, 0).unwrap();
        let mut used: Vec<usize> = (0..5).map(|i| p.agent(i)).collect();
        used.push(p.plant());
        used.sort_unstable();
        used.dedup();
        assert_eq!(used.len(), 6);
    }

    #[test]
    fn a_concurrent_run_puts_its_plant_on_another_cpu() {
        let first = Placement::resolve(&PinRequest::Auto, false, &[0, 1], 0).unwrap();
        let second = Placement::resolve(&PinRequest::Auto, false, &[0, 1], 1).unwrap();
        assert_ne!(first.plant(), second.plant());
    }

    #[test]
    fn runs_claiming_slots_at_the_same_moment_all_get_different_ones() {
        let dir = std::env::temp_dir().join(format!("fm-slots-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let k = 6;
        let barrier = std::sync::Arc::new(std::sync::Barrier::new(k));
        let handles: Vec<_> = (0..k)
            .map(|_| {
                let (dir, barrier) = (dir.clone(), barrier.clone());
                std::thread::spawn(move || {
                    barrier.wait();
                    claim_slot(&dir).unwrap()
                })
            })
            .collect();
        let mut slots: Vec<Slot> = handles.into_iter().map(|h| h.join().unwrap()).collect();
        let mut got: Vec<usize> = slots.iter().map(|s| s.index).collect();
        got.sort_unstable();
        assert_eq!(got, (0..k).collect::<Vec<_>>());
        // A released slot is claimed again. A process another test of this binary forks at that
        // moment holds a copy of the lock's descriptor until its exec closes it: the slot is free
        // again within milliseconds, not at once.
        let freed = slots.iter().position(|s| s.index == 2).unwrap();
        drop(slots.swap_remove(freed));
        let deadline = std::time::Instant::now() + std::time::Duration::from_secs(2);
        while claim_slot(&dir).unwrap().index != 2 {
            assert!(std::time::Instant::now() < deadline, "slot 2 not freed");
            std::thread::sleep(std::time::Duration::from_millis(5));
        }
        drop(slots);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn auto_pins_lockstep_only_always_pins_both_and_off_never_pins() {
        assert!(Placement::resolve(&PinRequest::Auto, true, &[0, 1], 0).is_none());
        assert!(Placement::resolve(&PinRequest::Auto, false, &[3], 0).is_none());
        assert!(Placement::resolve(&PinRequest::Off, false, &[0, 1], 0).is_none());
        let always = Placement::resolve(&PinRequest::Always, true, &[0, 1], 0).unwrap();
        assert_eq!(always.describe(5), "plant cpu 0, agents 1 0 1 0 1");
        assert!(Placement::adapts(&PinRequest::Auto, false));
        assert!(!Placement::adapts(&PinRequest::Auto, true));
        assert!(!Placement::adapts(&PinRequest::Always, false));
        assert!(!Placement::adapts(&PinRequest::Cpus(vec![0, 1]), false));
        let explicit = Placement::resolve(&PinRequest::Cpus(vec![1]), true, &[0, 1], 0).unwrap();
        assert_eq!((explicit.plant(), explicit.agent(3)), (1, 1));
    }

    #[test]
    fn pin_requests_parse_and_bad_lists_name_the_flag() {
        assert_eq!(PinRequest::parse("auto", &[0, 1]), Ok(PinRequest::Auto));
        assert_eq!(PinRequest::parse("off", &[0, 1]), Ok(PinRequest::Off));
        assert_eq!(PinRequest::parse("always", &[0, 1]), Ok(PinRequest::Always));
        assert_eq!(
            PinRequest::parse("1,0", &[0, 1]),
            Ok(PinRequest::Cpus(vec![1, 0]))
        );
        let e = PinRequest::parse("5", &[0, 1]).unwrap_err().to_string();
        assert!(e.starts_with("--pin:"), "{e}");
    }
}
