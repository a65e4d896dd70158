//! What the plant flies a quadrotor on while its controller is down (a crashed, hung or late
//! agent, `docs/failures.md`): the last command held for `runtime.hold_s`, then the onboard
//! failsafe of `runtime.fallback`, as a flight controller's failsafe would run on the vehicle:
//!
//! * `slot`: fly the formation slot, P_d(t) + Delta_i0(t) of the leader's reference of the step
//!   (broadcast to every quadrotor, D4/D11), with velocity and acceleration feedforward;
//! * `hold`: brake and hold the point where the brake stops it (altitude included);
//! * `hover`: the level hover (roll and pitch to zero, yaw rate damped, thrust against gravity),
//!   which keeps the velocity it had.
//!
//! `slot` and `hold` share one cascade of its own (no RBFNN, no neighbour consensus, no estimate
//! of the faults beyond an integrator): a PD position loop with the controller's acceleration and
//! tilt limits (D5), a disturbance observer of the external acceleration (the lumped uncertainty
//! (61): the measured acceleration less the one its thrust and attitude give, low-passed at
//! [`DISTURBANCE_OBSERVER_RATE`], starting at the controller's last estimate F-hat) whose estimate
//! it cancels, an integral acceleration trim for what is left, and a repulsion from the quadrotors
//! nearer than [`SEPARATION_ACTIVATION`] safety distances, the conversion (28) to thrust and
//! roll/pitch at the current heading, a rate-limited attitude setpoint, a P attitude loop with
//! setpoint-rate feedforward to a clamped body-rate setpoint, and a PI rate loop on the torque
//! whose integrator starts at the last torque the controller sent (bumpless transfer) and absorbs
//! the actuator faults. Every gain is a named
//! constant below (docs/failures.md lists them). Pure functions; [`Failsafe`] is the state the
//! plant keeps per quadrotor while it flies it.

use crate::dynamics::RigidState;
use formation_config::kinematics::AttitudeTrig;
use formation_config::protocol::wire::ControlCommand;
use formation_config::scenario::events::Runtime;
use nalgebra::Vector3;

/// Largest tilt the hover thrust compensates, rad (beyond it the thrust stays at that tilt's value).
const HOVER_COMPENSATION_TILT_RAD: f64 = 1.0;

/// Position loop: stiffness k_P of a = a* + k_P (p* - p) + k_V (v* - v), 1/s².
pub const POSITION_GAIN: f64 = 1.5;
/// Position loop: damping k_V, 1/s (with k_P: natural frequency 1.22 rad/s, damping ratio 1.02).
pub const VELOCITY_GAIN: f64 = 2.5;
/// Position loop: integral gain k_I of the acceleration trim (trim' = k_I (p* - p)), 1/s³
/// (k_I < k_P k_V keeps the loop stable; the trim absorbs the lumped uncertainty (61)).
pub const POSITION_INTEGRAL_GAIN: f64 = 1.0;
/// Largest acceleration trim per axis, m/s².
pub const MAX_TRIM: f64 = 2.0;
/// Disturbance observer: bandwidth omega_D of the low-pass on the measured external acceleration
/// (d-hat' = omega_D (a_measured - a_thrust - d-hat)), 1/s. Five times the fastest change of the
/// uncertainty (61) a slot of the paper mission meets (sin(1.6 P_42 + V_42) of agent 4 in the
/// spin, ~2 rad/s), so the cancelled estimate lags it by ~11 degrees; 5 and 20 1/s measure the
/// same (docs/failures.md).
pub const DISTURBANCE_OBSERVER_RATE: f64 = 10.0;
/// Largest horizontal acceleration asked, m/s² (the controller's D5 limit).
pub const MAX_HORIZONTAL_ACCEL: f64 = 3.0;
/// Largest upward and downward acceleration asked, m/s² (D5).
pub const MAX_VERTICAL_ACCEL: f64 = 4.0;
/// Largest roll or pitch setpoint, rad (D5's tilt limit).
pub const MAX_TILT_RAD: f64 = 0.35;
/// Rate limit of the attitude setpoint, rad/s (the controller's command filter 1, D14).
pub const SETPOINT_RATE_LIMIT: f64 = 0.47;
/// Attitude loop: body-rate setpoint per rad of attitude error, 1/s.
pub const ATTITUDE_GAIN: f64 = 8.0;
/// Largest body-rate setpoint per axis, rad/s (inside the 1.134 rad/s rate constraint).
pub const MAX_RATE_SETPOINT: f64 = 0.8;
/// Rate loop: angular acceleration per rad/s of rate error (torque = J k_R e_w + I), 1/s.
pub const RATE_GAIN: f64 = 40.0;
/// Rate loop: integrator rate (I' = J k_I e_w), 1/s².
pub const RATE_INTEGRAL_GAIN: f64 = 150.0;
/// Repulsion: it acts from this many safety distances between two quadrotors on.
pub const SEPARATION_ACTIVATION: f64 = 2.0;
/// Repulsion: acceleration per m of intrusion into the activation distance, 1/s².
pub const SEPARATION_GAIN: f64 = 6.0;
/// `hold`: the braking deceleration that sets the point where it stops, m/s².
pub const HOLD_BRAKE_ACCEL: f64 = 3.0;

