//! The supervision of a lockstep run's agents as a state machine (`docs/failures.md`): when to
//! kill or stop an agent process for a timeline crash or hang, when to start the process that
//! takes over, what to do when one dies or hangs outside the timeline. Every decision is a pure
//! function of what the driver tells it (steps recorded, deaths, hellos, the plant's take-downs);
//! the driver carries the actions out. No iceoryx2, no processes.

use formation_config::protocol::messages::{RuntimeEvent, EVENT_ANY, EVENT_UP_AGAIN};
use formation_config::scenario::events::{
    DownWindow, EventKind, RestartPolicy, RestartState, Runtime, Timeline,
};

/// What the driver must do.
#[derive(Debug, Clone, PartialEq)]
pub enum Action {
    /// SIGKILL agent i's process (a timeline crash; its last command is in) and reap it.
    Kill(usize),
    /// SIGSTOP agent i's process (a timeline hang).
    Stop(usize),
    /// Start the process that takes over agent i at `plan.rejoin_at` (after SIGKILLing a stopped
    /// one), rebuilding from the recorded states.
    Respawn(Plan),
    /// Agent i's new process has its ports: the plant may send it the states of `step`.
    Joined {
        /// Agent index.
        agent: usize,
        /// Its first step.
        step: u64,
    },
    /// Agent i's process is gone: ask the plant to take it down.
    TakeDown(usize),
    /// Tell every process that agent i's new process takes over at `step` (published ahead).
    Announce(RuntimeEvent),
    /// Start a fresh process for agent i from the scenario's initial state, as at launch: it was
    /// lost before the run's first step, so there is nothing to rebuild.
    Relaunch(usize),
    /// Stop the run with this message (exit 1).
    Fail(String),
}

/// The takeover of one agent.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Plan {
    /// Agent index.
    pub agent: usize,
    /// First step the old process did not compute.
    pub down_from: u64,
    /// First step the new process computes.
    pub rejoin_at: u64,
    /// Restore the last checkpoint (a hang always resumes warm).
    pub warm: bool,
    /// A timeline event (not a restart under the policy).
    pub scheduled: bool,
}

/// The pause before a successor starts again after `failed` consecutive starts that did not
/// come up (0: at once), s: 100 ms doubled per failed start, at most [`BACKOFF_CAP`].
pub fn restart_backoff(failed: u32) -> std::time::Duration {
    if failed == 0 {
        return std::time::Duration::ZERO;
    }
    BACKOFF_BASE
        .saturating_mul(1 << (failed - 1).min(16))
        .min(BACKOFF_CAP)
}

/// The first pause of [`restart_backoff`].
pub const BACKOFF_BASE: std::time::Duration = std::time::Duration::from_millis(100);
/// The longest pause of [`restart_backoff`].
pub const BACKOFF_CAP: std::time::Duration = std::time::Duration::from_secs(2);
/// Starts refused because a predecessor still holds the agent's ports (exit 75) that are waited
/// out, with the backoff, before the run stops (about 13 s): longer than a fence takes.
pub const MAX_HELD_STARTS: u32 = 10;

/// How an agent process ended, as the supervision tells them apart.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Ending {
    /// It died, exited with an error or was killed as hung: a restart under the policy.
    Failed,
    /// It could not make its ports because its predecessor still holds them (exit 75): it waits
    /// for the predecessor to be fenced, not counted against `runtime.max_restarts`.
    PortHeld,
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Slot {
    /// The process computes its steps.
    Running,
    /// Killed or stopped for a timeline window; waiting for its end.
    Parked(DownWindow),
    /// Died outside the timeline; the plant has been asked to take it down.
    Dead,
    /// Taken down from `from`; its successor takes over at `rejoin_at`.
    Down { from: u64, rejoin_at: u64 },
    /// A new process was started for `rejoin_at` and has not said hello yet.
    Spawned { rejoin_at: u64 },
}

/// The supervisor of N agents.
#[derive(Debug, Clone)]
pub struct Supervisor {
    runtime: Runtime,
    /// Steps ahead of the recorder that an announcement must be (the plant's lead plus slack).
    lead: u64,
    timeline: Timeline,
    slots: Vec<Slot>,
    restarts: Vec<u32>,
    /// Per agent: starts refused since its last join because a predecessor held its ports.
    held: Vec<u32>,
    /// Per agent: successors that ended since its last join before saying hello.
    failed_starts: Vec<u32>,
}

