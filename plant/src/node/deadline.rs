//! The realtime plant's deadline policy (`docs/realtime.md`, `docs/failures.md`): an agent whose
//! command of step k is not in by the deadline is flown on its fallback (`crate::fallback`): its
//! last command held for `runtime.hold_s`, then the failsafe of `runtime.fallback`. The count restarts as soon as a
//! command of the agent is in again, whose command is then used. A command that came after its
//! own step's deadline but before this one's (a late command: a slow link, a slow wake-up) is the
//! newest the agent has sent: it is applied in place of the held one, and the agent counts as
//! answering (an agent that is always one step late flies with one step more delay, not on its
//! failsafe). Pure: no iceoryx2, no clock.

/// What the plant applies to quadrotor i at a step.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Decision {
    /// Its controller's command of the step came in time: apply it.
    Command,
    /// None came in time; its last command came `since_steps` steps before this one (0: it is the
    /// first step missed): fly the fallback (`Plant::apply_fallback`), which holds that command
    /// within `hold_s`, then flies the failsafe of `runtime.fallback`.
    Fallback { since_steps: u64 },
    /// None came in time, but a command of an earlier step came since the last one applied:
    /// apply it (the newest the agent sent).
    Late,
}

/// What came from agent i for a step.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Arrival {
    /// Its command of the step, before the deadline.
    OnTime,
    /// No command of the step, but one of an earlier step not yet applied.
    Late,
    /// Nothing.
    Nothing,
}

/// Per agent, the steps missed in a row.
#[derive(Debug, Clone)]
pub struct Silence {
    missed: Vec<u64>,
}

impl Silence {
    /// No agent silent, for `n` agents.
    pub fn new(n: usize) -> Silence {
        Silence { missed: vec![0; n] }
    }

    /// The decision for agent i at a step, given what came from it.
    pub fn decide(&mut self, i: usize, arrived: Arrival) -> Decision {
        match arrived {
            Arrival::OnTime => {
                self.missed[i] = 0;
                Decision::Command
            }
            Arrival::Late => {
                self.missed[i] = 0;
                Decision::Late
            }
            Arrival::Nothing => {
                let since_steps = self.missed[i];
                self.missed[i] += 1;
                Decision::Fallback { since_steps }
            }
        }
    }

    /// Steps agent i has missed in a row.
    #[cfg(test)]
    pub fn missed(&self, i: usize) -> u64 {
        self.missed[i]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Plant;
    use formation_config::protocol::wire::ControlCommand;
    use formation_config::scenario::Scenario;

    #[test]
    fn a_silent_agent_is_held_then_flown_on_the_fallback_and_taken_back_when_its_commands_return() {
        let mut s = Silence::new(2);
        assert_eq!(s.decide(0, Arrival::OnTime), Decision::Command);
        assert_eq!(
            s.decide(1, Arrival::Nothing),
            Decision::Fallback { since_steps: 0 }
        );
        assert_eq!(
            s.decide(1, Arrival::Nothing),
            Decision::Fallback { since_steps: 1 }
        );
        assert_eq!(
            s.decide(0, Arrival::OnTime),
            Decision::Command,
            "the others go on"
        );
        assert_eq!(s.missed(1), 2);
        assert_eq!(
            s.decide(1, Arrival::OnTime),
            Decision::Command,
            "its command is used again"
        );
        assert_eq!(s.missed(1), 0);
        assert_eq!(
            s.decide(1, Arrival::Nothing),
            Decision::Fallback { since_steps: 0 },
            "counted anew"
        );
    }

    #[test]
    fn a_late_command_is_applied_and_keeps_the_agent_off_its_failsafe() {
        let mut s = Silence::new(1);
        assert_eq!(
            s.decide(0, Arrival::Nothing),
            Decision::Fallback { since_steps: 0 }
        );
        assert_eq!(s.decide(0, Arrival::Late), Decision::Late);
        assert_eq!(s.missed(0), 0, "a late command is an answer");
        for _ in 0..1000 {
            assert_eq!(
                s.decide(0, Arrival::Late),
                Decision::Late,
                "always one step late: never the failsafe"
            );
        }
        assert_eq!(
            s.decide(0, Arrival::Nothing),
            Decision::Fallback { since_steps: 0 }
        );
    }

    #[test]
    fn the_plant_holds_the_last_command_for_hold_s_then_hovers_level() {
        let sc = Scenario::paper();
        let mut rt = sc.runtime.clone();
        rt.fallback = formation_config::scenario::events::Fallback::Hover;
        let dt = sc.simulation.dt_s;
        let mut plant = Plant::from_scenario(&sc);
        let last = ControlCommand {
            thrust_n: 7.5,
            torque_nm: [0.01, 0.0, 0.0],
            ..ControlCommand::default()
        };
        let mut s = Silence::new(sc.n_agents());
        assert_eq!(s.decide(0, Arrival::OnTime), Decision::Command);
        plant.apply(0, &last);
        let hold_steps = (rt.hold_s / dt).round() as u64;
        let mut applied = Vec::new();
        for _ in 0..hold_steps + 2 {
            for i in 1..sc.n_agents() {
                plant.apply(i, &last);
            }
            match s.decide(0, Arrival::Nothing) {
                Decision::Fallback { since_steps } => {
                    applied.push(plant.apply_fallback(0, since_steps, &rt))
                }
                Decision::Command | Decision::Late => unreachable!("no command came"),
            }
            plant.advance();
        }
        assert_eq!(applied[0].thrust_n, 7.5, "zero-order hold first");
        assert_eq!(applied[hold_steps as usize - 1].thrust_n, 7.5);
        let hover = applied[hold_steps as usize + 1];
        assert_ne!(hover.thrust_n, 7.5, "then the level hover");
        assert_eq!(hover.telemetry.attitude_cmd[..2], [0.0, 0.0]);
    }
}
