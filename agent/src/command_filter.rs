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

    /// Whether input `u` would drive a channel at its rate limit: its wanted rate
    /// w / (2 xi) (S_M(u) - q1) is beyond the limit.
    pub fn rate_limited(&self, u: [f64; 3]) -> bool {
        (0..3).any(|k| {
            let target = u[k].clamp(-self.mag[k], self.mag[k]);
            ((self.w / (2.0 * self.xi)) * (target - self.q1[k])).abs() > self.rate[k]
        })
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

#[cfg(test)]
mod tests {
    use super::*;

    /// A step beyond 2 xi rate / w from the output drives the rate limiter; a smaller one, or the
    /// magnitude limit's own value when the output already sits there, does not.
    #[test]
    fn a_command_far_from_the_output_is_rate_limited() {
        let spec = CommandFilterSpec {
            natural_frequency_rad_s: 23.0,
            damping: 1.0,
            magnitude_limit: [0.35, 0.35, 3.2],
            rate_limit: [0.47, 0.47, 0.47],
        };
        let mut f = CommandFilter::new(&spec, [0.0; 3]);
        // 2 xi rate / w = 0.0409 rad.
        assert!(!f.rate_limited([0.04, -0.04, 0.0]));
        assert!(f.rate_limited([0.0, -0.042, 0.0]));
        f.reset([0.35, 0.0, 0.0]);
        assert!(!f.rate_limited([1.0, 0.0, 0.0]), "clamped to where it is");
        assert!(f.rate_limited([-0.3, 0.0, 0.0]));
    }
}