impl Supervisor {
    /// The supervisor of `n` agents on `timeline`, announcing `lead` steps ahead.
    pub fn new(n: usize, timeline: Timeline, runtime: Runtime, lead: u64) -> Supervisor {
        Supervisor {
            runtime,
            lead,
            timeline,
            slots: vec![Slot::Running; n],
            restarts: vec![0; n],
            held: vec![0; n],
            failed_starts: vec![0; n],
        }
    }

    /// How long agent i's next successor waits before it starts ([`restart_backoff`] of the
    /// successors that failed since its last join).
    pub fn backoff(&self, i: usize) -> std::time::Duration {
        restart_backoff(self.failed_starts[i])
    }

    /// Restarts under the policy, per agent.
    pub fn restarts(&self) -> &[u32] {
        &self.restarts
    }

    /// The timeline as the supervisor knows it.
    pub fn timeline(&self) -> &Timeline {
        &self.timeline
    }

    /// A runtime event added to the run (a live injection).
    pub fn add_event(&mut self, e: &RuntimeEvent) {
        e.apply(&mut self.timeline);
    }

    /// Whether agent i's process is expected to be gone (killed or stopped by the timeline).
    pub fn expects_gone(&self, i: usize) -> bool {
        matches!(self.slots[i], Slot::Parked(_))
    }

    /// Whether a takeover is under way: an agent is taken down or its successor has been started
    /// and has not said hello yet.
    pub fn taking_over(&self) -> bool {
        self.slots
            .iter()
            .any(|s| matches!(s, Slot::Dead | Slot::Down { .. } | Slot::Spawned { .. }))
    }

    /// Agent i's process was lost (with its host) before the run's first step, when nothing of it
    /// is to be rebuilt (`line` names it): under the policy a fresh process starts from the
    /// scenario's initial state ([`Action::Relaunch`], a restart like any other), otherwise the
    /// run stops.
    pub fn on_lost_at_start(&mut self, i: usize, line: &str) -> Action {
        match self.decide_restart(i, line, Ending::Failed) {
            Action::TakeDown(i) => {
                self.slots[i] = Slot::Running;
                Action::Relaunch(i)
            }
            other => other,
        }
    }

    /// Steps 0..recorded are recorded.
    pub fn on_recorded(&mut self, recorded: u64) -> Vec<Action> {
        let mut out = Vec::new();
        for i in 0..self.slots.len() {
            match self.slots[i] {
                Slot::Running => {
                    // Its last command before the window is in once the step before it is recorded.
                    let due = self.timeline.down_windows().iter().copied().find(|w| {
                        w.agent == i
                            && w.kind.takes_agent_down()
                            && w.to != u64::MAX
                            && w.from <= recorded
                            && w.to > recorded
                    });
                    if let Some(w) = due {
                        self.slots[i] = Slot::Parked(w);
                        out.push(if w.kind == EventKind::Hang {
                            Action::Stop(i)
                        } else {
                            Action::Kill(i)
                        });
                    }
                }
                Slot::Parked(w) if recorded >= w.to => {
                    self.slots[i] = Slot::Spawned { rejoin_at: w.to };
                    out.push(Action::Respawn(Plan {
                        agent: i,
                        down_from: w.from,
                        rejoin_at: w.to,
                        warm: w.kind == EventKind::Hang
                            || self.runtime.restart_state == RestartState::Warm,
                        scheduled: true,
                    }));
                }
                Slot::Down { from, rejoin_at } if recorded >= rejoin_at => {
                    self.slots[i] = Slot::Spawned { rejoin_at };
                    out.push(Action::Respawn(Plan {
                        agent: i,
                        down_from: from,
                        rejoin_at,
                        warm: self.runtime.restart_state == RestartState::Warm,
                        scheduled: false,
                    }));
                }
                _ => {}
            }
        }
        out
    }

    /// Agent i said hello.
    pub fn on_hello(&mut self, i: usize) -> Option<Action> {
        match self.slots.get(i) {
            Some(Slot::Spawned { rejoin_at }) => {
                let step = *rejoin_at;
                self.slots[i] = Slot::Running;
                self.held[i] = 0;
                self.failed_starts[i] = 0;
                Some(Action::Joined { agent: i, step })
            }
            _ => None,
        }
    }

