//! Placement and scheduling that adapt to the load of others (lockstep runs).
//!
//! On idle CPUs a lockstep step is fastest pinned (`--pin auto`, ~9 %, docs/runtime.md "Cost of a
//! step") and under `SCHED_BATCH` (~12 %: a woken process does not preempt the one that woke it).
//! Beside programs that compute, both turn against the run: every hop of the step chain then waits
//! for a whole scheduler slice of the other program, because a pinned process cannot move to
//! another CPU and a `SCHED_BATCH` process never preempts. Beside two CPU-bound loops on 2 vCPUs
//! the pinned paper step took ~49x its idle time and a 20-ring step ~14x even unpinned
//! (docs/measurements.md). So the run has two modes, *quiet* and *busy*:
//!
//! * quiet: plant and agents pinned to the layout (`--pin auto` only) under `SCHED_BATCH`;
//! * busy: plant and agents unpinned (`--pin auto` only) under `SCHED_OTHER` at [`BUSY_NICE`]
//!   (nice 0 without the privilege to lower it), so that each wakes up ahead of other work.
//!
//! Before spawning, the CPUs are sampled over [`START_WINDOW`]; if one is busy with other work
//! above [`START_BUSY_ABOVE`], the run starts busy ([`PinGovernor::start`]). During the run a
//! thread of the orchestrator samples every [`SAMPLE_EVERY`] the load of others on each CPU (the
//! CPU's busy time less what this run's processes used there, [`foreign_loads`]) and turns busy
//! when it stays above [`UNPIN_ABOVE`], quiet again when it stays below [`REPIN_BELOW`]
//! ([`PinGovernor::next`]). `--pin always`, `--pin off` and a CPU list keep their placement; the
//! scheduling adapts in every lockstep run.
//!
//! The decisions are a pure state machine ([`PinGovernor`]); the /proc reading is
//! [`super::proc_load`]. A failure to read /proc leaves the run as it is, with one warning.
//! Neither placement nor scheduling changes what a lockstep run computes, only how fast.

use super::placement::Placement;
use super::proc_load::{self, CpuTimes, Sched};
use super::spawn::RoleProcess;
use std::collections::HashMap;
use std::sync::mpsc::{self, RecvTimeoutError};
use std::sync::{Arc, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::Duration;

/// Window over which the CPUs are sampled before the role processes start (200 ms): 20 clock
/// ticks of `/proc/stat` per CPU at `USER_HZ` = 100, enough to tell a CPU-bound program (~100 %)
/// from background noise, short enough not to delay a run noticeably.
pub const START_WINDOW: Duration = Duration::from_millis(200);

/// Load of others on a CPU of the layout, as a fraction of that CPU, above which a run starts
/// unpinned (0.30). A CPU-bound program takes ~1.0 of a CPU; the noise of an otherwise idle
/// machine (daemons, a shell) stays well below 0.1. Lower than [`UNPIN_ABOVE`]: before the run
/// nothing of its own is subtracted, so the sample is exact up to the tick resolution (5 % here),
/// and starting unpinned costs at most the ~9 % pinning gains while a pinned start beside a busy
/// program costs many times the step until the governor reacts.
pub const START_BUSY_ABOVE: f64 = 0.30;

/// Period of the governor's samples during the run (500 ms): 50 ticks per CPU, so the load of
/// others is known to a few % once the run's own time is subtracted; reacts within ~1 s.
pub const SAMPLE_EVERY: Duration = Duration::from_millis(500);

/// Load of others on a pinned CPU, as a fraction of that CPU, above which plant and agents are
/// unpinned (0.50) once it held for [`UNPIN_AFTER`] samples in a row: half a CPU taken by others
/// is a program that is runnable most of the time, which a pinned hop has to wait behind.
/// Above [`START_BUSY_ABOVE`] because during the run the estimate subtracts the run's own CPU
/// time, sampled by the kernel at tick resolution, and is noisier.
pub const UNPIN_ABOVE: f64 = 0.50;

/// Samples in a row above [`UNPIN_ABOVE`] before unpinning (2, i.e. ~1 s): one burst (a short
/// command, a page-cache flush) does not unpin.
pub const UNPIN_AFTER: u32 = 2;

/// Load of others, as a fraction of a CPU, below which every CPU of the layout must stay for
/// [`REPIN_AFTER`] samples in a row before plant and agents are pinned again (0.20). Well below
/// [`UNPIN_ABOVE`] (hysteresis): a load hovering near one threshold cannot make the placement
/// flip back and forth.
pub const REPIN_BELOW: f64 = 0.20;

/// Samples in a row below [`REPIN_BELOW`] before pinning again (6, i.e. ~3 s of [`SAMPLE_EVERY`]):
/// a build pauses between compile jobs for about a second; pinning into such a pause and
/// unpinning 1 s later would cost more than it gains.
pub const REPIN_AFTER: u32 = 6;

/// Nice value of plant and agents while other work computes on the run's CPUs (-10): at this
/// weight (9.3x that of nice 0) a woken role process preempts a CPU-bound program at once. Beside
/// two CPU-bound loops on 2 vCPUs, a 20-ring lockstep step (docs/measurements.md, "Pinning beside
/// other work"): `SCHED_BATCH` ~1.4-3.9 ms, `SCHED_OTHER` nice 0 ~0.8 ms, nice -10 ~0.44 ms, against
/// ~0.28 ms idle. Lowering nice needs CAP_SYS_NICE (root has it); without it the processes run at
/// nice 0 and the run says so. Not a real-time policy: a lockstep run keeps a CPU busy for as long
/// as it lasts, and under `SCHED_FIFO` it would starve everything else there.
pub const BUSY_NICE: i32 = -10;

/// Load of others on one CPU over a sample, as a fraction of that CPU (0.0 ..= 1.0).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CpuLoad {
    /// The CPU.
    pub cpu: usize,
    /// Its busy time not spent by this run, over the time that passed.
    pub foreign: f64,
}

