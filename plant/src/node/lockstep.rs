//! The plant's lockstep pacing as a state machine without iceoryx2: what the event loop
//! (`super::run`) asks before it acts. Every decision is a pure function of this state.
//!
//! A step k: the states of k go out once the orchestrator's recorder allows it (`k < recorded +
//! PLANT_LEAD`); each command of k is applied as it arrives; once all N are in, the plant advances
//! to k + 1, and the record of k goes out after the states of k + 1.

use formation_config::protocol::pacing::{ACK_EVERY, HOUSEKEEPING_EVERY, PLANT_LEAD};

/// What to do about the states of step k.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum States {
    /// Publish them (and wake each agent).
    Send,
    /// The lead over the recorder is used up: wake the orchestrator once, then wait for progress.
    TellBlocked,
    /// Nothing to do: already out, already told, the run has not started, or it is over.
    Wait,
}

/// The plant's position in the lockstep.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Lockstep {
    /// Agents N.
    n: usize,
    /// Steps of the run.
    steps: u64,
    /// The current step k.
    k: u64,
    /// Steps recorded by the orchestrator (None: the run has not started).
    recorded: Option<u64>,
    /// The states of k are out.
    states_out: bool,
    /// The orchestrator was told the plant is blocked at k.
    told_blocked: bool,
    /// The record of k - 1 has not gone out yet.
    record_pending: bool,
    /// Commands of k in.
    got: usize,
}

impl Lockstep {
    /// At step 0 of a run of `steps` steps with `n` agents, before the start signal.
    pub fn new(n: usize, steps: u64) -> Lockstep {
        Lockstep {
            n,
            steps,
            k: 0,
            recorded: None,
            states_out: false,
            told_blocked: false,
            record_pending: false,
            got: 0,
        }
    }

    /// The current step k.
    pub fn k(&self) -> u64 {
        self.k
    }

    /// The orchestrator announced `recorded` steps (announcements may arrive out of order).
    pub fn on_progress(&mut self, recorded: u64) {
        self.recorded = Some(self.recorded.map_or(recorded, |r| r.max(recorded)));
    }

    /// A command of step k arrived.
    pub fn on_command(&mut self) {
        self.got += 1;
    }

    /// Whether the slow inputs (progress, fault injections) must be read now: when the lead over
    /// the recorder is used up, on a wake-up that brought no command (`idle`), and every
    /// HOUSEKEEPING_EVERY steps. Only asked while the states of k are not out.
    pub fn must_read_slow_inputs(&self, idle: bool) -> bool {
        let lead_used_up = self.recorded.is_none_or(|r| self.k >= r + PLANT_LEAD);
        lead_used_up || idle || self.k.is_multiple_of(HOUSEKEEPING_EVERY)
    }

    /// Whether the states of k are still to go out (and the run not over).
    pub fn states_pending(&self) -> bool {
        !self.states_out && self.k < self.steps
    }

    /// What to do about the states of k.
    pub fn states(&self) -> States {
        if !self.states_pending() {
            return States::Wait;
        }
        match self.recorded {
            Some(r) if self.k < r + PLANT_LEAD => States::Send,
            Some(_) if !self.told_blocked => States::TellBlocked,
            _ => States::Wait,
        }
    }

    /// The states of k went out.
    pub fn on_states_sent(&mut self) {
        self.states_out = true;
        self.told_blocked = false;
    }

    /// The orchestrator was told the plant is blocked.
    pub fn on_told_blocked(&mut self) {
        self.told_blocked = true;
    }

    /// Whether the record of k - 1 is due; if so, the record is taken as sent and the answer says
    /// whether the orchestrator must be woken for it (every ACK_EVERY steps, and at the last).
    pub fn take_record(&mut self) -> Option<bool> {
        if !self.record_pending {
            return None;
        }
        self.record_pending = false;
        Some(self.k.is_multiple_of(ACK_EVERY) || self.k == self.steps)
    }

    /// Whether step k is complete (states out, all N commands in) and the plant may advance.
    pub fn may_advance(&self) -> bool {
        self.k < self.steps && self.states_out && self.got == self.n
    }

    /// The plant advanced to k + 1; the record of k is pending.
    pub fn on_advance(&mut self) {
        self.record_pending = true;
        self.got = 0;
        self.states_out = false;
        self.k += 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn no_state_goes_out_before_the_start_signal() {
        let l = Lockstep::new(5, 100);
        assert_eq!(l.states(), States::Wait);
        assert!(
            l.must_read_slow_inputs(false),
            "before the start the lead is used up"
        );
    }

    #[test]
    fn states_go_out_while_the_plant_is_less_than_plant_lead_steps_ahead_of_the_recorder() {
        let mut l = Lockstep::new(1, 1000);
        l.on_progress(0);
        for _ in 0..PLANT_LEAD {
            assert_eq!(l.states(), States::Send, "k = {}", l.k());
            l.on_states_sent();
            l.on_command();
            assert!(l.may_advance());
            l.on_advance();
        }
        assert_eq!(l.k(), PLANT_LEAD);
        assert_eq!(l.states(), States::TellBlocked);
        l.on_told_blocked();
        assert_eq!(l.states(), States::Wait, "told once, then wait");
        l.on_progress(1);
        assert_eq!(l.states(), States::Send);
    }

    #[test]
    fn the_plant_advances_only_once_every_command_of_the_step_is_in() {
        let mut l = Lockstep::new(3, 10);
        l.on_progress(0);
        l.on_command();
        l.on_command();
        assert!(!l.may_advance(), "states not out yet");
        l.on_states_sent();
        assert!(!l.may_advance(), "2 of 3 commands");
        l.on_command();
        assert!(l.may_advance());
    }

    #[test]
    fn the_orchestrator_is_woken_by_a_record_every_ack_every_steps_and_at_the_last() {
        let steps = 2 * ACK_EVERY + 3;
        let mut l = Lockstep::new(1, steps);
        l.on_progress(steps);
        assert_eq!(l.take_record(), None, "no record before the first step");
        let mut woken = Vec::new();
        while l.k() < steps {
            l.on_states_sent();
            l.on_command();
            l.on_advance();
            if l.take_record() == Some(true) {
                woken.push(l.k());
            }
        }
        assert_eq!(woken, vec![ACK_EVERY, 2 * ACK_EVERY, steps]);
        assert!(
            !l.may_advance() && l.states() == States::Wait,
            "the run is over"
        );
    }

    #[test]
    fn progress_announcements_out_of_order_never_move_the_recorder_back() {
        let mut l = Lockstep::new(1, 100);
        l.on_progress(40);
        l.on_progress(16);
        for _ in 0..(40 + PLANT_LEAD - 1) {
            l.on_states_sent();
            l.on_command();
            l.on_advance();
        }
        assert_eq!(l.states(), States::Send, "recorded stays 40");
    }

    #[test]
    fn slow_inputs_are_read_on_idle_wake_ups_and_every_housekeeping_period() {
        let mut l = Lockstep::new(1, 1000);
        l.on_progress(500);
        assert!(
            l.must_read_slow_inputs(false),
            "k = 0 is a housekeeping step"
        );
        l.on_states_sent();
        l.on_command();
        l.on_advance();
        assert!(!l.must_read_slow_inputs(false));
        assert!(l.must_read_slow_inputs(true));
    }
}
