//! Lockstep: one frame per step from a host to the launcher.
//!
//! The agents of a host answer a lockstep step moments apart; a bridge that sent each command as
//! it came would send the plant one frame per agent (1.6-1.8 frames per step from a host with
//! two agents, docs/multi-host.md), each costing Zenoh's sending and receiving threads and a
//! wake-up of the plant that finds its step still incomplete. The plant cannot advance before it
//! has every command of the step, so a frame holding the command of one agent of the host gains
//! nothing by leaving before the commands of the host's other agents: [`CommandHold`] keeps it
//! until they are in, and the last one's wake-up sends the frame.
//!
//! Bounds, so that a hold never costs a step more than [`HOLD_FOR_COMMANDS`] once:
//! * an agent whose command does not come within [`HOLD_FOR_COMMANDS`] (its process is down, the
//!   plant flies its fallback) is no longer waited for until a command of it comes again;
//! * a frame that carries an event other than the plant's wake-up (a neighbour woken after a
//!   share it needs in this very step, a hello, a runtime event) leaves at once: someone may be
//!   waiting for it within the step;
//! * realtime runs never hold (every command has its own deadline).
//!
//! Pure: the caller gives the time, drains and sends.

use std::time::{Duration, Instant};

/// Longest a frame to the launcher waits for the commands of the host's other agents. Far above
/// an agent's step on a loaded machine (a few hundred µs), so a live agent is always waited for;
/// paid once per outage of an agent (then it is not waited for until it answers again).
pub const HOLD_FOR_COMMANDS: Duration = Duration::from_millis(2);

/// What to do with the frame to the launcher after a drain.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Decision {
    /// Send it (it may be empty).
    Send,
    /// Keep it and wait at most this long for the missing commands.
    Hold(Duration),
}

/// The hold of the frame to the launcher of one bridge plan (see the module doc).
#[derive(Debug, Clone)]
pub struct CommandHold {
    /// Holding is on (lockstep, and this host forwards commands).
    enabled: bool,
    /// Per forwarded topic: `None` for a topic that is not a command; `Some(awaited)` for a
    /// command: `awaited` false once it failed to come within the hold (until it comes again).
    commands: Vec<Option<bool>>,
    /// Per forwarded topic: a sample of it is in the pending frame.
    got: Vec<bool>,
    /// The pending frame carries an event other than the plant's wake-up.
    other_event: bool,
    /// When the pending frame was first held.
    since: Option<Instant>,
}

impl CommandHold {
    /// A hold over the forwarded topics, `is_command[k]` telling the commands of this host's
    /// agents (sent to the launcher); `lockstep` false turns it off.
    pub fn new(is_command: &[bool], lockstep: bool) -> CommandHold {
        CommandHold {
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

    /// An event went into the pending frame: the plant's wake-up (`plant_wake`) or another.
    pub fn on_event(&mut self, plant_wake: bool) {
        self.other_event |= !plant_wake;
    }

    /// Send the pending frame now, or hold it (how long at most) for the commands still awaited.
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
        if held >= HOLD_FOR_COMMANDS {
            for (c, g) in self.commands.iter_mut().zip(&self.got) {
                if *c == Some(true) && !*g {
                    *c = Some(false);
                }
            }
            return Decision::Send;
        }
        Decision::Hold(HOLD_FOR_COMMANDS - held)
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
    fn two_agents() -> CommandHold {
        CommandHold::new(&[true, false, true], true)
    }

    #[test]
    fn the_first_command_of_a_step_waits_for_the_other_agents_and_goes_with_the_last() {
        let t = Instant::now();
        let mut h = two_agents();
        h.on_sample(1);
        h.on_sample(0);
        h.on_event(true);
        assert_eq!(h.decide(t), Decision::Hold(HOLD_FOR_COMMANDS));
        let later = t + Duration::from_micros(300);
        assert_eq!(
            h.decide(later),
            Decision::Hold(HOLD_FOR_COMMANDS - Duration::from_micros(300))
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
        assert_eq!(h.decide(t + HOLD_FOR_COMMANDS), Decision::Send);
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
        let mut rt = CommandHold::new(&[true, false, true], false);
        rt.on_sample(0);
        assert_eq!(rt.decide(t), Decision::Send);
        let mut none = CommandHold::new(&[false, false], true);
        none.on_sample(0);
        assert_eq!(none.decide(t), Decision::Send);
    }
}
