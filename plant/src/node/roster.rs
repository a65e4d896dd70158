//! Which quadrotors' controllers are up at each step, as the plant sees it (`docs/failures.md`):
//! the timeline (scenario events, runtime events), the new processes that have joined, and the
//! decisions the plant's loop asks of them. Pure: no iceoryx2.

use formation_config::protocol::messages::{
    RuntimeEvent, EVENT_ANY, EVENT_DOWN, EVENT_DOWN_REQUEST, EVENT_JOINED,
};
use formation_config::scenario::events::{EventKind, Timeline};

/// What one runtime event asks of the plant.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Reaction {
    /// Nothing beyond the timeline update.
    None,
    /// Agent i's process is gone: take it down at the first step whose command is missing, and
    /// tell everyone.
    TakeDown(usize),
}

/// The plant's view of who computes which step.
#[derive(Debug, Clone)]
pub struct Roster {
    timeline: Timeline,
    /// Per agent: the step its newest process joined for (None: none joined since the start).
    joined: Vec<Option<u64>>,
}

impl Roster {
    /// The roster of `n` agents on `timeline`.
    pub fn new(n: usize, timeline: Timeline) -> Roster {
        Roster {
            timeline,
            joined: vec![None; n],
        }
    }

    /// Takes a runtime event in.
    pub fn on_event(&mut self, e: &RuntimeEvent) -> Reaction {
        let i = e.agent as usize;
        match e.kind {
            EVENT_JOINED if i < self.joined.len() => {
                self.joined[i] = Some(e.step);
                Reaction::None
            }
            EVENT_DOWN_REQUEST if i < self.joined.len() => Reaction::TakeDown(i),
            // The plant's own announcement: already applied.
            EVENT_DOWN => Reaction::None,
            _ => {
                e.apply(&mut self.timeline);
                Reaction::None
            }
        }
    }

    /// Takes agent i down from step `from` (its process is gone); returns the event that says so.
    pub fn take_down(&mut self, i: usize, from: u64) -> RuntimeEvent {
        self.timeline.set_down(i, from, EventKind::Crash);
        RuntimeEvent {
            step: from,
            kind: EVENT_DOWN,
            agent: i as u32,
            other: EVENT_ANY,
            ..RuntimeEvent::default()
        }
    }

    /// Steps agent i has been down at step k (`None`: it computes step k).
    pub fn down_for(&self, i: usize, k: u64) -> Option<u64> {
        self.timeline.down_window(i, k).map(|w| k - w.from)
    }

    /// An agent whose new process takes over at step k and has not joined yet: the states of k
    /// wait for it (its neighbours' shares of k must reach its new subscribers).
    pub fn awaited(&self, k: u64) -> Option<usize> {
        if k == 0 {
            return None;
        }
        (0..self.joined.len()).find(|&i| {
            self.timeline.up(i, k) && !self.timeline.up(i, k - 1) && self.joined[i] != Some(k)
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use formation_config::protocol::messages::{EVENT_CRASH, EVENT_UP_AGAIN};

    fn ev(kind: u32, agent: u32, step: u64, down_steps: u64) -> RuntimeEvent {
        RuntimeEvent {
            step,
            kind,
            agent,
            other: EVENT_ANY,
            down_steps,
            ..RuntimeEvent::default()
        }
    }

    #[test]
    fn a_crashed_agent_is_flown_on_its_fallback_and_its_new_process_is_awaited_at_its_rejoin() {
        let mut r = Roster::new(3, Timeline::new(&[], 0.001));
        r.on_event(&ev(EVENT_CRASH, 1, 100, 50));
        assert_eq!(r.down_for(1, 99), None);
        assert_eq!(r.down_for(1, 100), Some(0));
        assert_eq!(r.down_for(1, 149), Some(49));
        assert_eq!(r.down_for(1, 150), None);
        assert_eq!(r.awaited(149), None);
        assert_eq!(
            r.awaited(150),
            Some(1),
            "states of 150 wait for the new process"
        );
        r.on_event(&ev(EVENT_JOINED, 1, 150, 0));
        assert_eq!(r.awaited(150), None);
    }

    #[test]
    fn a_dead_process_is_down_until_the_orchestrator_names_the_step_its_successor_takes_over() {
        let mut r = Roster::new(2, Timeline::new(&[], 0.001));
        assert_eq!(
            r.on_event(&ev(EVENT_DOWN_REQUEST, 0, u64::MAX, 0)),
            Reaction::TakeDown(0)
        );
        let said = r.take_down(0, 500);
        assert_eq!((said.kind, said.step, said.agent), (EVENT_DOWN, 500, 0));
        assert_eq!(r.down_for(0, 10_000), Some(9_500), "open window");
        r.on_event(&ev(EVENT_UP_AGAIN, 0, 700, 0));
        assert_eq!(r.down_for(0, 700), None);
        assert_eq!(r.awaited(700), Some(0));
        assert_eq!(
            r.on_event(&said),
            Reaction::None,
            "its own announcement changes nothing"
        );
        assert_eq!(r.down_for(0, 600), Some(100));
    }
}
