//! Start-up reference generator (docs/deviations.md D19): the reference r an agent tracks starts at the
//! agent's first shared position and velocity and reaches its slot s = P_d + Delta_i0 along a path whose
//! acceleration never exceeds a_S and whose acceleration limit rises from 0 at the jerk j_S; from then on
//! r = s. The controller sees the slot offset by e = r - s (and e', e''), which it adds to Delta_i0.
//!
//! The generator is a second-order system on the slot error e (all vectors in R³):
//!
//! ```text
//! v_w  = -(e/|e|) min(lambda |e|, sqrt(2 beta a_S |e|))   wanted relative velocity (towards the slot)
//! r''  = clip(s'' + 4 lambda (v_w - e'), a(t)),  a(t) = min(a_S, j_S (t - t_0))
//! ```
//!
//! Near the slot it is linear, e'' = -4 lambda (e' + lambda e): a double pole at -2 lambda (no
//! overshoot). Far away the wanted speed is the one from which a braking at beta a_S stops at the slot,
//! so the approach does not overshoot either. Because r'' includes s'', a slot that moves or accelerates
//! (P_d rushing to a target that does not start under the swarm) is followed within a_S instead of being
//! handed to the position law as an infeasible reference. Pure: no allocation, no clock.

/// Fraction beta of a_S the approach plans to brake with (the rest is margin for the slot's own
/// acceleration and for the velocity loop of the generator), -.
const BRAKING_SHARE: f64 = 0.5;

/// The generator is over (r = s from then on) when |e| and |e'| are both below this, m and m/s: a
/// jump of 1e-6 m in the reference is far below anything the position law resolves.
const DONE_BELOW: f64 = 1e-6;

/// Parameters of the generator.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct BlendGains {
    /// a_S: largest acceleration of the reference, m/s².
    pub accel: f64,
    /// j_S: rate at which the acceleration limit rises from 0 to a_S at start-up, m/s³.
    pub jerk: f64,
    /// lambda: rate of the final approach, 1/s (double pole of e at -2 lambda).
    pub rate: f64,
}

/// The slot of one member with its derivatives: position, velocity, acceleration.
pub type Slot = [[f64; 3]; 3];

/// The start-up generator of one member of the consensus (the agent itself or one neighbour).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Blend {
    g: BlendGains,
    t0: f64,
    /// Time of the last update, s.
    t: f64,
    r: [f64; 3],
    rv: [f64; 3],
    /// The slot of the last update.
    s: Slot,
    /// Offset e, e', e'' of the last update; `None` once the generator is over.
    out: Option<Slot>,
}

fn norm(v: [f64; 3]) -> f64 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    std::array::from_fn(|k| a[k] - b[k])
}

impl Blend {
    /// The generator of a member first seen at position `p` and velocity `v` at time `t0` (s), with
    /// slot `s` then. `None` when the member starts exactly on its slot at its velocity (nothing to
    /// shape: the reference is the slot's, bit for bit).
    pub fn new(p: [f64; 3], v: [f64; 3], t0: f64, s: &Slot, g: BlendGains) -> Option<Blend> {
        let e = sub(p, s[0]);
        let ev = sub(v, s[1]);
        if norm(e) == 0.0 && norm(ev) == 0.0 {
            return None;
        }
        Some(Blend {
            g,
            t0,
            t: t0,
            r: p,
            rv: v,
            s: *s,
            out: Some([e, ev, [0.0; 3]]),
        })
    }

    /// The generator of a member that is already flying, at position `p` and velocity `v` at time
    /// `t` (s), with slot `s` then: as [`Blend::new`], but its acceleration limit is a_S from the
    /// start (no rise at j_S): a controller that comes back, or a neighbour's generator it resumes
    /// (docs/failures.md, bumpless re-entry). `None` when the member is exactly on its slot.
    pub fn resumed(p: [f64; 3], v: [f64; 3], t: f64, s: &Slot, g: BlendGains) -> Option<Blend> {
        let mut b = Blend::new(p, v, t, s, g)?;
        b.t0 = f64::NEG_INFINITY;
        Some(b)
    }

    /// Advances the reference to time `t` (s, not before the last update) with the member's slot `s`
    /// at `t`, and returns the offset e, e', e'' to add to it; `None` once the generator is over.
    pub fn advance(&mut self, t: f64, s: &Slot) -> Option<Slot> {
        self.out?;
        let h = (t - self.t).max(0.0);
        let accel = |t: f64, r: [f64; 3], rv: [f64; 3], s: &Slot| -> [f64; 3] {
            let e = sub(r, s[0]);
            let ev = sub(rv, s[1]);
            let pe = norm(e);
            let g = &self.g;
            let speed = (g.rate * pe).min((2.0 * BRAKING_SHARE * g.accel * pe).sqrt());
            let scale = if pe > 0.0 { speed / pe } else { 0.0 };
            let a: [f64; 3] =
                std::array::from_fn(|k| s[2][k] + 4.0 * g.rate * (-scale * e[k] - ev[k]));
            let cap = g.accel.min(g.jerk * (t - self.t0));
            let n = norm(a);
            if n > cap {
                std::array::from_fn(|k| a[k] * cap / n)
            } else {
                a
            }
        };
        // One step of constant acceleration from the state (and slot) of the last update.
        let a_prev = accel(self.t, self.r, self.rv, &self.s);
        self.r = std::array::from_fn(|k| self.r[k] + (self.rv[k] * h + 0.5 * a_prev[k] * h * h));
        self.rv = std::array::from_fn(|k| self.rv[k] + a_prev[k] * h);
        self.t = t;
        self.s = *s;
        let a = accel(t, self.r, self.rv, s);
        let e = sub(self.r, s[0]);
        let ev = sub(self.rv, s[1]);
        self.out = if norm(e) < DONE_BELOW && norm(ev) < DONE_BELOW {
            None
        } else {
            Some([e, ev, sub(a, s[2])])
        };
        self.out
    }

