//! Eq. (1)-(2) of one quadrotor and a fixed-step RK4 with the inputs held over the step.

use crate::memo::{Direct, Math};
use crate::perturbations::{disturbance_with, model_perturbation_with, uncertainty};
use formation_config::kinematics::{rotational_drift, AttitudeTrig};
use formation_config::scenario::AgentSpec;
use nalgebra::Vector3;

/// The twelve states of eq. (1)-(2).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RigidState {
    /// Position P_i, m.
    pub p: Vector3<f64>,
    /// Velocity V_i, m/s.
    pub v: Vector3<f64>,
    /// Attitude A_i = [phi, theta, psi], rad.
    pub a: Vector3<f64>,
    /// Body rate Omega_i, rad/s.
    pub w: Vector3<f64>,
}

impl RigidState {
    fn axpy(&self, h: f64, d: &RigidState) -> RigidState {
        RigidState {
            p: self.p + d.p * h,
            v: self.v + d.v * h,
            a: self.a + d.a * h,
            w: self.w + d.w * h,
        }
    }

    /// True when every component is finite.
    pub fn is_finite(&self) -> bool {
        self.p
            .iter()
            .chain(self.v.iter())
            .chain(self.a.iter())
            .chain(self.w.iter())
            .all(|x| x.is_finite())
    }
}

/// Physical parameters of one quadrotor.
#[derive(Debug, Clone, PartialEq)]
pub struct Body {
    /// Mass m_i, kg.
    pub mass: f64,
    /// Diagonal of J_i, kg m².
    pub inertia: Vector3<f64>,
    /// Diagonal of K_iD, N m s/rad.
    pub drag: Vector3<f64>,
    /// Gravity g, m/s².
    pub gravity: f64,
}

/// Inputs held over one step: thrust T_i and the delivered torque U_iA (after faults and saturation).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HeldInput {
    /// Total thrust, N.
    pub thrust: f64,
    /// Delivered torque U_iA, N m.
    pub torque: Vector3<f64>,
}

/// The terms of eq. (2) that depend on time only (evaluated once per distinct RK4 stage time).
#[derive(Debug, Clone, Copy)]
pub struct TimeTerms {
    /// Delta F_i(t).
    pub model: nalgebra::Matrix3<f64>,
    /// D_iA(t), rad/s².
    pub disturbance: Vector3<f64>,
}

impl TimeTerms {
    /// The terms of agent `spec` at time `t`.
    pub fn at(spec: &AgentSpec, t: f64) -> TimeTerms {
        TimeTerms::at_with(spec, t, &mut Direct)
    }

    /// [`TimeTerms::at`] with exp, sin and cos from `f` (a plant's [`crate::memo::Memo`]).
    pub fn at_with(spec: &AgentSpec, t: f64, f: &mut impl Math) -> TimeTerms {
        TimeTerms {
            model: model_perturbation_with(&spec.model_perturbation, t, f),
            disturbance: disturbance_with(&spec.disturbance, t, f),
        }
    }
}

/// Time derivative of the state under eq. (1)-(2).
pub fn derivative(
    body: &Body,
    spec: &AgentSpec,
    x: &RigidState,
    u: &HeldInput,
    t: f64,
) -> RigidState {
    derivative_with(body, spec, x, u, &TimeTerms::at(spec, t))
}

/// Time derivative with the time-only terms given.
pub fn derivative_with(
    body: &Body,
    spec: &AgentSpec,
    x: &RigidState,
    u: &HeldInput,
    tt: &TimeTerms,
) -> RigidState {
    let f_p = uncertainty(&spec.uncertainty, &x.p, &x.v);
    derivative_given(body, x, u, tt, &f_p)
}

/// Time derivative with the time-only terms and the position uncertainty F_iP(x) (eq. (61)) given.
pub fn derivative_given(
    body: &Body,
    x: &RigidState,
    u: &HeldInput,
    tt: &TimeTerms,
    f_p: &Vector3<f64>,
) -> RigidState {
    let trig = AttitudeTrig::of(&x.a);
    let acc =
        trig.thrust_axis() * (u.thrust / body.mass) - Vector3::new(0.0, 0.0, body.gravity) + *f_p;
    let w = &x.w;
    let a_dot = trig.euler_rates(w);
    let w_dot = tt.model * rotational_drift(&body.inertia, &body.drag, w)
        + u.torque.component_div(&body.inertia)
        + tt.disturbance;
    RigidState {
        p: x.v,
        v: acc,
        a: a_dot,
        w: w_dot,
    }
}

/// One classical RK4 step of length `h` from time `t`, inputs held.
pub fn rk4(
    body: &Body,
    spec: &AgentSpec,
    x: &RigidState,
    u: &HeldInput,
    t: f64,
    h: f64,
) -> RigidState {
    let t0 = TimeTerms::at(spec, t);
    let tm = TimeTerms::at(spec, t + 0.5 * h);
    let t1 = TimeTerms::at(spec, t + h);
    let f_p0 = uncertainty(&spec.uncertainty, &x.p, &x.v);
    rk4_with(body, spec, x, u, h, [&t0, &tm, &t1], &f_p0)
}

/// RK4 with the time-only terms at the start, the middle and the end of the step given (the plant
/// reuses the end of one step as the start of the next, and computes them through its memo), and
/// F_iP (61) at the start state (the plant computes it once for the step's truth and the first
/// stage).
pub fn rk4_with(
    body: &Body,
    spec: &AgentSpec,
    x: &RigidState,
    u: &HeldInput,
    h: f64,
    [t0, tm, t1]: [&TimeTerms; 3],
    f_p0: &Vector3<f64>,
) -> RigidState {
    let k1 = derivative_given(body, x, u, t0, f_p0);
    let k2 = derivative_with(body, spec, &x.axpy(0.5 * h, &k1), u, tm);
    let k3 = derivative_with(body, spec, &x.axpy(0.5 * h, &k2), u, tm);
    let k4 = derivative_with(body, spec, &x.axpy(h, &k3), u, t1);
    RigidState {
        p: x.p + (k1.p + (k2.p + k3.p) * 2.0 + k4.p) * (h / 6.0),
        v: x.v + (k1.v + (k2.v + k3.v) * 2.0 + k4.v) * (h / 6.0),
        a: x.a + (k1.a + (k2.a + k3.a) * 2.0 + k4.a) * (h / 6.0),
        w: x.w + (k1.w + (k2.w + k3.w) * 2.0 + k4.w) * (h / 6.0),
    }
}
