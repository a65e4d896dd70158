//! What the plant flies a quadrotor on while its controller is down (a crashed or hung agent,
//! `docs/failures.md`): the last command held for `runtime.hold_s`, then a level-hover fallback,
//! as an onboard flight controller's failsafe would: roll and pitch driven to zero, yaw rate damped,
//! thrust compensating gravity for the current tilt.

use crate::dynamics::RigidState;
use formation_config::protocol::wire::ControlCommand;
use formation_config::scenario::events::Runtime;
use nalgebra::Vector3;

/// Largest tilt the hover thrust compensates, rad (beyond it the thrust stays at that tilt's value).
const HOVER_COMPENSATION_TILT_RAD: f64 = 1.0;

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
/// [`level_hover`], whose telemetry carries only its attitude target (level, heading `yaw`) so the
/// constraint metrics measure the quadrotor against what it is asked to do.
#[allow(clippy::too_many_arguments)] // the step, the vehicle and the policy, each its own kind
pub fn command(
    rt: &Runtime,
    last: &ControlCommand,
    since_steps: u64,
    dt: f64,
    step: u64,
    agent: usize,
    yaw: f64,
    hover: impl FnOnce() -> (f64, [f64; 3]),
) -> ControlCommand {
    let mut cmd = if (since_steps as f64) * dt < rt.hold_s {
        *last
    } else {
        let (thrust_n, torque_nm) = hover();
        let mut c = ControlCommand {
            thrust_n,
            torque_nm,
            ..ControlCommand::default()
        };
        c.telemetry.attitude_cmd = [0.0, 0.0, yaw];
        c
    };
    cmd.step = step;
    cmd.t = step as f64 * dt;
    cmd.agent = agent as u32;
    cmd.sent_ns = 0;
    cmd
}

#[cfg(test)]
mod tests {
    use super::*;

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
        let hover = || level_hover(&rt, 1.0, 9.81, &j, &x);
        let held = command(&rt, &last, 10, 0.001, 100, 2, 0.5, hover);
        assert_eq!((held.thrust_n, held.torque_nm), (9.0, [0.1, 0.0, 0.0]));
        assert_eq!((held.step, held.agent), (100, 2));
        let late = command(&rt, &last, 1000, 0.001, 100, 2, 0.5, hover);
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
}