/// What the governor decides after a sample.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Decision {
    /// Keep the placement as it is.
    Nothing,
    /// Unpin plant and agents: this CPU is busy with other work.
    Unpin(CpuLoad),
    /// Pin plant and agents to the layout again: every CPU has been quiet.
    Pin,
}

/// The adaptive placement's decisions, from load samples alone (no processes, no clock).
#[derive(Debug, Clone, PartialEq)]
pub struct PinGovernor {
    pinned: bool,
    /// Samples in a row with a CPU above [`UNPIN_ABOVE`] (while pinned).
    over: u32,
    /// Samples in a row with every CPU below [`REPIN_BELOW`] (while unpinned).
    under: u32,
}

/// The CPU most loaded by others in `sample`, if any is above `threshold`.
fn busiest_above(sample: &[CpuLoad], threshold: f64) -> Option<CpuLoad> {
    sample
        .iter()
        .copied()
        .filter(|l| l.foreign > threshold)
        .max_by(|a, b| a.foreign.total_cmp(&b.foreign))
}

impl PinGovernor {
    /// The start, from a sample taken before the role processes exist: pinned, unless a CPU is
    /// busier than [`START_BUSY_ABOVE`] (then that CPU is returned as the reason).
    pub fn start(sample: &[CpuLoad]) -> (PinGovernor, Option<CpuLoad>) {
        let busy = busiest_above(sample, START_BUSY_ABOVE);
        let governor = PinGovernor {
            pinned: busy.is_none(),
            over: 0,
            under: 0,
        };
        (governor, busy)
    }

    /// Whether plant and agents are pinned now.
    pub fn pinned(&self) -> bool {
        self.pinned
    }

    /// The decision after one sample of the run (every CPU of the layout).
    pub fn next(&mut self, sample: &[CpuLoad]) -> Decision {
        if self.pinned {
            let busy = busiest_above(sample, UNPIN_ABOVE);
            self.over = if busy.is_some() { self.over + 1 } else { 0 };
            match busy {
                Some(load) if self.over >= UNPIN_AFTER => {
                    *self = PinGovernor {
                        pinned: false,
                        over: 0,
                        under: 0,
                    };
                    Decision::Unpin(load)
                }
                _ => Decision::Nothing,
            }
        } else {
            if sample.iter().all(|l| l.foreign < REPIN_BELOW) {
                self.under += 1;
            } else {
                self.under = 0;
            }
            if self.under >= REPIN_AFTER {
                *self = PinGovernor {
                    pinned: true,
                    over: 0,
                    under: 0,
                };
                Decision::Pin
            } else {
                Decision::Nothing
            }
        }
    }
}

