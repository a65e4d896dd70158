//! Command filter of Fig. 3: magnitude limiter, rate limiter and a second-order low-pass,
//! q1' = q2, q2' = 2 xi w (S_R(w / (2 xi) (S_M(u) - q1)) - q2), per channel. Output q1 is the filtered
//! command, q2 its derivative.

use formation_config::scenario::CommandFilterSpec;

/// Three-channel command filter.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct CommandFilter {
    w: f64,
    xi: f64,
    mag: [f64; 3],
    rate: [f64; 3],
    q1: [f64; 3],
    q2: [f64; 3],
}

impl CommandFilter {
    /// A filter at rest at `initial`.
    pub fn new(spec: &CommandFilterSpec, initial: [f64; 3]) -> CommandFilter {
        CommandFilter {
            w: spec.natural_frequency_rad_s,
            xi: spec.damping,
            mag: spec.magnitude_limit,
            rate: spec.rate_limit,
            q1: initial,
            q2: [0.0; 3],
        }
    }

    /// Filtered command q1.
    pub fn value(&self) -> [f64; 3] {
        self.q1
    }

    /// Derivative q2 of the filtered command.
    pub fn derivative(&self) -> [f64; 3] {
        self.q2
    }

    /// Puts the filter at rest at `value` (within the magnitude limits): q1 = value, q2 = 0.
    pub fn reset(&mut self, value: [f64; 3]) {
        for k in 0..3 {
            self.q1[k] = value[k].clamp(-self.mag[k], self.mag[k]);
            self.q2[k] = 0.0;
        }
    }

    /// Magnitude limits of the channels.
    pub fn magnitude_limit(&self) -> [f64; 3] {
        self.mag
    }

    /// Advances the filter by `dt` with input `u` (semi-implicit Euler: q2 first, then q1 with the new
    /// q2). The magnitude limit also bounds the output, so |q1| never exceeds it.
    pub fn advance(&mut self, u: [f64; 3], dt: f64) {
        for k in 0..3 {
            let target = u[k].clamp(-self.mag[k], self.mag[k]);
            let wanted_rate = (self.w / (2.0 * self.xi)) * (target - self.q1[k]);
            let rate = wanted_rate.clamp(-self.rate[k], self.rate[k]);
            let q2_dot = 2.0 * self.xi * self.w * (rate - self.q2[k]);
            self.q2[k] += dt * q2_dot;
            self.q1[k] = (self.q1[k] + dt * self.q2[k]).clamp(-self.mag[k], self.mag[k]);
        }
    }
}
