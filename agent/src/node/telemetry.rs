//! Live telemetry of agent i for `formation inspect`: every `TELEMETRY_EVERY_S` of simulation
//! time, one [`AgentTelemetry`] built from the command the controller just produced, its state and
//! the reference of the same step. Sent without waiting; the service keeps the latest sample for
//! late subscribers.

use formation_config::protocol::wire::{
    AgentTelemetry, ControlCommand, ReferenceFrame, VehicleState, TELEMETRY_EVERY_S,
};
use formation_config::scenario::Scenario;
use std::time::Duration;

/// Decides which steps are sampled and builds the samples.
pub struct Sampler {
    agent: usize,
    every: u64,
    margin: f64,
    rate_limit: f64,
    /// P_d + Delta_i0 of the latest reference handed to the controller.
    target: [f64; 3],
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
            sent: 0,
            send_time: Duration::ZERO,
        }
    }

    /// Remembers where this agent should be at the reference's step.
    pub fn observe_reference(&mut self, r: &ReferenceFrame) {
        let o = r.offset[self.agent];
        self.target = [r.p_d[0] + o[0], r.p_d[1] + o[1], r.p_d[2] + o[2]];
    }

    /// True when step `k` is sampled.
    pub fn due(&self, k: u64) -> bool {
        k.is_multiple_of(self.every)
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
