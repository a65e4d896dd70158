//! Lockstep: one frame per step and direction between the plant's host and another host.
//!
//! In a lockstep step the plant publishes the states of a host's agents one after the other, and
//! the agents of that host answer moments apart; a bridge that sent each as it came would send
//! 1.2-1.3 frames per step to the host and 1.6-1.8 back from a host with two agents
//! (docs/multi-host.md), each frame costing Zenoh's sending and receiving threads and a wake-up
//! on the other side that finds its work still incomplete. Neither side gains from the first
//! part alone: the plant cannot advance before it has every command of the step, and the plant
//! publishes every state of the step in one go. So a frame holding a *per-step sample* (a state
//! to the host, a command to the plant's host) waits until the host's other per-step samples of
//! the step are in, and the last one's wake-up sends the frame ([`StepHold`]).
//!
//! Bounds, so that a hold never costs a step more than [`HOLD_FOR_STEP`] once:
//! * a sample that does not come within [`HOLD_FOR_STEP`] (its agent is down, the plant flies
//!   its fallback and publishes no state) is no longer waited for until it comes again;
//! * a frame to the plant's host that carries an event other than the plant's wake-up (a
//!   neighbour woken after a share it needs in this very step, a hello, a runtime event) leaves
//!   at once: its receiver may be what the missing command waits for. (A frame of states may
//!   carry the agents' wake-ups, the plant's or a neighbour's: the states it waits for come from
//!   the plant's one loop, which waits for nobody.)
//! * realtime runs never hold (every message has its own deadline).
//!
//! Pure: the caller gives the time, drains and sends.

use std::time::{Duration, Instant};

/// Longest a frame waits for the per-step samples still missing. Far above an agent's step on a
/// loaded machine (a few hundred µs), so a live agent is always waited for; paid once per outage
/// of an agent (then it is not waited for until it answers again).
pub const HOLD_FOR_STEP: Duration = Duration::from_millis(2);

/// What to do with a frame after a drain.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Decision {
    /// Send it (it may be empty).
    Send,
    /// Keep it and wait at most this long for the missing commands.
    Hold(Duration),
}

/// The hold of the frames to one destination host under one bridge plan (see the module doc).
#[derive(Debug, Clone)]
pub struct StepHold {
    /// Holding is on (lockstep, and this host sends per-step samples there).
    enabled: bool,
    /// Per forwarded topic: `None` for a topic that is not a per-step sample to this destination;
    /// `Some(awaited)` for one: `awaited` false once it failed to come within the hold (until it
    /// comes again).
    commands: Vec<Option<bool>>,
    /// Per forwarded topic: a sample of it is in the pending frame.
    got: Vec<bool>,
    /// The pending frame carries an event that may not wait.
    other_event: bool,
    /// When the pending frame was first held.
    since: Option<Instant>,
}

impl StepHold {
    /// A hold over the forwarded topics, `is_command[k]` telling the per-step samples to this
    /// destination; `lockstep` false turns it off.
    pub fn new(is_command: &[bool], lockstep: bool) -> StepHold {
        StepHold {
            enabled: lockstep && is_command.iter().any(|c| *c),
            commands: is_command.iter().map(|c| c.then_some(true)).collect(),
            got: vec![false; is_command.len()],
            other_event: false,
            since: None,
        }
    }

    /// Topic `k` put samples into the pending frame.
    pub fn on_sample(&mut self, k: usize) {
        self.got[k] = true;
        if let Some(awaited) = &mut self.commands[k] {
            *awaited = true;
        }
    }

    /// An event went into the pending frame: one that may wait with it (`may_wait`), or another.
    pub fn on_event(&mut self, may_wait: bool) {
        self.other_event |= !may_wait;
    }

    /// Send the pending frame now, or hold it (how long at most) for the samples still awaited.
    pub fn decide(&mut self, now: Instant) -> Decision {
        let has_command = self
            .commands
            .iter()
            .zip(&self.got)
            .any(|(c, g)| c.is_some() && *g);
        let missing = |s: &Self| {
            s.commands
                .iter()
                .zip(&s.got)
                .any(|(c, g)| *c == Some(true) && !*g)
        };
        if !self.enabled || !has_command || self.other_event || !missing(self) {
            return Decision::Send;
        }
        let since = *self.since.get_or_insert(now);
        let held = now.saturating_duration_since(since);
        if held >= HOLD_FOR_STEP {
            for (c, g) in self.commands.iter_mut().zip(&self.got) {
                if *c == Some(true) && !*g {
                    *c = Some(false);
                }
            }
            return Decision::Send;
        }
        Decision::Hold(HOLD_FOR_STEP - held)
    }

    /// The pending frame went out: the next one starts empty.
    pub fn sent(&mut self) {
        self.got.fill(false);
        self.other_event = false;
        self.since = None;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: Duration = Duration::from_millis(1);

    /// Topics 0 and 2 are the commands of two agents; topic 1 a share.
    fn two_agents() -> StepHold {
        StepHold::new(&[true, false, true], true)
    }

    #[test]
    fn the_first_command_of_a_step_waits_for_the_other_agents_and_goes_with_the_last() {
        let t = Instant::now();
        let mut h = two_agents();
        h.on_sample(1);
        h.on_sample(0);
        h.on_event(true);
        assert_eq!(h.decide(t), Decision::Hold(HOLD_FOR_STEP));
        let later = t + Duration::from_micros(300);
        assert_eq!(
            h.decide(later),
            Decision::Hold(HOLD_FOR_STEP - Duration::from_micros(300))
        );
        h.on_sample(2);
        h.on_event(true);
        assert_eq!(h.decide(later), Decision::Send);
        h.sent();
        // A frame without a command (a share for a later step) leaves at once.
        h.on_sample(1);
        assert_eq!(h.decide(later), Decision::Send);
    }

    #[test]
    fn an_agent_that_does_not_answer_costs_one_hold_until_it_answers_again() {
        let t = Instant::now();
        let mut h = two_agents();
        h.on_sample(0);
        assert!(matches!(h.decide(t), Decision::Hold(_)));
        assert_eq!(h.decide(t + HOLD_FOR_STEP), Decision::Send);
        h.sent();
        // Agent 2 is down: the next steps are not held for it.
        for k in 1..4 {
            h.on_sample(0);
            assert_eq!(h.decide(t + k * 10 * MS), Decision::Send);
            h.sent();
        }
        // It answers again (a successor): waited for from then on.
        h.on_sample(2);
        assert!(
            matches!(h.decide(t + 50 * MS), Decision::Hold(_)),
            "agent 1 still owes"
        );
        h.on_sample(0);
        assert_eq!(h.decide(t + 50 * MS), Decision::Send);
        h.sent();
        h.on_sample(0);
        assert!(matches!(h.decide(t + 60 * MS), Decision::Hold(_)));
    }

    #[test]
    fn a_frame_with_another_event_or_a_realtime_run_is_never_held() {
        let t = Instant::now();
        let mut h = two_agents();
        h.on_sample(0);
        h.on_event(false);
        assert_eq!(h.decide(t), Decision::Send, "a neighbour's wake-up");
        let mut rt = StepHold::new(&[true, false, true], false);
        rt.on_sample(0);
        assert_eq!(rt.decide(t), Decision::Send);
        let mut none = StepHold::new(&[false, false], true);
        none.on_sample(0);
        assert_eq!(none.decide(t), Decision::Send);
    }
}
