//! The mission of Section 4: T_g, P_d and Lambda_F (see `formation_config::scenario::Mission` for the
//! parameters and docs/deviations.md for our readings D1-D3).

use crate::shaping::{cap, spin_bounds, step_bounds, Transition};
use crate::smooth::{rise, smooth_step, time, Jet};
use formation_config::protocol::wire::ReferenceFrame;
use formation_config::scenario::Scenario;
use formation_config::MAX_AGENTS;

/// Precomputed mission parameters.
#[derive(Debug, Clone)]
pub struct Mission {
    n: usize,
    target_radius: f64,
    target_rate: f64,
    convergence_rate: f64,
    start_xy: [f64; 2],
    cruise_altitude: f64,
    climb_rate: f64,
    descent: f64,
    descent_sharpness: f64,
    /// R_c of each agent's ring (one ring: R_c for every agent; concentric rings: R_c,j), m.
    cover_radius: [f64; MAX_AGENTS],
    /// R_e of each agent's ring, m.
    enclose_radius: [f64; MAX_AGENTS],
    radius_sharpness: f64,
    spin_rate: f64,
    spin_sharpness: f64,
    phases: [f64; MAX_AGENTS],
    t1: f64,
    t2: f64,
    t3: f64,
    /// The radius change, the spin onset and the descent, as written and as flown (D26).
    transitions: [Transition; 3],
}

impl Mission {
    /// Builds the mission of a (validated) scenario.
    pub fn from_scenario(s: &Scenario) -> Mission {
        let m = &s.mission;
        let n = s.n_agents().min(MAX_AGENTS);
        let start_xy = if m.leader.start_at_initial_centroid && n > 0 {
            let mut c = [0.0; 2];
            for a in &s.agents {
                c[0] += a.initial_position_m[0] / n as f64;
                c[1] += a.initial_position_m[1] / n as f64;
            }
            c
        } else {
            [0.0, 0.0]
        };
        let mut phases = [0.0; MAX_AGENTS];
        let mut cover_radius = [0.0; MAX_AGENTS];
        let mut enclose_radius = [0.0; MAX_AGENTS];
        for i in 0..n {
            // A validated scenario has a slot for every agent.
            let (c, e, p) = m.formation.slot(i, n).unwrap_or_default();
            (cover_radius[i], enclose_radius[i], phases[i]) = (c, e, p);
        }
        let transitions = transitions(s, n, &cover_radius, &enclose_radius);
        let [radius, spin, descent] = transitions.map(|t| t.flown);
        Mission {
            transitions,
            n,
            target_radius: m.target.path_radius_m,
            target_rate: m.target.angular_rate_rad_s,
            convergence_rate: m.leader.convergence_rate,
            start_xy,
            cruise_altitude: m.leader.cruise_altitude_m,
            climb_rate: m.leader.climb_rate,
            descent: m.leader.descent_m,
            descent_sharpness: descent,
            cover_radius,
            enclose_radius,
            radius_sharpness: radius,
            spin_rate: m.formation.spin_rate_rad_s,
            spin_sharpness: spin,
            phases,
            t1: m.formation.t1_s,
            t2: m.formation.t2_s,
            t3: m.formation.t3_s,
        }
    }

    /// Number of agents.
    pub fn n_agents(&self) -> usize {
        self.n
    }

    /// The radius change, the spin onset and the descent: the sharpness each is written with and
    /// flown with, and what each asks of a slot (D26).
    pub fn transitions(&self) -> &[Transition; 3] {
        &self.transitions
    }

    /// Ground target T_g(t) = [r sin(w t), r cos(w t), 0] with derivatives, per axis (x, y).
    pub fn target(&self, t: f64) -> [Jet; 2] {
        let (s, c) = time(t).scale(self.target_rate).sin_cos();
        [s.scale(self.target_radius), c.scale(self.target_radius)]
    }

    /// Virtual leader P_d(t) with derivatives, per axis.
    pub fn leader(&self, t: f64) -> [Jet; 3] {
        self.leader_on(t, &self.target(t))
    }

    /// [`Mission::leader`] with T_g(t) given (the frame computes it once for both).
    fn leader_on(&self, t: f64, tg: &[Jet; 2]) -> [Jet; 3] {
        let s = rise(self.convergence_rate, t);
        let one_minus_s = s.scale(-1.0).add(Jet::constant(1.0));
        let x = s.mul(tg[0]).add(one_minus_s.scale(self.start_xy[0]));
        let y = s.mul(tg[1]).add(one_minus_s.scale(self.start_xy[1]));
        // h_t = descent (step(T3) - 1)... written as -descent * (1 - step_down), step_down = atan(k(T3-t))/pi + 1/2
        // atan(k (T3 - t))/pi + 1/2 = 1 - smooth_step(k, T3, t)
        let step = smooth_step(self.descent_sharpness, self.t3, t);
        let h_t = step.scale(-self.descent);
        let height = h_t.add(Jet::constant(self.cruise_altitude));
        let z = height.mul(rise(self.climb_rate, t));
        [x, y, z]
    }