/// A position target with its feedforward: where the failsafe flies the quadrotor.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Target {
    /// Position, m.
    pub p: Vector3<f64>,
    /// Velocity, m/s.
    pub v: Vector3<f64>,
    /// Acceleration, m/s².
    pub a: Vector3<f64>,
}

/// What the failsafe remembers between steps of one down window.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Failsafe {
    /// Rate-loop integrator, N m (starts at the last torque the controller sent).
    pub integral: Vector3<f64>,
    /// Rate-limited attitude setpoint, rad.
    pub setpoint: Vector3<f64>,
    /// `hold`: the point it holds, m.
    pub hold: Vector3<f64>,
    /// The heading it holds (its heading at the take-over), rad.
    pub heading: f64,
    /// The position loop's integral acceleration trim, m/s² (starts at 0: the observer carries
    /// the uncertainty).
    pub trim: Vector3<f64>,
    /// The observer's estimate d-hat of the external acceleration (the lumped uncertainty (61)),
    /// m/s² (starts at F-hat, the controller's last estimate, carried in its command).
    pub disturbance: Vector3<f64>,
    /// The velocity at the previous failsafe step and the acceleration the thrust and attitude of
    /// that step give without external forces (None at the take-over): what the observer
    /// compares the next velocity with.
    pub last: Option<(Vector3<f64>, Vector3<f64>)>,
}

impl Failsafe {
    /// The failsafe taking over quadrotor `x` from the controller's last command (`torque` and
    /// its uncertainty estimate `f_hat`): the rate integrator at that torque, the disturbance
    /// estimate at `f_hat`, the setpoint at the current attitude, and (for `hold`) the point a brake
    /// at [`HOLD_BRAKE_ACCEL`] stops it at.
    pub fn take_over(x: &RigidState, torque: Vector3<f64>, f_hat: Vector3<f64>) -> Failsafe {
        let speed = x.v.norm();
        Failsafe {
            trim: Vector3::zeros(),
            disturbance: f_hat,
            last: None,
            integral: torque,
            setpoint: x.a,
            hold: x.p + x.v * (speed / (2.0 * HOLD_BRAKE_ACCEL)),
            heading: x.a[2],
        }
    }
}

/// The vehicle the failsafe flies: mass, gravity, inertia and actuator limits.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Airframe {
    /// Mass, kg.
    pub mass: f64,
    /// Gravity, m/s².
    pub gravity: f64,
    /// Inertia diagonal, kg m².
    pub inertia: Vector3<f64>,
    /// Torque limits (3), N m.
    pub torque_lo: Vector3<f64>,
    /// Upper torque limits, N m.
    pub torque_hi: Vector3<f64>,
    /// Largest thrust, N.
    pub thrust_max: f64,
}

/// The acceleration the position loop asks for `target` from `x`, with the trim and the
/// repulsion `push` added, within the acceleration and tilt limits.
pub fn position_law(
    target: &Target,
    x: &RigidState,
    trim: Vector3<f64>,
    push: Vector3<f64>,
    gravity: f64,
) -> Vector3<f64> {
    let mut a = target.a
        + (target.p - x.p) * POSITION_GAIN
        + (target.v - x.v) * VELOCITY_GAIN
        + trim
        + push;
    a.z = a.z.clamp(-MAX_VERTICAL_ACCEL, MAX_VERTICAL_ACCEL);
    let cap = MAX_HORIZONTAL_ACCEL.min((a.z + gravity) * MAX_TILT_RAD.tan());
    let h = a.xy().norm();
    if h > cap {
        a.x *= cap / h;
        a.y *= cap / h;
    }
    a
}