    /// The offset of the last update (`None`: over).
    pub fn offset(&self) -> Option<Slot> {
        self.out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const G: BlendGains = BlendGains {
        accel: 1.0,
        jerk: 2.0,
        rate: 0.5,
    };

    /// Runs the generator at 1 kHz against a slot given as a function of time; returns the peak
    /// acceleration and jerk of the reference, the peak overshoot past the slot along the initial error,
    /// and the time it ended.
    fn fly(
        p: [f64; 3],
        v: [f64; 3],
        slot: impl Fn(f64) -> Slot,
        g: BlendGains,
    ) -> (f64, f64, f64, f64) {
        let dt = 1e-3;
        let mut b = Blend::new(p, v, 0.0, &slot(0.0), g).unwrap();
        let e0 = sub(p, slot(0.0)[0]);
        let (mut peak_a, mut peak_j, mut over) = (0.0f64, 0.0f64, 0.0f64);
        let mut a_last = [0.0; 3];
        for i in 1..200_000 {
            let t = i as f64 * dt;
            let s = slot(t);
            match b.advance(t, &s) {
                None => return (peak_a, peak_j, over, t),
                Some(e) => {
                    let a: [f64; 3] = std::array::from_fn(|k| s[2][k] + e[2][k]);
                    peak_a = peak_a.max(norm(a));
                    if i > 1 {
                        peak_j = peak_j.max(norm(sub(a, a_last)) / dt);
                    }
                    a_last = a;
                    let along = (0..3).map(|k| e[0][k] * e0[k]).sum::<f64>() / norm(e0).max(1e-12);
                    over = over.max(-along);
                }
            }
        }
        panic!("generator did not end within 200 s");
    }

    /// From offsets of up to 4 m at rest the reference stays within a_S, rises at no more than about
    /// j_S, does not overshoot the slot and ends on it.
    #[test]
    fn an_offset_start_is_flown_within_the_acceleration_and_jerk_limits_without_overshoot() {
        for e0 in [
            [4.0, 0.0, 0.0],
            [-2.8, 2.8, 0.3],
            [0.5, -0.2, 0.0],
            [0.0, 0.0, -1.0],
        ] {
            let (a, j, over, end) = fly(e0, [0.0; 3], |_| [[0.0; 3]; 3], G);
            assert!(a <= G.accel * (1.0 + 1e-9), "{e0:?}: peak acceleration {a}");
            // d/dt of 4 lambda (v_w - e'): |v_w'| <= lambda |e'| and |e''| <= a_S; |e'| stays below
            // the braking speed sqrt(2 beta a_S |e_0|).
            let v_max = (2.0 * BRAKING_SHARE * G.accel * norm(e0)).sqrt();
            let bound = G.jerk.max(4.0 * G.rate * (G.accel + G.rate * v_max));
            assert!(j <= 1.05 * bound, "{e0:?}: jerk {j} > {bound}");
            assert!(over < 1e-3, "{e0:?}: overshoot {over} m");
            assert!(end < 40.0, "{e0:?}: ended at {end} s");
        }
    }

    /// A slot that rushes away (P_d converging 4 m to a target beside the swarm at rate 2, 8 m/s at
    /// t = 0, the agent at rest) is caught within a_S: the reference never asks for the slot's 16 m/s².
    #[test]
    fn a_slot_that_rushes_away_is_followed_within_the_acceleration_limit() {
        let slot = |t: f64| -> Slot {
            let x = -4.0 * (1.0 - (-2.0 * t).exp());
            [
                [x + 1.17 * t, 0.0, 0.0],
                [-8.0 * (-2.0 * t).exp() + 1.17, 0.0, 0.0],
                [16.0 * (-2.0 * t).exp(), 0.0, 0.0],
            ]
        };
        let g = BlendGains { accel: 1.5, ..G };
        let (a, _, _, end) = fly([0.0; 3], [0.0; 3], slot, g);
        assert!(a <= g.accel * (1.0 + 1e-9), "peak acceleration {a}");
        assert!(end < 60.0, "ended at {end} s");
    }

    /// A member that starts on its slot at the slot's velocity gets no generator (bit-identical
    /// reference), and an over generator stays over.
    #[test]
    fn a_member_on_its_slot_gets_no_generator() {
        let s = [[1.0, 2.0, 3.0], [0.1, 0.0, 0.0], [0.0; 3]];
        assert_eq!(Blend::new(s[0], s[1], 0.0, &s, G), None);
        let mut b = Blend::new([1.0, 2.0, 3.0], [0.0; 3], 0.0, &s, G).unwrap();
        assert!(b.offset().is_some());
        b.out = None;
        assert_eq!(b.advance(1.0, &s), None);
    }
}