/// The load of others on each CPU of `layout` between two readings of `/proc/stat`: the CPU's
/// busy time less the CPU time this run's processes spent there (`own`: clock ticks per process
/// over the same interval, with the CPU it was pinned to, `None` when it may run anywhere), over
/// the time that passed for that CPU. A process that may run anywhere (the orchestrator, the
/// leader, everything while unpinned) counts an equal share on every CPU of the layout.
pub fn foreign_loads(
    before: &[(usize, CpuTimes)],
    after: &[(usize, CpuTimes)],
    layout: &[usize],
    own: &[(Option<usize>, u64)],
) -> Vec<CpuLoad> {
    let anywhere: u64 = own.iter().filter(|(c, _)| c.is_none()).map(|o| o.1).sum();
    let share = anywhere as f64 / layout.len().max(1) as f64;
    layout
        .iter()
        .filter_map(|&cpu| {
            let find = |s: &[(usize, CpuTimes)]| s.iter().find(|(c, _)| *c == cpu).map(|x| x.1);
            let (b, a) = (find(before)?, find(after)?);
            let total = a.total.saturating_sub(b.total);
            let busy = a.busy.saturating_sub(b.busy) as f64;
            let pinned_here: u64 = own
                .iter()
                .filter(|(c, _)| *c == Some(cpu))
                .map(|o| o.1)
                .sum();
            let foreign = if total == 0 {
                0.0
            } else {
                ((busy - pinned_here as f64 - share) / total as f64).clamp(0.0, 1.0)
            };
            Some(CpuLoad { cpu, foreign })
        })
        .collect()
}

/// Where a process of the run goes when plant and agents are pinned.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Place {
    /// The plant's CPU of the layout.
    Plant,
    /// Agent i's CPU of the layout.
    Agent(usize),
    /// Never pinned (leader, orchestrator).
    Anywhere,
}

#[derive(Debug, Clone, Copy)]
struct Member {
    pid: u32,
    place: Place,
}

#[derive(Debug)]
struct State {
    /// Quiet (pinned where the placement adapts, `SCHED_BATCH`) or busy.
    quiet: bool,
    /// Whether [`BUSY_NICE`] was granted when last asked for (`None`: not asked yet).
    boosted: Option<bool>,
    members: Vec<Member>,
}

/// What adapts to the load of others in a run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Adapts {
    /// Nothing (realtime runs: their scheduling is their own, docs/realtime.md).
    Nothing,
    /// The scheduling policy of plant and agents (lockstep with `--pin off`, `always` or a list).
    Scheduling,
    /// Scheduling and pinning (lockstep with `--pin auto`).
    SchedulingAndPinning,
}

/// The run's placement and scheduling as they are now, shared by the spawns (a taken-over agent
/// starts where and as its predecessor would be now) and the governor.
#[derive(Debug, Clone)]
pub struct Pins {
    layout: Option<Placement>,
    adapts: Adapts,
    state: Arc<Mutex<State>>,
    /// Why the run started busy.
    busy_because: Option<CpuLoad>,
}

impl Pins {
    /// A placement that does not adapt: pinned to `layout`, or not at all.
    pub fn fixed(layout: Option<Placement>) -> Pins {
        Pins::with(layout, Adapts::Nothing, true, None)
    }

    fn with(
        layout: Option<Placement>,
        adapts: Adapts,
        quiet: bool,
        busy_because: Option<CpuLoad>,
    ) -> Pins {
        Pins {
            layout,
            adapts,
            state: Arc::new(Mutex::new(State {
                quiet,
                boosted: None,
                members: Vec::new(),
            })),
            busy_because,
        }
    }

    fn lock(&self) -> MutexGuard<'_, State> {
        self.state.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Whether the run is quiet now: the role processes it spawns inherit `SCHED_BATCH` from the
    /// orchestrator (see `run`) when they are.
    pub fn quiet(&self) -> bool {
        self.lock().quiet
    }

    /// The scheduling of plant and agents in mode `quiet`, if it adapts.
    fn sched(&self, quiet: bool) -> Option<Sched> {
        match (self.adapts, quiet) {
            (Adapts::Nothing, _) => None,
            (_, true) => Some(Sched::Batch),
            (_, false) => Some(Sched::Other { nice: BUSY_NICE }),
        }
    }