    /// Agent i's process died (or was declared hung and killed) outside the timeline; `line`
    /// names it. `None`: the timeline killed it (expected).
    pub fn on_death(&mut self, i: usize, line: &str, ending: Ending) -> Option<Action> {
        match self.slots[i] {
            Slot::Parked(_) => return None,
            Slot::Running => {}
            Slot::Spawned { .. } => self.failed_starts[i] += 1,
            Slot::Dead | Slot::Down { .. } => {
                return Some(Action::Fail(format!("{line} while it was being replaced")))
            }
        }
        Some(self.decide_restart(i, line, ending))
    }

    fn decide_restart(&mut self, i: usize, line: &str, ending: Ending) -> Action {
        if self.runtime.restart == RestartPolicy::Never {
            return Action::Fail(line.to_string());
        }
        if ending == Ending::PortHeld {
            if self.held[i] >= MAX_HELD_STARTS {
                return Action::Fail(format!(
                    "{line}; agent {}'s ports were still held by a predecessor after {} starts",
                    i + 1,
                    self.held[i]
                ));
            }
            self.held[i] += 1;
            self.slots[i] = Slot::Dead;
            return Action::TakeDown(i);
        }
        if self.restarts[i] >= self.runtime.max_restarts {
            return Action::Fail(format!(
                "{line}; agent {} was restarted {} times already (runtime.max_restarts)",
                i + 1,
                self.restarts[i]
            ));
        }
        self.restarts[i] += 1;
        self.slots[i] = Slot::Dead;
        Action::TakeDown(i)
    }

    /// Realtime: agent i died (its restart counted by [`Supervisor::on_death`]) with `recorded`
    /// steps recorded, its last own command in the record of step `from - 1`. The plant already
    /// flies it on its fallback (its commands stopped coming), so no take-down is asked: its
    /// successor starts at once, replays its own steps before `from`, observes the fallback's from
    /// `from` to `recorded` (as a lockstep successor does its down window: bumpless re-entry and
    /// the re-seed of `runtime.rejoin_reseed`), and answers the newest states it gets.
    pub fn on_dead_realtime(&mut self, i: usize, from: u64, recorded: u64) -> Option<Action> {
        if self.slots.get(i) != Some(&Slot::Dead) {
            return None;
        }
        self.slots[i] = Slot::Spawned {
            rejoin_at: recorded,
        };
        Some(Action::Respawn(Plan {
            agent: i,
            down_from: from.min(recorded),
            rejoin_at: recorded,
            warm: self.runtime.restart_state == RestartState::Warm,
            scheduled: false,
        }))
    }