/// The repulsion of quadrotor `me` from the quadrotors at `others` nearer than
/// [`SEPARATION_ACTIVATION`] x `safety_m`: [`SEPARATION_GAIN`] per m of intrusion, along the line
/// between them (none from a quadrotor at the same point).
pub fn repulsion(
    me: &Vector3<f64>,
    others: impl Iterator<Item = Vector3<f64>>,
    safety_m: f64,
) -> Vector3<f64> {
    let reach = SEPARATION_ACTIVATION * safety_m;
    let mut push = Vector3::zeros();
    for o in others {
        let d = me - o;
        let n = d.norm();
        if n < reach && n > 0.0 {
            push += d * (SEPARATION_GAIN * (reach - n) / n);
        }
    }
    push
}

/// Thrust (N) and roll/pitch (rad) for the acceleration `a` at heading `psi` (eq. (28)), the
/// roll and pitch clamped to [`MAX_TILT_RAD`].
pub fn thrust_and_tilt(a: &Vector3<f64>, mass: f64, gravity: f64, psi: f64) -> (f64, [f64; 2]) {
    let uz = a.z + gravity;
    let norm = (a.x * a.x + a.y * a.y + uz * uz).sqrt();
    let (sp, cp) = psi.sin_cos();
    let phi = ((a.x * sp - a.y * cp) / norm).clamp(-1.0, 1.0).asin();
    let theta = ((a.x * cp + a.y * sp) / uz).atan();
    (
        mass * norm,
        [
            phi.clamp(-MAX_TILT_RAD, MAX_TILT_RAD),
            theta.clamp(-MAX_TILT_RAD, MAX_TILT_RAD),
        ],
    )
}

/// One step of the attitude cascade: moves the setpoint towards `wanted` (at most
/// [`SETPOINT_RATE_LIMIT`] per axis), and returns the torque of the PI rate loop on the body-rate
/// setpoint (P attitude loop plus the setpoint's rate, clamped to [`MAX_RATE_SETPOINT`]),
/// advancing the integrator (held while the torque saturates in its direction).
pub fn attitude_step(
    fs: &mut Failsafe,
    wanted: &Vector3<f64>,
    x: &RigidState,
    frame: &Airframe,
    dt: f64,
) -> Vector3<f64> {
    let step = SETPOINT_RATE_LIMIT * dt;
    let moved = (wanted - fs.setpoint).map(|d| d.clamp(-step, step));
    fs.setpoint += moved;
    let euler_rate = (fs.setpoint - x.a) * ATTITUDE_GAIN + moved / dt;
    let trig = AttitudeTrig::of(&x.a);
    let rate_sp = (trig.euler_rate_matrix_inverse() * euler_rate)
        .map(|w| w.clamp(-MAX_RATE_SETPOINT, MAX_RATE_SETPOINT));
    let e_w = rate_sp - x.w;
    let raw = e_w.component_mul(&frame.inertia) * RATE_GAIN + fs.integral;
    let torque = raw.zip_zip_map(&frame.torque_lo, &frame.torque_hi, |u, lo, hi| {
        u.clamp(lo, hi)
    });
    let growth = e_w.component_mul(&frame.inertia) * (RATE_INTEGRAL_GAIN * dt);
    for k in 0..3 {
        let pushes_out = (raw[k] >= frame.torque_hi[k] && growth[k] > 0.0)
            || (raw[k] <= frame.torque_lo[k] && growth[k] < 0.0);
        if !pushes_out {
            fs.integral[k] =
                (fs.integral[k] + growth[k]).clamp(frame.torque_lo[k], frame.torque_hi[k]);
        }
    }
    torque
}

/// The acceleration thrust `thrust` (N) gives a quadrotor of `frame` at attitude `a` without
/// external forces: R e_3 T / m - g e_3 (eq. (1) without F_iP).
pub fn thrust_acceleration(thrust: f64, a: &Vector3<f64>, frame: &Airframe) -> Vector3<f64> {
    formation_config::kinematics::thrust_axis(a) * (thrust / frame.mass)
        - Vector3::new(0.0, 0.0, frame.gravity)
}