    fn cpu_of(&self, place: Place, quiet: bool) -> Option<usize> {
        let pinned = quiet || self.adapts != Adapts::SchedulingAndPinning;
        let layout = self.layout.as_ref().filter(|_| pinned)?;
        match place {
            Place::Plant => Some(layout.plant()),
            Place::Agent(i) => Some(layout.agent(i)),
            Place::Anywhere => None,
        }
    }

    /// Starts a process at `place` with `spawn` (given its CPU now, `None`: not pinned) and
    /// records it; the placement does not change meanwhile.
    pub fn spawn<E>(
        &self,
        place: Place,
        spawn: impl FnOnce(Option<usize>) -> Result<RoleProcess, E>,
    ) -> Result<RoleProcess, E> {
        let mut state = self.lock();
        let child = spawn(self.cpu_of(place, state.quiet))?;
        if place != Place::Anywhere {
            if let Some(sched) = self.sched(state.quiet) {
                // A successor spawned from a thread at the background nice, or a busy run's
                // processes: as the run's mode is now. Scheduling is an optimisation.
                if let Ok(granted) = proc_load::set_process_sched(child.pid(), sched) {
                    state.boosted.get_or_insert(granted);
                }
            }
        }
        state.add(child.pid(), place);
        Ok(child)
    }

    /// Records a process of the run that is never pinned (its CPU time is the run's own).
    pub fn add_anywhere(&self, pid: u32) {
        self.lock().add(pid, Place::Anywhere);
    }

    /// One line for the log and the console: the layout (`plant cpu 0, agents 1 0 1 0 1`) or
    /// `not pinned`, with the reason when the layout was left for the load of others.
    pub fn describe(&self, n: usize) -> String {
        let (quiet, boosted) = {
            let s = self.lock();
            (s.quiet, s.boosted)
        };
        let placement = match (&self.layout, self.busy_because) {
            (Some(l), _) if self.cpu_of(Place::Plant, quiet).is_some() => l.describe(n),
            (Some(_), Some(load)) => format!(
                "not pinned: cpu {} busy with other work ({:.0} % of a CPU over {} ms; `--pin always` pins anyway)",
                load.cpu,
                100.0 * load.foreign,
                START_WINDOW.as_millis()
            ),
            _ => "not pinned".to_string(),
        };
        match self.sched(quiet) {
            Some(Sched::Other { nice }) => {
                format!(
                    "{placement}; {}",
                    describe_busy(nice, boosted.unwrap_or(true))
                )
            }
            _ => placement,
        }
    }

    /// Puts every thread of plant and agents in mode `quiet`: pinned (or unpinned, to
    /// `allowed`) where the placement adapts, and scheduled as [`Pins::sched`] says. The first
    /// failure other than an exited process is returned, the others are still moved. Returns
    /// whether [`BUSY_NICE`] was granted (true when not asked for).
    fn apply(&self, quiet: bool, allowed: &[usize]) -> Result<bool, MoveError> {
        let mut state = self.lock();
        state.quiet = quiet;
        let mut first_error = None;
        let mut granted = true;
        for m in &state.members {
            if m.place == Place::Anywhere {
                continue;
            }
            if self.adapts == Adapts::SchedulingAndPinning {
                let cpus = match self.cpu_of(m.place, quiet) {
                    Some(c) => vec![c],
                    None => allowed.to_vec(),
                };
                if let Err(e) = proc_load::set_process_affinity(m.pid, &cpus) {
                    first_error.get_or_insert(MoveError::Cpus {
                        pid: m.pid,
                        source: e,
                    });
                }
            }
            if let Some(sched) = self.sched(quiet) {
                match proc_load::set_process_sched(m.pid, sched) {
                    Ok(g) => granted &= g,
                    Err(e) => {
                        first_error.get_or_insert(MoveError::Sched {
                            pid: m.pid,
                            source: e,
                        });
                    }
                }
            }
        }
        if !quiet {
            state.boosted = Some(granted);
        }
        first_error.map_or(Ok(granted), Err)
    }

