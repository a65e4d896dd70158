//! Start-up blend of the reference (docs/deviations.md D19): the slot P_d + Delta_i0 an agent tracks is
//! offset at start-up by e(t) = e_0 h_0((t - t_0)/T), which begins at the agent's initial position error
//! e_0 and reaches zero, with zero rate and acceleration, at t_0 + T. T is the shortest time for which the
//! blend's acceleration stays within a_S.

/// Peak |h_0''| of the minimum-jerk shape h_0(s) = 1 - 10 s³ + 15 s⁴ - 6 s⁵ on [0, 1]: 10/sqrt(3).
const C0: f64 = 5.773_502_691_896_258;

/// The blend of one agent.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Blend {
    e0: [f64; 3],
    t0: f64,
    duration: f64,
}

fn norm(v: [f64; 3]) -> f64 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}

impl Blend {
    /// The blend from position error e_0 (m) at time t_0 (s) whose acceleration stays within
    /// `accel_limit` (m/s²): T = sqrt(C0 |e_0| / a_S). `None` when the agent starts exactly on its slot
    /// (nothing to blend: the reference is the slot's, bit for bit).
    pub fn new(e0: [f64; 3], t0: f64, accel_limit: f64) -> Option<Blend> {
        let pe = norm(e0);
        if pe == 0.0 {
            return None;
        }
        Some(Blend {
            e0,
            t0,
            duration: (C0 * pe / accel_limit).sqrt(),
        })
    }

    /// T, s.
    pub fn duration(&self) -> f64 {
        self.duration
    }

    /// e, e', e'' at time t (s); `None` once the blend is over (t >= t_0 + T).
    pub fn at(&self, t: f64) -> Option<[[f64; 3]; 3]> {
        let tt = self.duration;
        let s = ((t - self.t0) / tt).max(0.0);
        if s >= 1.0 {
            return None;
        }
        let (s2, s3) = (s * s, s * s * s);
        let h = [
            1.0 - 10.0 * s3 + 15.0 * s3 * s - 6.0 * s3 * s2,
            (-30.0 * s2 + 60.0 * s3 - 30.0 * s2 * s2) / tt,
            (-60.0 * s + 180.0 * s2 - 120.0 * s3) / (tt * tt),
        ];
        Some(std::array::from_fn(|d| {
            std::array::from_fn(|k| self.e0[k] * h[d])
        }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The blend starts at the initial error at rest, never asks for more than a_S (and does use it),
    /// and is on the slot (zero error, rate and acceleration) by T.
    #[test]
    fn blend_starts_at_the_initial_error_stays_within_the_acceleration_limit_and_ends_on_the_slot()
    {
        for (e0, a_s) in [
            ([4.0, 0.0, 0.0], 1.0),
            ([-2.8, 2.8, 0.3], 1.0),
            ([0.5, -0.2, 0.0], 0.5),
            ([0.0, 0.0, -1.0], 3.0),
        ] {
            let b = Blend::new(e0, 3.0, a_s).unwrap();
            let start = b.at(3.0).unwrap();
            assert_eq!(start[0], e0);
            assert_eq!(norm(start[1]), 0.0);
            let n = 20_000;
            let mut peak: f64 = 0.0;
            for i in 0..n {
                let t = 3.0 + b.duration() * i as f64 / n as f64;
                peak = peak.max(norm(b.at(t).unwrap()[2]));
            }
            assert!(peak <= a_s * (1.0 + 1e-9), "peak {peak} > {a_s}");
            assert!(
                peak >= 0.999 * a_s,
                "peak {peak} well below {a_s}: T longer than needed"
            );
            let end = b.at(3.0 + b.duration() * (1.0 - 1e-9)).unwrap();
            assert!(end.iter().all(|v| norm(*v) < 1e-6), "{end:?}");
            assert_eq!(b.at(3.0 + b.duration() * (1.0 + 1e-9)), None);
        }
        assert_eq!(Blend::new([0.0; 3], 0.0, 1.0), None);
    }
}
