//! Which neighbours may need this agent's shared state of the current step right away: only those
//! whose delayed step is the current one (delay below one step, or step 0). Waking the others would
//! cost a context switch per neighbour and step for nothing: they already hold the older samples
//! when their own state arrives. This only decides wake-ups; the controller's inputs are unchanged,
//! and a missed wake-up costs at most one wait timeout.

use formation_agent::delay::delay_steps;
use formation_config::scenario::{DelaySpec, Scenario};
use formation_config::wire::DelayInjection;

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
}