    /// The run's processes now: (pid, CPU it is pinned to).
    fn members(&self) -> Vec<(u32, Option<usize>)> {
        let state = self.lock();
        state
            .members
            .iter()
            .map(|m| (m.pid, self.cpu_of(m.place, state.quiet)))
            .collect()
    }

    /// The CPUs whose load of others decides the mode: the layout's, else `allowed`.
    fn watched(&self, allowed: &[usize]) -> Vec<usize> {
        self.layout
            .as_ref()
            .map_or_else(|| allowed.to_vec(), Placement::cpus)
    }
}

impl State {
    /// A process at a place (an agent's successor replaces it).
    fn add(&mut self, pid: u32, place: Place) {
        match self
            .members
            .iter_mut()
            .find(|m| m.place == place && place != Place::Anywhere)
        {
            Some(m) => m.pid = pid,
            None => self.members.push(Member { pid, place }),
        }
    }
}

/// One line on the scheduling of a busy run: `nice` granted or not.
fn describe_busy(nice: i32, granted: bool) -> String {
    if granted {
        format!("plant and agents under SCHED_OTHER at nice {nice} beside other work")
    } else {
        format!(
            "plant and agents under SCHED_OTHER at nice 0 beside other work (nice {nice} needs CAP_SYS_NICE)"
        )
    }
}

/// The placement of a run before its processes start: `layout` as resolved from `--pin`;
/// `adapts` what adapts to the load of others. Unless nothing does, the CPUs (the layout's, else
/// `allowed`) are sampled first (over [`START_WINDOW`]) and a governor is returned for
/// [`Governor::start`].
pub fn decide_start(
    layout: Option<Placement>,
    adapts: Adapts,
    allowed: &[usize],
) -> (Pins, Option<PinGovernor>) {
    if adapts == Adapts::Nothing {
        return (Pins::fixed(layout), None);
    }
    let cpus = layout
        .as_ref()
        .map_or_else(|| allowed.to_vec(), Placement::cpus);
    let sample = proc_load::cpu_times().and_then(|before| {
        std::thread::sleep(START_WINDOW);
        let after = proc_load::cpu_times()?;
        // This process sleeps meanwhile: nothing of the run is subtracted.
        Ok(foreign_loads(&before, &after, &cpus, &[]))
    });
    match sample {
        Ok(loads) => {
            let (governor, busy) = PinGovernor::start(&loads);
            (
                Pins::with(layout, adapts, governor.pinned(), busy),
                Some(governor),
            )
        }
        Err(e) => {
            eprintln!("warning: {e}; the placement does not adapt to the load of others");
            (Pins::fixed(layout), None)
        }
    }
}

/// Why a process of the run could not be moved to the governor's mode.
#[derive(Debug, thiserror::Error)]
pub enum MoveError {
    /// Its CPUs cannot be set.
    #[error("cannot set the CPUs of pid {pid}: {source}")]
    Cpus {
        /// The process.
        pid: u32,
        /// The system's error.
        source: std::io::Error,
    },
    /// Its scheduling cannot be set.
    #[error("cannot set the scheduling of pid {pid}: {source}")]
    Sched {
        /// The process.
        pid: u32,
        /// The system's error.
        source: std::io::Error,
    },
}

/// The governor's thread; dropping it stops the thread (at once: it sleeps on a channel).
pub struct Governor {
    stop: Option<mpsc::Sender<()>>,
    thread: Option<JoinHandle<()>>,
}

impl Governor {
    /// Starts sampling every [`SAMPLE_EVERY`]; `allowed` is where unpinned processes may run.
    pub fn start(pins: Pins, governor: PinGovernor, allowed: Vec<usize>) -> Governor {
        let (stop, stopped) = mpsc::channel();
        let thread = std::thread::Builder::new()
            .name("pin-governor".into())
            .spawn(move || govern(&pins, governor, &allowed, &stopped))
            .map_err(|e| eprintln!("warning: cannot start the placement governor: {e}"))
            .ok();
        Governor {
            stop: Some(stop),
            thread,
        }
    }
}

