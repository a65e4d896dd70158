//! Which neighbours may need this agent's shared state of the current step right away: only those
//! whose delayed step is the current one (delay below one step, or step 0). Waking the others would
//! cost a context switch per neighbour and step for nothing: they already hold the older samples
//! when their own state arrives. This only decides wake-ups; the controller's inputs are unchanged,
//! and a missed wake-up costs at most one wait timeout.

use crate::delay::delay_steps;
use formation_config::protocol::wire::DelayInjection;
use formation_config::scenario::{DelaySpec, Scenario};

/// Neighbour j, its scenario profile, and its runtime override (from step on).
type Profile = (usize, DelaySpec, Option<(u64, DelaySpec)>);

/// The delay profiles of this agent's neighbours, with their runtime overrides.
pub struct NeighbourDelays {
    dt: f64,
    max_delay: f64,
    profiles: Vec<Profile>,
}

impl NeighbourDelays {
    /// Profiles of `neighbours` from the scenario.
    pub fn new(s: &Scenario, neighbours: &[usize]) -> NeighbourDelays {
        NeighbourDelays {
            dt: s.simulation.dt_s,
            max_delay: s.simulation.max_delay_s,
            profiles: neighbours
                .iter()
                .map(|&j| (j, s.agents[j].delay.clone(), None))
                .collect(),
        }
    }

    /// Records a delay injection (for any agent; others' are ignored).
    pub fn observe(&mut self, inj: &DelayInjection) {
        for (j, _, over) in &mut self.profiles {
            if *j == inj.agent as usize {
                *over = Some((
                    inj.step,
                    DelaySpec {
                        base_s: inj.base_s,
                        amplitude_s: inj.amplitude_s,
                        angular_rate_rad_s: inj.angular_rate_rad_s,
                    },
                ));
            }
        }
    }

    /// True when neighbour number `idx` (in `neighbours` order) may need the share of `step` now.
    pub fn needs_now(&self, idx: usize, step: u64) -> bool {
        if step == 0 {
            return true;
        }
        let (_, base, over) = &self.profiles[idx];
        let d = match over {
            Some((from, o)) if step >= *from => o,
            _ => base,
        };
        let tau = d.tau(step as f64 * self.dt, self.max_delay);
        delay_steps(tau, self.dt) <= 1
    }

    /// True when neighbour number `idx` may need the share of `step` before this agent's command
    /// of `step` is in: it needs it now, or at `step + 1` (which starts once every command of
    /// `step` is in) its delay is at most one step. Otherwise the share may go out after the
    /// command.
    pub fn needed_before_next_step(&self, idx: usize, step: u64) -> bool {
        self.needs_now(idx, step) || self.needs_now(idx, step + 1)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Agent 0 with neighbour 1, whose delay is `base_s` (constant).
    fn delays(base_s: f64) -> NeighbourDelays {
        let mut s = Scenario::paper();
        s.agents[1].delay = DelaySpec {
            base_s,
            amplitude_s: 0.0,
            angular_rate_rad_s: 0.0,
        };
        NeighbourDelays::new(&s, &[1])
    }

    #[test]
    fn a_share_is_needed_at_once_only_at_step_0_or_under_a_delay_of_one_step() {
        let dt = Scenario::paper().simulation.dt_s;
        let long = delays(20.0 * dt);
        assert!(long.needs_now(0, 0));
        assert!(!long.needs_now(0, 5));
        assert!(!long.needed_before_next_step(0, 5));
        let short = delays(0.4 * dt);
        assert!(short.needs_now(0, 5));
        assert!(short.needed_before_next_step(0, 5));
    }

    #[test]
    fn a_delay_injection_that_shortens_the_delay_next_step_makes_the_share_go_out_first() {
        let dt = Scenario::paper().simulation.dt_s;
        let mut d = delays(20.0 * dt);
        d.observe(&DelayInjection {
            step: 100,
            agent: 1,
            base_s: 0.0,
            ..Default::default()
        });
        assert!(!d.needs_now(0, 99));
        assert!(
            d.needed_before_next_step(0, 99),
            "at step 100 the neighbour needs the share of step 99 or 100"
        );
        assert!(d.needs_now(0, 100));
    }
}