/// One step of the disturbance observer at state `x`: the acceleration measured since the
/// previous failsafe step ((v - v_prev) / dt) less the one its thrust and attitude gave is the
/// external acceleration; the estimate follows it at [`DISTURBANCE_OBSERVER_RATE`]. Nothing to
/// compare at the take-over's first step.
pub fn observe_disturbance(fs: &mut Failsafe, x: &RigidState, dt: f64) {
    if let Some((v_prev, a_thrust)) = fs.last {
        let measured = (x.v - v_prev) / dt - a_thrust;
        let gain = (DISTURBANCE_OBSERVER_RATE * dt).min(1.0);
        fs.disturbance += (measured - fs.disturbance) * gain;
    }
}

/// The `slot` or `hold` command for `target`: thrust along the asked acceleration (compensating
/// the current tilt) less the observed disturbance, roll and pitch from it, heading held at
/// `heading`; returns thrust, torque and the attitude setpoint.
pub fn fly_to(
    fs: &mut Failsafe,
    target: &Target,
    push: Vector3<f64>,
    heading: f64,
    x: &RigidState,
    frame: &Airframe,
    dt: f64,
) -> (f64, Vector3<f64>, Vector3<f64>) {
    observe_disturbance(fs, x, dt);
    let a = position_law(target, x, fs.trim - fs.disturbance, push, frame.gravity);
    fs.trim = (fs.trim + (target.p - x.p) * (POSITION_INTEGRAL_GAIN * dt))
        .map(|f| f.clamp(-MAX_TRIM, MAX_TRIM));
    let (_, tilt) = thrust_and_tilt(&a, frame.mass, frame.gravity, x.a[2]);
    let wanted = Vector3::new(tilt[0], tilt[1], heading);
    let torque = attitude_step(fs, &wanted, x, frame, dt);
    let tilt_cos = (x.a[0].cos() * x.a[1].cos()).max(HOVER_COMPENSATION_TILT_RAD.cos());
    let thrust = (frame.mass * (a.z + frame.gravity) / tilt_cos).clamp(0.0, frame.thrust_max);
    fs.last = Some((x.v, thrust_acceleration(thrust, &x.a, frame)));
    (thrust, torque, fs.setpoint)
}

/// The level-hover command for a quadrotor of `mass` (kg) and inertia diagonal `inertia` (kg m²)
/// in state `x`: torque = -J (k_att [phi, theta, 0] + k_rate omega), thrust = m g / (cos phi cos theta).
pub fn level_hover(
    rt: &Runtime,
    mass: f64,
    gravity: f64,
    inertia: &Vector3<f64>,
    x: &RigidState,
) -> (f64, [f64; 3]) {
    let tilt_cos = (x.a[0].cos() * x.a[1].cos()).max(HOVER_COMPENSATION_TILT_RAD.cos());
    let thrust = mass * gravity / tilt_cos;
    let att = Vector3::new(x.a[0], x.a[1], 0.0);
    let torque =
        -(att * rt.fallback_attitude_gain + x.w * rt.fallback_rate_gain).component_mul(inertia);
    (thrust, torque.into())
}

/// The command of step `step` (time `t`) for agent `agent`, down for `since_steps` steps of `dt`:
/// `last` (the last command its controller sent, with its telemetry) while within `hold_s`, then
/// the failsafe `fly` (thrust, torque and attitude target), whose telemetry carries only its
/// attitude target so the constraint metrics measure the quadrotor against what it is asked to do.
pub fn command(
    rt: &Runtime,
    last: &ControlCommand,
    since_steps: u64,
    dt: f64,
    step: u64,
    agent: usize,
    fly: impl FnOnce() -> (f64, [f64; 3], [f64; 3]),
) -> ControlCommand {
    let mut cmd = if held(rt, since_steps, dt) {
        *last
    } else {
        let (thrust_n, torque_nm, target) = fly();
        let mut c = ControlCommand {
            thrust_n,
            torque_nm,
            ..ControlCommand::default()
        };
        c.telemetry.attitude_cmd = target;
        c
    };
    cmd.step = step;
    cmd.t = step as f64 * dt;
    cmd.agent = agent as u32;
    cmd.sent_ns = 0;
    cmd
}