impl Drop for Governor {
    fn drop(&mut self) {
        drop(self.stop.take());
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// One reading: every CPU's times and the CPU time of each process of the run.
struct Reading {
    cpus: Vec<(usize, CpuTimes)>,
    /// (pid, CPU it is pinned to, clock ticks so far).
    processes: Vec<(u32, Option<usize>, u64)>,
}

impl Reading {
    fn take(pins: &Pins) -> Result<Reading, proc_load::LoadError> {
        let members = pins.members();
        let cpus = proc_load::cpu_times()?;
        let processes = members
            .into_iter()
            .filter_map(|(pid, cpu)| Some((pid, cpu, proc_load::process_ticks(pid)?)))
            .collect();
        Ok(Reading { cpus, processes })
    }

    /// Ticks each process used since `before` (all of them for a process started since).
    fn own_since(&self, before: &Reading) -> Vec<(Option<usize>, u64)> {
        let earlier: HashMap<u32, u64> = before.processes.iter().map(|p| (p.0, p.2)).collect();
        self.processes
            .iter()
            .map(|&(pid, cpu, ticks)| {
                let from = earlier.get(&pid).copied().unwrap_or(0);
                (cpu, ticks.saturating_sub(from))
            })
            .collect()
    }
}

fn govern(pins: &Pins, mut governor: PinGovernor, allowed: &[usize], stopped: &mpsc::Receiver<()>) {
    let cpus = pins.watched(allowed);
    let pinning = pins.adapts == Adapts::SchedulingAndPinning && pins.layout.is_some();
    let give_up = |e: &dyn std::fmt::Display| {
        eprintln!("warning: {e}; the placement stays as it is");
        tracing::warn!("placement governor stopped: {e}");
    };
    let mut before = match Reading::take(pins) {
        Ok(r) => r,
        Err(e) => return give_up(&e),
    };
    while let Err(RecvTimeoutError::Timeout) = stopped.recv_timeout(SAMPLE_EVERY) {
        let after = match Reading::take(pins) {
            Ok(r) => r,
            Err(e) => return give_up(&e),
        };
        let loads = foreign_loads(&before.cpus, &after.cpus, &cpus, &after.own_since(&before));
        before = after;
        let quiet = match governor.next(&loads) {
            Decision::Nothing => continue,
            Decision::Unpin(_) => false,
            Decision::Pin => true,
        };
        let granted = match pins.apply(quiet, allowed) {
            Ok(g) => g,
            Err(e) => return give_up(&e),
        };
        let line = match governor_line(&loads, quiet, pinning, granted) {
            Some(l) => l,
            None => continue,
        };
        eprintln!("formation run: {line}");
        tracing::info!("{line}");
    }
}

/// What the run says when it turns busy (`quiet` false) or quiet again after `loads`.
fn governor_line(loads: &[CpuLoad], quiet: bool, pinning: bool, granted: bool) -> Option<String> {
    if quiet {
        let what = if pinning {
            "pinned again, under SCHED_BATCH"
        } else {
            "plant and agents under SCHED_BATCH again"
        };
        return Some(format!(
            "other work under {:.0} % of every CPU for {:.1} s: {what}",
            100.0 * REPIN_BELOW,
            (REPIN_AFTER * SAMPLE_EVERY).as_secs_f64()
        ));
    }
    let load = busiest_above(loads, UNPIN_ABOVE)?;
    let unpinned = if pinning { "unpinned; " } else { "" };
    Some(format!(
        "cpu {} busy with other work ({:.0} % of a CPU for {} samples of {} ms): {unpinned}{}",
        load.cpu,
        100.0 * load.foreign,
        UNPIN_AFTER,
        SAMPLE_EVERY.as_millis(),
        describe_busy(BUSY_NICE, granted)
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(loads: &[f64]) -> Vec<CpuLoad> {
        loads
            .iter()
            .enumerate()
            .map(|(cpu, &foreign)| CpuLoad { cpu, foreign })
            .collect()
    }

    /// The decisions for a script of samples, from a start on an idle machine.
    fn script(samples: &[[f64; 2]]) -> Vec<Decision> {
        let (mut g, _) = PinGovernor::start(&sample(&[0.0, 0.0]));
        samples.iter().map(|s| g.next(&sample(s))).collect()
    }

    fn changes(d: &[Decision]) -> usize {
        d.iter().filter(|d| **d != Decision::Nothing).count()
    }

    #[test]
    fn an_idle_machine_starts_pinned_and_stays_pinned() {
        let (g, reason) = PinGovernor::start(&sample(&[0.05, 0.02]));
        assert!(g.pinned());
        assert_eq!(reason, None);
        let d = script(&[[0.1, 0.05]; 40]);
        assert_eq!(changes(&d), 0);
    }

    #[test]
    fn a_cpu_busy_with_other_work_at_the_start_starts_unpinned_naming_it() {
        let (g, reason) = PinGovernor::start(&sample(&[0.1, 0.95]));
        assert!(!g.pinned());
        assert_eq!(
            reason,
            Some(CpuLoad {
                cpu: 1,
                foreign: 0.95
            })
        );
        // Just under the threshold: pinned.
        let (g, _) = PinGovernor::start(&sample(&[START_BUSY_ABOVE - 0.01, 0.0]));
        assert!(g.pinned());
    }

    #[test]
    fn other_work_mid_run_unpins_after_two_samples_not_after_one() {
        let d = script(&[[0.0, 0.0], [0.9, 0.1], [0.85, 0.1], [0.9, 0.1]]);
        assert_eq!(d[1], Decision::Nothing, "one sample is not enough");
        assert_eq!(
            d[2],
            Decision::Unpin(CpuLoad {
                cpu: 0,
                foreign: 0.85
            })
        );
        assert_eq!(d[3], Decision::Nothing, "said once");
    }

    #[test]
    fn quiet_again_pins_again_after_the_hysteresis_only() {
        let (mut g, _) = PinGovernor::start(&sample(&[0.9, 0.9]));
        let quiet = sample(&[0.1, REPIN_BELOW - 0.01]);
        for k in 1..REPIN_AFTER {
            assert_eq!(g.next(&quiet), Decision::Nothing, "sample {k}");
        }
        assert_eq!(g.next(&quiet), Decision::Pin);
        assert!(g.pinned());
        // A load between the two thresholds neither unpins nor pins.
        let mut d = script(&[[0.9, 0.0], [0.9, 0.0]]);
        assert!(matches!(d[1], Decision::Unpin(_)));
        let mut g2 = PinGovernor {
            pinned: false,
            over: 0,
            under: 0,
        };
        d = (0..20).map(|_| g2.next(&sample(&[0.35, 0.0]))).collect();
        assert_eq!(changes(&d), 0);
    }

    #[test]
    fn a_flickering_load_does_not_thrash() {
        // Busy one sample in two: never two in a row, never unpinned.
        let flicker: Vec<[f64; 2]> = (0..40)
            .map(|k| if k % 2 == 0 { [0.95, 0.0] } else { [0.05, 0.0] })
            .collect();
        assert_eq!(changes(&script(&flicker)), 0);
        // Busy two in three: unpinned once, and the quiet samples never last long enough to pin.
        let bursts: Vec<[f64; 2]> = (0..60)
            .map(|k| if k % 3 == 2 { [0.05, 0.0] } else { [0.95, 0.0] })
            .collect();
        let d = script(&bursts);
        assert_eq!(changes(&d), 1, "{d:?}");
    }

    fn t(busy: u64, total: u64) -> CpuTimes {
        CpuTimes { busy, total }
    }

    #[test]
    fn the_load_of_others_is_a_cpus_busy_time_less_the_runs_own_there_and_its_share_of_the_rest() {
        let before = [(0, t(1000, 5000)), (1, t(2000, 5000))];
        let after = [(0, t(1040, 5050)), (1, t(2030, 5050))];
        // CPU 0: 40 busy ticks of 50; the plant pinned there used 25, the orchestrator and leader
        // (anywhere) 10, counted 5 on each CPU: 10 of others. CPU 1: 30 busy, agents 20 + 5.
        let own = [(Some(0), 25), (Some(1), 20), (None, 6), (None, 4)];
        let loads = foreign_loads(&before, &after, &[0, 1], &own);
        assert_eq!(loads.len(), 2);
        assert!((loads[0].foreign - 10.0 / 50.0).abs() < 1e-12, "{loads:?}");
        assert!((loads[1].foreign - 5.0 / 50.0).abs() < 1e-12, "{loads:?}");
        // Never below zero (tick sampling can put the run's time above the CPU's), a CPU without
        // a reading is left out, and no time passed is no load.
        let loads = foreign_loads(&before, &after, &[0, 1, 7], &[(Some(0), 60)]);
        assert_eq!(loads[0].foreign, 0.0);
        assert_eq!(loads.len(), 2);
        assert_eq!(foreign_loads(&before, &before, &[0], &[])[0].foreign, 0.0);
    }

    fn auto_layout() -> Option<Placement> {
        Placement::resolve(
            &super::super::placement::PinRequest::Auto,
            false,
            &[0, 1],
            0,
        )
    }

    #[test]
    fn a_successor_takes_its_agents_place_and_spawns_follow_the_placement_now() {
        let pins = Pins::with(auto_layout(), Adapts::SchedulingAndPinning, true, None);
        {
            let mut s = pins.lock();
            s.add(10, Place::Plant);
            s.add(11, Place::Agent(0));
            s.add(12, Place::Anywhere);
            s.add(13, Place::Anywhere);
            s.add(14, Place::Agent(0));
        }
        assert_eq!(
            pins.members(),
            [(10, Some(0)), (14, Some(1)), (12, None), (13, None)]
        );
        pins.lock().quiet = false;
        assert_eq!(pins.cpu_of(Place::Agent(0), false), None);
        assert!(
            pins.describe(5)
                .starts_with("not pinned; plant and agents under SCHED_OTHER"),
            "{}",
            pins.describe(5)
        );
        let busy = Pins::with(
            auto_layout(),
            Adapts::SchedulingAndPinning,
            false,
            Some(CpuLoad {
                cpu: 1,
                foreign: 0.97,
            }),
        );
        assert!(
            busy.describe(5)
                .starts_with("not pinned: cpu 1 busy with other work (97 % of a CPU over 200 ms"),
            "{}",
            busy.describe(5)
        );
    }

    #[test]
    fn a_busy_run_is_scheduled_to_preempt_other_work_and_a_quiet_one_under_batch() {
        let pins = Pins::with(auto_layout(), Adapts::SchedulingAndPinning, true, None);
        assert_eq!(pins.sched(true), Some(Sched::Batch));
        assert_eq!(pins.sched(false), Some(Sched::Other { nice: BUSY_NICE }));
        const {
            assert!(
                BUSY_NICE < 0,
                "busy processes must outweigh nice-0 programs"
            )
        };
        // Realtime runs keep their own scheduling.
        assert_eq!(Pins::fixed(auto_layout()).sched(false), None);
    }

    #[test]
    fn pin_always_and_pin_off_keep_their_placement_while_the_scheduling_adapts() {
        // `--pin always`: pinned in both modes.
        let always = Pins::with(auto_layout(), Adapts::Scheduling, false, None);
        assert_eq!(always.cpu_of(Place::Plant, false), Some(0));
        assert_eq!(always.sched(false), Some(Sched::Other { nice: BUSY_NICE }));
        assert!(
            always.describe(5).starts_with("plant cpu 0"),
            "{}",
            always.describe(5)
        );
        // `--pin off`: never pinned; the CPUs watched are those it may use.
        let off = Pins::with(None, Adapts::Scheduling, true, None);
        assert_eq!(off.cpu_of(Place::Plant, true), None);
        assert_eq!(off.watched(&[0, 1]), vec![0, 1]);
        assert_eq!(off.describe(5), "not pinned");
    }

    #[test]
    fn the_run_says_when_it_turns_busy_naming_the_cpu_and_the_nice_granted() {
        let loads = sample(&[0.1, 0.9]);
        let line = governor_line(&loads, false, true, true).expect("a line");
        assert!(
            line.starts_with("cpu 1 busy with other work (90 % of a CPU"),
            "{line}"
        );
        assert!(
            line.contains("unpinned; plant and agents under SCHED_OTHER at nice -10"),
            "{line}"
        );
        let refused = governor_line(&loads, false, false, false).expect("a line");
        assert!(!refused.contains("unpinned"), "{refused}");
        assert!(
            refused.contains("at nice 0") && refused.contains("CAP_SYS_NICE"),
            "{refused}"
        );
        let quiet = governor_line(&sample(&[0.0, 0.0]), true, true, true).expect("a line");
        assert!(
            quiet.ends_with("pinned again, under SCHED_BATCH"),
            "{quiet}"
        );
    }
}