    /// The plant took agent i down from step `from` (`recorded` steps are recorded): its
    /// successor takes over far enough ahead that every process knows before the plant gets there.
    pub fn on_taken_down(&mut self, i: usize, from: u64, recorded: u64) -> Option<Action> {
        if self.slots.get(i) != Some(&Slot::Dead) {
            return None;
        }
        let rejoin_at = (from + 1).max(recorded + self.lead);
        self.timeline.set_down(i, from, EventKind::Crash);
        self.timeline.set_up_again(i, rejoin_at);
        self.slots[i] = Slot::Down { from, rejoin_at };
        Some(Action::Announce(RuntimeEvent {
            step: rejoin_at,
            kind: EVENT_UP_AGAIN,
            agent: i as u32,
            other: EVENT_ANY,
            ..RuntimeEvent::default()
        }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use formation_config::scenario::events::Event;

    fn crash(agent: usize, at_s: f64, down_s: f64, kind: EventKind) -> Timeline {
        let mut e = Event::new(at_s, kind);
        e.agent = Some(agent);
        e.down_s = Some(down_s);
        Timeline::new(&[e], 0.001)
    }

    #[test]
    fn a_timeline_crash_kills_after_its_last_command_and_respawns_once_the_window_is_recorded() {
        let mut s = Supervisor::new(
            5,
            crash(3, 20.0, 0.5, EventKind::Crash),
            Runtime::default(),
            68,
        );
        assert!(s.on_recorded(19_999).is_empty());
        assert_eq!(s.on_recorded(20_000), vec![Action::Kill(2)]);
        assert!(s.expects_gone(2));
        assert_eq!(
            s.on_death(2, "agent 3 was killed", Ending::Failed),
            None,
            "the timeline killed it"
        );
        assert!(s.on_recorded(20_499).is_empty(), "killed once");
        let plan = match s.on_recorded(20_500).as_slice() {
            [Action::Respawn(p)] => *p,
            other => panic!("{other:?}"),
        };
        assert_eq!(
            (plan.agent, plan.down_from, plan.rejoin_at, plan.warm),
            (2, 20_000, 20_500, true)
        );
        assert_eq!(
            s.on_hello(2),
            Some(Action::Joined {
                agent: 2,
                step: 20_500
            })
        );
        assert_eq!(s.on_hello(2), None, "only the awaited hello counts");
        assert_eq!(
            s.restarts()[2],
            0,
            "a timeline crash is not a restart under the policy"
        );
    }

    #[test]
    fn a_timeline_hang_stops_the_process_and_always_resumes_warm() {
        let rt = Runtime {
            restart_state: RestartState::Cold,
            ..Runtime::default()
        };
        let mut s = Supervisor::new(5, crash(1, 1.0, 0.2, EventKind::Hang), rt, 68);
        assert_eq!(s.on_recorded(1000), vec![Action::Stop(0)]);
        match s.on_recorded(1200).as_slice() {
            [Action::Respawn(p)] => assert!(p.warm),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn a_death_outside_the_timeline_stops_the_run_unless_the_policy_restarts_and_counts_it() {
        let mut never = Supervisor::new(3, Timeline::new(&[], 0.001), Runtime::default(), 68);
        assert!(matches!(
            never.on_death(1, "agent 2 was killed", Ending::Failed),
            Some(Action::Fail(_))
        ));
        let rt = Runtime {
            restart: RestartPolicy::OnFailure,
            max_restarts: 1,
            ..Runtime::default()
        };
        let mut s = Supervisor::new(3, Timeline::new(&[], 0.001), rt, 68);
        assert_eq!(
            s.on_death(1, "agent 2 was killed", Ending::Failed),
            Some(Action::TakeDown(1))
        );
        let up = s.on_taken_down(1, 5000, 4990).expect("announced");
        assert_eq!(
            up,
            Action::Announce(RuntimeEvent {
                step: 5058,
                kind: EVENT_UP_AGAIN,
                agent: 1,
                other: EVENT_ANY,
                ..RuntimeEvent::default()
            })
        );
        assert!(s.on_recorded(5057).is_empty());
        assert!(
            matches!(s.on_recorded(5058).as_slice(), [Action::Respawn(p)] if !p.scheduled && p.down_from == 5000)
        );
        s.on_hello(1);
        assert_eq!(s.restarts(), &[0, 1, 0]);
        assert!(
            matches!(s.on_death(1, "agent 2 was killed", Ending::Failed), Some(Action::Fail(m)) if m.contains("max_restarts"))
        );
    }

    #[test]
    fn an_agent_lost_before_the_first_step_is_relaunched_fresh_under_the_policy_and_counted() {
        let never = Runtime::default();
        let mut s = Supervisor::new(5, Timeline::new(&[], 0.001), never, 68);
        assert!(matches!(
            s.on_lost_at_start(3, "agent 4 was lost with host b"),
            Action::Fail(m) if m.contains("agent 4")
        ));
        let rt = Runtime {
            restart: RestartPolicy::OnFailure,
            max_restarts: 1,
            ..Runtime::default()
        };
        let mut s = Supervisor::new(5, Timeline::new(&[], 0.001), rt, 68);
        assert_eq!(s.on_lost_at_start(3, "lost"), Action::Relaunch(3));
        assert_eq!(s.on_lost_at_start(4, "lost"), Action::Relaunch(4));
        assert!(
            !s.taking_over(),
            "a relaunched agent runs from the first step on"
        );
        assert_eq!(s.restarts(), &[0, 0, 0, 1, 1]);
        // Its later death goes the usual way, and the count applies.
        assert!(
            matches!(s.on_death(3, "died", Ending::Failed), Some(Action::Fail(m)) if m.contains("max_restarts"))
        );
    }

    #[test]
    fn a_takeover_is_under_way_from_the_death_to_the_successors_hello() {
        let rt = Runtime {
            restart: RestartPolicy::OnFailure,
            ..Runtime::default()
        };
        let mut s = Supervisor::new(3, Timeline::new(&[], 0.001), rt, 68);
        assert!(!s.taking_over());
        s.on_death(1, "died", Ending::Failed);
        assert!(s.taking_over(), "dead, not taken down yet");
        s.on_taken_down(1, 100, 90);
        assert!(s.taking_over(), "down");
        assert_eq!(s.on_recorded(158).len(), 1);
        assert!(s.taking_over(), "successor started");
        s.on_hello(1);
        assert!(!s.taking_over(), "joined");
    }

    #[test]
    fn a_realtime_death_is_respawned_at_once_from_the_recorded_steps_and_joins_on_hello() {
        let rt = Runtime {
            restart: RestartPolicy::OnFailure,
            ..Runtime::default()
        };
        let mut s = Supervisor::new(3, Timeline::new(&[], 0.001), rt, 68);
        assert_eq!(s.on_dead_realtime(1, 380, 500), None, "not dead");
        assert_eq!(
            s.on_death(1, "agent 2 died", Ending::Failed),
            Some(Action::TakeDown(1))
        );
        let a = s.on_dead_realtime(1, 380, 500);
        assert_eq!(
            a,
            Some(Action::Respawn(Plan {
                agent: 1,
                down_from: 380,
                rejoin_at: 500,
                warm: true,
                scheduled: false,
            }))
        );
        assert_eq!(s.restarts(), &[0, 1, 0]);
        assert!(
            s.on_recorded(10_000).is_empty(),
            "no announcement is awaited"
        );
        assert_eq!(
            s.on_hello(1),
            Some(Action::Joined {
                agent: 1,
                step: 500
            })
        );
    }

    #[test]
    fn restarts_back_off_from_100_ms_doubling_to_2_s() {
        let ms = |n| restart_backoff(n).as_millis();
        assert_eq!(
            (0..8).map(ms).collect::<Vec<_>>(),
            [0, 100, 200, 400, 800, 1600, 2000, 2000]
        );
        assert_eq!(ms(u32::MAX), 2000);
    }

    /// A successor refused its ports (its predecessor still holds them) is tried again without
    /// using up `max_restarts`, each time after a longer pause; one that comes up resets both.
    #[test]
    fn a_successor_whose_ports_are_held_waits_with_backoff_and_is_not_counted() {
        let mut s = Supervisor::new(3, Timeline::new(&[], 0.001), rt_on(1), 100);
        assert_eq!(
            s.on_death(1, "died", Ending::Failed),
            Some(Action::TakeDown(1))
        );
        assert_eq!(
            s.backoff(1),
            std::time::Duration::ZERO,
            "the first start is at once"
        );
        let respawn = |s: &mut Supervisor| match s.on_taken_down(1, 1000, 1000) {
            Some(Action::Announce(e)) => {
                let plans = s.on_recorded(e.step);
                assert!(
                    matches!(plans.as_slice(), [Action::Respawn(_)]),
                    "{plans:?}"
                );
            }
            other => panic!("{other:?}"),
        };
        respawn(&mut s);
        for tries in 1..=MAX_HELD_STARTS {
            assert_eq!(
                s.on_death(1, "exited with code 75", Ending::PortHeld),
                Some(Action::TakeDown(1))
            );
            assert_eq!(s.backoff(1), restart_backoff(tries), "try {tries}");
            respawn(&mut s);
        }
        assert_eq!(s.restarts()[1], 1, "only the first death is a restart");
        assert!(matches!(
            s.on_death(1, "exited with code 75", Ending::PortHeld),
            Some(Action::Fail(m)) if m.contains("still held")
        ));
        let mut s = Supervisor::new(3, Timeline::new(&[], 0.001), rt_on(1), 100);
        s.on_death(1, "died", Ending::Failed);
        respawn(&mut s);
        s.on_death(1, "exited with code 75", Ending::PortHeld);
        respawn(&mut s);
        assert!(matches!(
            s.on_hello(1),
            Some(Action::Joined { agent: 1, .. })
        ));
        assert_eq!(
            s.backoff(1),
            std::time::Duration::ZERO,
            "a join resets the backoff"
        );
    }

    fn rt_on(max_restarts: u32) -> Runtime {
        Runtime {
            restart: RestartPolicy::OnFailure,
            max_restarts,
            ..Runtime::default()
        }
    }
}
