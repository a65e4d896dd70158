//! Live telemetry of agent i for `formation inspect`: every `TELEMETRY_EVERY_S` of simulation
//! time, one [`AgentTelemetry`] built from the command the controller just produced, its state and
//! the reference of the same step. Sent without waiting; the service keeps the latest sample for
//! late subscribers. Lockstep samples every step that is a multiple of the period
//! ([`Sampler::due`]); realtime, where an agent that falls behind answers only the newest state,
//! samples the first answered step of each period ([`Sampler::due_once`]).

use formation_config::protocol::wire::{
    AgentTelemetry, ControlCommand, ReferenceFrame, VehicleState, TELEMETRY_EVERY_S,
};
use formation_config::scenario::Scenario;
use formation_config::view::SeparationTally;
use std::time::Duration;

/// Decides which steps are sampled and builds the samples.
pub struct Sampler {
    agent: usize,
    every: u64,
    margin: f64,
    rate_limit: f64,
    /// P_d + Delta_i0 of the latest reference handed to the controller.
    target: [f64; 3],
    /// Period index (`k / every`) of the latest sample taken by [`Sampler::due_once`].
    last_period: Option<u64>,
    /// The separation layer of the commands since this process started (D25).
    separation: SeparationTally,
    dt: f64,
    /// Samples sent and the wall time spent building and sending them (the overhead).
    sent: u64,
    send_time: Duration,
}

impl Sampler {
    /// A sampler for agent `agent` (0-based) of `s`.
    pub fn new(s: &Scenario, agent: usize) -> Sampler {
        let every = (TELEMETRY_EVERY_S / s.simulation.dt_s).round().max(1.0) as u64;
        Sampler {
            agent,
            every,
            margin: s.controller.attitude.attitude_margin_rad,
            rate_limit: s.controller.attitude.rate_limit_rad_s,
            target: [0.0; 3],
            last_period: None,
            separation: SeparationTally::default(),
            dt: s.simulation.dt_s,
            sent: 0,
            send_time: Duration::ZERO,
        }
    }

    /// Remembers where this agent should be at the reference's step.
    pub fn observe_reference(&mut self, r: &ReferenceFrame) {
        let o = r.offset[self.agent];
        self.target = [r.p_d[0] + o[0], r.p_d[1] + o[1], r.p_d[2] + o[2]];
    }

    /// Accounts the separation layer of a command this process computed.
    pub fn observe_command(&mut self, cmd: &ControlCommand) {
        self.separation.observe(&cmd.telemetry);
    }

    /// True when step `k` is sampled.
    pub fn due(&self, k: u64) -> bool {
        k.is_multiple_of(self.every)
    }

    /// True for the first step `k` of each sampling period that reaches it (steps only increase):
    /// the same period as [`Sampler::due`] when steps are skipped (realtime).
    pub fn due_once(&mut self, k: u64) -> bool {
        let period = k / self.every;
        if self.last_period.is_some_and(|p| p >= period) {
            return false;
        }
        self.last_period = Some(period);
        true
    }

    /// The sample of the step whose state is `s` and command `cmd`; `latency` is the wall time of
    /// the controller step.
    pub fn sample(
        &self,
        s: &VehicleState,
        cmd: &ControlCommand,
        latency: Duration,
    ) -> AgentTelemetry {
        let e: f64 = (0..3)
            .map(|k| (s.position[k] - self.target[k]).powi(2))
            .sum::<f64>()
            .sqrt();
        AgentTelemetry {
            step: s.step,
            t: s.t,
            agent: self.agent as u32,
            _pad: 0,
            formation_error_m: e,
            attitude: s.attitude,
            rate: s.rate,
            attitude_limit_rad: norm(cmd.telemetry.attitude_cmd) + self.margin,
            rate_limit_rad_s: self.rate_limit,
            loop_latency_us: latency.as_secs_f64() * 1e6,
            sep_active_s: self.separation.active_s(self.dt),
            sep_min_predicted_m: self.separation.min_predicted_m,
            controller: cmd.telemetry,
        }
    }
}

impl Sampler {
    /// Accounts one sample that took `d` to build and send.
    pub fn count_send(&mut self, d: Duration) {
        self.sent += 1;
        self.send_time += d;
    }

    /// Samples sent so far.
    pub fn sent(&self) -> u64 {
        self.sent
    }

    /// Mean wall time to build and send one sample, µs (0 before the first).
    pub fn mean_send_us(&self) -> f64 {
        if self.sent == 0 {
            0.0
        } else {
            self.send_time.as_secs_f64() * 1e6 / self.sent as f64
        }
    }
}

fn norm(v: [f64; 3]) -> f64 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn realtime_sampling_takes_the_first_answered_step_of_each_period_even_when_steps_are_skipped()
    {
        let mut s = Sampler::new(&Scenario::paper(), 0);
        let every = s.every;
        assert!(every > 1, "the default period spans several steps");
        let taken: Vec<u64> = [0, 1, every - 1, every + 3, every + 4, 3 * every + 1]
            .into_iter()
            .filter(|&k| s.due_once(k))
            .collect();
        assert_eq!(taken, vec![0, every + 3, 3 * every + 1]);
    }
}