    /// Ring radius A_t of agent `i`'s ring (0-based) with derivatives.
    pub fn radius(&self, i: usize, t: f64) -> Jet {
        self.radius_on(i, self.radius_down(t))
    }

    /// The agent-independent part of [`Mission::radius`]: 1 - smooth_step(k, T1, t), which goes
    /// from 1 (cover) to 0 (enclose).
    fn radius_down(&self, t: f64) -> Jet {
        // atan(k (T1 - t))/pi + 1/2 = 1 - smooth_step(k, T1, t)
        smooth_step(self.radius_sharpness, self.t1, t)
            .scale(-1.0)
            .add(Jet::constant(1.0))
    }

    /// [`Mission::radius`] of agent `i` from [`Mission::radius_down`] at the same time.
    fn radius_on(&self, i: usize, down: Jet) -> Jet {
        down.scale(self.cover_radius[i] - self.enclose_radius[i])
            .add(Jet::constant(self.enclose_radius[i]))
    }

    /// Spin angle w_t (t - T2) with derivatives (without the phase phi_i).
    pub fn spin_angle(&self, t: f64) -> Jet {
        let w = smooth_step(self.spin_sharpness, self.t2, t).scale(self.spin_rate);
        let tau = Jet {
            v: t - self.t2,
            d: 1.0,
            dd: 0.0,
        };
        w.mul(tau)
    }

    /// Lambda_i(t) of agent `i` (0-based), per axis (z is 0).
    pub fn lambda(&self, i: usize, t: f64) -> [Jet; 2] {
        self.lambda_on(i, self.radius_down(t), self.spin_angle(t))
    }

    /// [`Mission::lambda`] from the agent-independent parts at the same time, [`Mission::radius_down`]
    /// and [`Mission::spin_angle`]: a frame computes them once for all agents (the same values,
    /// bit for bit, as computing them per agent).
    fn lambda_on(&self, i: usize, down: Jet, spin: Jet) -> [Jet; 2] {
        let a = self.radius_on(i, down);
        let angle = spin.add(Jet::constant(self.phases[i]));
        let (s, c) = angle.sin_cos();
        [a.mul(c), a.mul(s)]
    }

    /// Fills the reference frame of step `step` at time `t`: T_g, P_d and derivatives, and
    /// Delta_i0 = Lambda_i - Lambda_0 with derivatives for every agent.
    pub fn reference(&self, step: u64, t: f64, out: &mut ReferenceFrame) {
        out.step = step;
        out.t = t;
        out.n_agents = self.n as u32;
        let tg = self.target(t);
        out.target = [tg[0].v, tg[1].v, 0.0];
        let pd = self.leader_on(t, &tg);
        for k in 0..3 {
            out.p_d[k] = pd[k].v;
            out.v_d[k] = pd[k].d;
            out.a_d[k] = pd[k].dd;
        }
        let mut mean = [Jet::default(); 2];
        let (down, spin) = (self.radius_down(t), self.spin_angle(t));
        for i in 0..self.n {
            let l = self.lambda_on(i, down, spin);
            for k in 0..2 {
                out.offset[i][k] = l[k].v;
                out.offset_vel[i][k] = l[k].d;
                out.offset_acc[i][k] = l[k].dd;
                mean[k] = mean[k].add(l[k].scale(1.0 / self.n as f64));
            }
            out.offset[i][2] = 0.0;
            out.offset_vel[i][2] = 0.0;
            out.offset_acc[i][2] = 0.0;
        }
        for i in 0..self.n {
            for k in 0..2 {
                out.offset[i][k] -= mean[k].v;
                out.offset_vel[i][k] -= mean[k].d;
                out.offset_acc[i][k] -= mean[k].dd;
            }
        }
    }
}

/// The mission's three transitions with their sharpness capped to `mission.shaping` (D26): the
/// radius change over the largest change of any ring, the spin onset on the largest ring, the
/// descent.
fn transitions(
    s: &Scenario,
    n: usize,
    cover: &[f64; MAX_AGENTS],
    enclose: &[f64; MAX_AGENTS],
) -> [Transition; 3] {
    let m = &s.mission;
    let sh = &m.shaping;
    let change = (0..n)
        .map(|i| (cover[i] - enclose[i]).abs())
        .fold(0.0, f64::max);
    let ring = (0..n).map(|i| cover[i].max(enclose[i])).fold(0.0, f64::max);
    let rate = m.formation.spin_rate_rad_s;
    let descent = m.leader.descent_m;
    let one = |name, k: f64, bounds: &dyn Fn(f64) -> (f64, f64)| {
        let flown = if sh.enabled {
            cap(k, bounds, sh.accel_m_s2, sh.jerk_m_s3)
        } else {
            k
        };
        Transition {
            name,
            written: k,
            flown,
            asked: bounds(k),
            flies: bounds(flown),
        }
    };
    [
        one("radius", m.formation.radius_sharpness, &|k| {
            step_bounds(k, change)
        }),
        one("spin", m.formation.spin_onset_sharpness, &|k| {
            spin_bounds(k, ring, rate)
        }),
        one("descent", m.leader.descent_sharpness, &|k| {
            step_bounds(k, descent)
        }),
    ]
}