/// Whether the step `since_steps` steps into a down window still holds the last command.
pub fn held(rt: &Runtime, since_steps: u64, dt: f64) -> bool {
    (since_steps as f64) * dt < rt.hold_s
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame() -> Airframe {
        Airframe {
            mass: 0.856,
            gravity: 9.81,
            inertia: Vector3::new(0.02351, 0.02351, 0.04701),
            torque_lo: Vector3::new(-0.4, -0.4, -2.0),
            torque_hi: Vector3::new(0.4, 0.4, 2.0),
            thrust_max: 33.6,
        }
    }

    fn at(p: [f64; 3], v: [f64; 3]) -> RigidState {
        RigidState {
            p: Vector3::from(p),
            v: Vector3::from(v),
            a: Vector3::zeros(),
            w: Vector3::zeros(),
        }
    }

    #[test]
    fn the_last_command_is_held_for_hold_s_then_the_fallback_levels_the_quadrotor() {
        let rt = Runtime::default();
        let last = ControlCommand {
            thrust_n: 9.0,
            torque_nm: [0.1, 0.0, 0.0],
            ..ControlCommand::default()
        };
        let x = RigidState {
            p: Vector3::zeros(),
            v: Vector3::zeros(),
            a: Vector3::new(0.2, -0.1, 0.5),
            w: Vector3::new(0.0, 0.0, 1.0),
        };
        let j = Vector3::new(0.02, 0.02, 0.04);
        let hover = || {
            let (t, u) = level_hover(&rt, 1.0, 9.81, &j, &x);
            (t, u, [0.0, 0.0, 0.5])
        };
        let held = command(&rt, &last, 10, 0.001, 100, 2, hover);
        assert_eq!((held.thrust_n, held.torque_nm), (9.0, [0.1, 0.0, 0.0]));
        assert_eq!((held.step, held.agent), (100, 2));
        let late = command(&rt, &last, 1000, 0.001, 100, 2, hover);
        assert_eq!(
            late.telemetry.attitude_cmd,
            [0.0, 0.0, 0.5],
            "its target: level"
        );
        assert!(
            late.thrust_n > 9.81,
            "compensates the tilt: {}",
            late.thrust_n
        );
        assert!(
            late.torque_nm[0] < 0.0 && late.torque_nm[1] > 0.0,
            "levels roll and pitch"
        );
        assert!(
            late.torque_nm[2] < 0.0,
            "damps the yaw rate, yaw itself is free"
        );
    }

    #[test]
    fn the_position_law_pulls_towards_the_target_within_the_acceleration_and_tilt_limits() {
        let t = Target {
            p: Vector3::new(10.0, 0.0, 5.0),
            v: Vector3::zeros(),
            a: Vector3::zeros(),
        };
        let a = position_law(
            &t,
            &at([0.0, 0.0, 5.0], [0.0; 3]),
            Vector3::zeros(),
            Vector3::zeros(),
            9.81,
        );
        assert!((a.x - MAX_HORIZONTAL_ACCEL).abs() < 1e-12 && a.y == 0.0 && a.z == 0.0);
        let near = position_law(
            &t,
            &at([9.9, 0.0, 5.0], [0.0; 3]),
            Vector3::zeros(),
            Vector3::zeros(),
            9.81,
        );
        assert!(
            (near.x - 0.1 * POSITION_GAIN).abs() < 1e-12,
            "linear near it"
        );
        let down = position_law(
            &t,
            &at([10.0, 0.0, 50.0], [0.0; 3]),
            Vector3::zeros(),
            Vector3::zeros(),
            9.81,
        );
        assert_eq!(down.z, -MAX_VERTICAL_ACCEL);
        let moving = Target {
            v: Vector3::new(1.0, 0.0, 0.0),
            ..t
        };
        let a = position_law(
            &moving,
            &at([10.0, 0.0, 5.0], [0.0; 3]),
            Vector3::zeros(),
            Vector3::zeros(),
            9.81,
        );
        assert!(
            (a.x - VELOCITY_GAIN).abs() < 1e-12,
            "follows the slot's velocity"
        );
    }

    #[test]
    fn the_repulsion_pushes_apart_only_inside_the_activation_distance() {
        let me = Vector3::new(0.0, 0.0, 5.0);
        let far = repulsion(&me, [Vector3::new(1.5, 0.0, 5.0)].into_iter(), 0.5);
        assert_eq!(far, Vector3::zeros());
        let near = repulsion(&me, [Vector3::new(0.6, 0.0, 5.0)].into_iter(), 0.5);
        assert!((near.x + SEPARATION_GAIN * 0.4).abs() < 1e-12, "{near}");
        assert_eq!((near.y, near.z), (0.0, 0.0));
    }

    #[test]
    fn thrust_and_tilt_invert_the_rotated_thrust_and_clamp_the_tilt() {
        let (t, tilt) = thrust_and_tilt(&Vector3::new(0.0, 0.0, 0.0), 1.0, 9.81, 0.3);
        assert!((t - 9.81).abs() < 1e-12 && tilt == [0.0, 0.0]);
        // +x at heading 0 is a positive pitch; +y a negative roll.
        let (_, tilt) = thrust_and_tilt(&Vector3::new(1.0, 0.0, 0.0), 1.0, 9.81, 0.0);
        assert!(tilt[1] > 0.0 && tilt[0].abs() < 1e-12);
        let (_, tilt) = thrust_and_tilt(&Vector3::new(0.0, 1.0, 0.0), 1.0, 9.81, 0.0);
        assert!(tilt[0] < 0.0);
        let (_, tilt) = thrust_and_tilt(&Vector3::new(20.0, 0.0, 0.0), 1.0, 9.81, 0.0);
        assert_eq!(tilt[1], MAX_TILT_RAD);
    }

    #[test]
    fn the_attitude_setpoint_is_rate_limited_and_the_rates_stay_inside_the_constraint() {
        let f = frame();
        let x = at([0.0; 3], [0.0; 3]);
        let mut fs = Failsafe::take_over(&x, Vector3::zeros(), Vector3::zeros());
        let u = attitude_step(&mut fs, &Vector3::new(0.3, 0.0, 0.0), &x, &f, 0.001);
        assert!((fs.setpoint.x - SETPOINT_RATE_LIMIT * 0.001).abs() < 1e-15);
        assert!(u.x > 0.0 && u.x <= f.torque_hi.x, "rolls towards it: {u}");
        // A far setpoint never asks more than MAX_RATE_SETPOINT.
        let mut fs = Failsafe {
            setpoint: Vector3::new(0.35, 0.0, 0.0),
            ..fs
        };
        let spinning = RigidState {
            w: Vector3::new(MAX_RATE_SETPOINT, 0.0, 0.0),
            ..x
        };
        let u = attitude_step(&mut fs, &Vector3::new(0.35, 0.0, 0.0), &spinning, &f, 0.001);
        assert!(u.x.abs() < 0.02 + 1e-12, "already at the largest rate: {u}");
    }

    /// Actuator faults on the torque: U delivered = gamma U + delta, per channel.
    struct ActuatorFaults {
        /// Effectiveness Gamma.
        gamma: Vector3<f64>,
        /// Bias delta, N m.
        delta: Vector3<f64>,
    }

    /// Flies `x` on the cascade for `steps` steps of 1 ms towards `target(t)`, with the actuator
    /// `faults` on the torque and the external acceleration `force(x)` it does not know (a
    /// small-angle rigid body, enough for the tests); calls `each(t, x)` after every step and
    /// returns the largest body rate.
    fn fly(
        x: &mut RigidState,
        fs: &mut Failsafe,
        faults: ActuatorFaults,
        target: impl Fn(f64) -> Target,
        force: impl Fn(&RigidState) -> Vector3<f64>,
        steps: usize,
        mut each: impl FnMut(f64, &RigidState),
    ) -> f64 {
        let f = frame();
        let dt = 0.001;
        let mut worst_rate: f64 = 0.0;
        for k in 0..steps {
            let t = k as f64 * dt;
            let (thrust, u, _) = fly_to(fs, &target(t), Vector3::zeros(), 0.0, x, &f, dt);
            let applied = (u.component_mul(&faults.gamma) + faults.delta).zip_zip_map(
                &f.torque_lo,
                &f.torque_hi,
                |u, lo, hi| u.clamp(lo, hi),
            );
            let acc = thrust_acceleration(thrust, &x.a, &f) + force(x);
            x.v += acc * dt;
            x.p += x.v * dt;
            x.w += applied.component_div(&f.inertia) * dt;
            x.a += AttitudeTrig::of(&x.a).euler_rates(&x.w) * dt;
            worst_rate = worst_rate.max(x.w.norm());
            each(t + dt, x);
        }
        worst_rate
    }

    /// A quadrotor flown by the cascade alone, with a constant disturbance torque, a loss of
    /// effectiveness and a force it does not know, ends at its target: the observer and the
    /// integrators absorb them, and the observer's estimate is the force.
    #[test]
    fn the_cascade_flies_a_faulty_quadrotor_to_its_target_and_keeps_its_rates_bounded() {
        let target = Target {
            p: Vector3::new(2.0, -1.0, 5.0),
            v: Vector3::zeros(),
            a: Vector3::zeros(),
        };
        let mut x = at([0.0, 0.0, 5.0], [0.5, 0.0, 0.0]);
        let mut fs = Failsafe::take_over(&x, Vector3::zeros(), Vector3::zeros());
        let force = Vector3::new(0.8, -0.6, 0.5);
        let worst_rate = fly(
            &mut x,
            &mut fs,
            ActuatorFaults {
                gamma: Vector3::new(0.7, 0.75, 0.8),
                delta: Vector3::new(0.15, -0.1, 0.8),
            },
            |_| target,
            |_| force,
            30_000,
            |_, _| {},
        );
        assert!((x.p - target.p).norm() < 0.05, "at {:?}", x.p);
        assert!(x.v.norm() < 0.05);
        assert!(worst_rate < 1.134, "rates {worst_rate}");
        assert!(
            (fs.disturbance - force).norm() < 1e-3,
            "observed {}",
            fs.disturbance
        );
    }

    /// A slot on a 1 m circle at the paper's spin rate (0.8 rad/s) under agent 4's uncertainty of
    /// (61) along y, sin(1.6 P_y + V_y), plus a 0.8 m/s² bias along x: once the take-over's
    /// transient is over the cascade keeps the quadrotor within 10 cm of it and its velocity within
    /// 10 cm/s (0.064 m and 0.063 m/s; with the observer's rate at 0, the PD loop and its
    /// integrator alone, 0.72 m and 0.73 m/s).
    #[test]
    fn the_slot_failsafe_tracks_a_spinning_slot_under_a_varying_uncertainty_within_10_cm() {
        let (r, w) = (1.0, 0.8);
        let slot = |t: f64| {
            let (s, c) = (w * t).sin_cos();
            Target {
                p: Vector3::new(r * c, 15.0 + r * s, 5.0),
                v: Vector3::new(-r * w * s, r * w * c, 0.0),
                a: Vector3::new(-r * w * w * c, -r * w * w * s, 0.0),
            }
        };
        let mut x = at([r, 15.0, 5.0], [0.0, r * w, 0.0]);
        let mut fs = Failsafe::take_over(&x, Vector3::zeros(), Vector3::zeros());
        let (mut worst_p, mut worst_v): (f64, f64) = (0.0, 0.0);
        let worst_rate = fly(
            &mut x,
            &mut fs,
            ActuatorFaults {
                gamma: Vector3::new(1.0, 1.0, 1.0),
                delta: Vector3::zeros(),
            },
            slot,
            |x| Vector3::new(0.8, (1.6 * x.p.y + x.v.y).sin(), 0.0),
            20_000,
            |t, x| {
                if t > 5.0 {
                    worst_p = worst_p.max((x.p - slot(t).p).norm());
                    worst_v = worst_v.max((x.v - slot(t).v).norm());
                }
            },
        );
        assert!(worst_p < 0.1, "position error {worst_p} m");
        assert!(worst_v < 0.1, "velocity error {worst_v} m/s");
        assert!(worst_rate < 1.134, "rates {worst_rate}");
    }

    #[test]
    fn hold_stops_where_a_brake_at_the_hold_deceleration_would() {
        let x = at([1.0, 2.0, 5.0], [3.0, 0.0, 0.0]);
        let fs = Failsafe::take_over(&x, Vector3::new(0.1, 0.0, 0.0), Vector3::new(0.3, 0.0, 9.0));
        assert!((fs.hold.x - (1.0 + 9.0 / (2.0 * HOLD_BRAKE_ACCEL))).abs() < 1e-12);
        assert_eq!(fs.integral.x, 0.1, "starts at the controller's torque");
        assert_eq!(
            fs.disturbance,
            Vector3::new(0.3, 0.0, 9.0),
            "and at its uncertainty estimate"
        );
        assert_eq!(fs.trim, Vector3::zeros());
    }
}
