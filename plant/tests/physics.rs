//! Physical facts of the plant model (eq. (1)-(4)).

use formation_config::kinematics::{euler_rate_matrix, rotation, thrust_axis};
use formation_config::protocol::wire::{ControlCommand, FaultInjection};
use formation_config::Scenario;
use formation_plant::dynamics::{derivative, rk4, Body, HeldInput, RigidState};
use formation_plant::faults::{actuate, saturate, FaultModel};
use formation_plant::Plant;
use nalgebra::{Matrix3, Vector3};

/// The paper scenario with every uncertainty, disturbance and model perturbation switched off.
fn clean_scenario() -> Scenario {
    let mut s = Scenario::paper();
    for a in &mut s.agents {
        a.uncertainty.gain = [0.0; 3];
        a.disturbance.slow_amplitude = 0.0;
        a.disturbance.chirp_amplitude = 0.0;
        a.disturbance.fast_amplitude = 0.0;
        a.disturbance.bias = 0.0;
        a.model_perturbation.amplitude = [0.0; 3];
        a.fault.gamma_final = [1.0; 3];
        a.fault.gamma_initial_excess = [0.0; 3];
        a.fault.delta_ramp_nm = [0.0; 3];
        a.fault.delta_osc_amplitude_nm = [0.0; 3];
        a.fault.delta_bias_nm = [0.0; 3];
    }
    s
}

fn body(s: &Scenario) -> Body {
    Body {
        mass: s.vehicle.mass_kg,
        inertia: Vector3::from(s.vehicle.inertia_kg_m2),
        drag: Vector3::from(s.vehicle.rotational_drag),
        gravity: s.simulation.gravity_m_s2,
    }
}

#[test]
fn hover_at_thrust_m_g_is_an_equilibrium() {
    let s = clean_scenario();
    let mut plant = Plant::from_scenario(&s);
    let hover = ControlCommand {
        thrust_n: s.vehicle.mass_kg * s.simulation.gravity_m_s2,
        ..Default::default()
    };
    let p0 = plant.vehicle_state(0).position;
    for _ in 0..5000 {
        for i in 0..plant.n() {
            plant.apply(i, &hover);
        }
        plant.advance();
    }
    let st = plant.vehicle_state(0);
    for k in 0..3 {
        assert!(
            (st.position[k] - p0[k]).abs() < 1e-9,
            "drifted: {:?} vs {:?}",
            st.position,
            p0
        );
        assert!(st.velocity[k].abs() < 1e-9);
        assert!(st.attitude[k].abs() < 1e-12);
        assert!(st.rate[k].abs() < 1e-12);
    }
}

#[test]
fn zero_thrust_is_free_fall_at_g() {
    let s = clean_scenario();
    let mut plant = Plant::from_scenario(&s);
    let cmd = ControlCommand::default();
    let steps = 1000; // 1 s
    for _ in 0..steps {
        for i in 0..plant.n() {
            plant.apply(i, &cmd);
        }
        plant.advance();
    }
    let t = steps as f64 * s.simulation.dt_s;
    let g = s.simulation.gravity_m_s2;
    let st = plant.vehicle_state(0);
    assert!(
        (st.velocity[2] + g * t).abs() < 1e-9,
        "v_z = {}",
        st.velocity[2]
    );
    assert!((st.position[2] - (s.agents[0].initial_position_m[2] - 0.5 * g * t * t)).abs() < 1e-9);
}

#[test]
fn rotation_matrices_are_orthonormal_with_unit_determinant() {
    for &(phi, theta, psi) in &[
        (0.0, 0.0, 0.0),
        (0.3, -0.2, 1.0),
        (-1.2, 0.9, -2.5),
        (0.05, 1.3, 3.0),
    ] {
        let a = Vector3::new(phi, theta, psi);
        let r = rotation(&a);
        let should_be_i = r.transpose() * r;
        assert!((should_be_i - Matrix3::identity()).norm() < 1e-12);
        assert!((r.determinant() - 1.0).abs() < 1e-12);
        assert!((r.column(2) - thrust_axis(&a)).norm() < 1e-15);
    }
}

#[test]
fn euler_rate_matrix_maps_a_pure_yaw_rate_to_psi_dot_at_level_attitude() {
    let m = euler_rate_matrix(&Vector3::zeros());
    assert!((m - Matrix3::identity()).norm() < 1e-15);
    let tilted = euler_rate_matrix(&Vector3::new(0.2, 0.3, 0.0));
    // phi' = p + sin(phi) tan(theta) q + cos(phi) tan(theta) r
    let w = Vector3::new(0.0, 1.0, 0.0);
    assert!(((tilted * w)[0] - 0.2f64.sin() * 0.3f64.tan()).abs() < 1e-15);
}

#[test]
fn saturation_clamps_to_the_limits_of_eq_3() {
    assert_eq!(saturate(0.5, -0.4, 0.4), 0.4);
    assert_eq!(saturate(-0.5, -0.4, 0.4), -0.4);
    assert_eq!(saturate(0.1, -0.4, 0.4), 0.1);
    assert!(saturate(f64::NAN, -0.4, 0.4).is_nan());
}

#[test]
fn faulty_actuator_applies_gamma_then_delta_then_saturation() {
    let lo = Vector3::new(-0.4, -0.4, -2.0);
    let hi = Vector3::new(0.4, 0.4, 2.0);
    let u = actuate(
        &Vector3::new(0.2, 1.0, -1.0),
        &Vector3::new(0.5, 0.5, 0.8),
        &Vector3::new(0.1, 0.0, -1.5),
        &lo,
        &hi,
    );
    assert!((u[0] - 0.2).abs() < 1e-15); // 0.5*0.2 + 0.1
    assert_eq!(u[1], 0.4); // 0.5 saturates
    assert_eq!(u[2], -2.0); // -0.8 - 1.5 saturates
}

#[test]
fn fault_profiles_of_eq_63_64_match_the_printed_values() {
    let s = Scenario::paper();
    let f = FaultModel::new(&s.agents[0].fault);
    let (g0, d0) = f.at(0, 0.0);
    assert_eq!(g0, Vector3::new(1.0, 1.0, 1.0));
    assert!((d0 - Vector3::new(0.0, 0.0, 0.5)).norm() < 1e-15);
    let t = 40.0;
    let (g, d) = f.at(40_000, t);
    let e = (-t).exp();
    assert!((g[0] - (0.7 + 0.3 * e)).abs() < 1e-15);
    assert!((d[1] - (0.1 * (1.0 - e) + 0.05 * (0.27 * t).sin())).abs() < 1e-15);
    assert!((d[2] - (-1.3 * (1.0 - e) + 0.5)).abs() < 1e-15);
    // Agent 3: delta_33 = -1.2 e^{-0.05t}(1 - e^{-t}) + 0.7 e^{-0.05t}
    let f3 = FaultModel::new(&s.agents[2].fault);
    let (_, d3) = f3.at(40_000, t);
    let expect = -1.2 * (-0.05 * t).exp() * (1.0 - e) + 0.7 * (-0.05 * t).exp();
    assert!((d3[2] - expect).abs() < 1e-12);
}

#[test]
fn an_injected_fault_overrides_the_profile_from_its_step_on() {
    let s = Scenario::paper();
    let mut plant = Plant::from_scenario(&s);
    plant.inject_fault(&FaultInjection {
        step: 3,
        t: 0.003,
        agent: 1,
        mode: 1,
        gamma: [0.5, 0.6, 0.7],
        delta: [0.01, 0.02, 0.03],
    });
    let cmd = ControlCommand::default();
    for k in 0..5 {
        for i in 0..plant.n() {
            plant.apply(i, &cmd);
        }
        let tr = plant.truth(1);
        if k < 3 {
            assert_ne!(tr.gamma, [0.5, 0.6, 0.7], "not before its step");
        } else {
            assert_eq!(tr.gamma, [0.5, 0.6, 0.7]);
            assert_eq!(tr.delta, [0.01, 0.02, 0.03]);
            assert_eq!(tr.torque_applied_nm, [0.01, 0.02, 0.03]);
        }
        plant.advance();
    }
}

#[test]
fn rk4_integrates_a_constant_body_rate_exactly_in_yaw() {
    let s = clean_scenario();
    let b = Body {
        drag: Vector3::zeros(),
        ..body(&s)
    };
    let x = RigidState {
        p: Vector3::zeros(),
        v: Vector3::zeros(),
        a: Vector3::zeros(),
        w: Vector3::new(0.0, 0.0, 0.5),
    };
    let u = HeldInput {
        thrust: b.mass * b.gravity,
        torque: Vector3::zeros(),
    };
    let mut y = x;
    for k in 0..1000 {
        y = rk4(&b, &s.agents[0], &y, &u, k as f64 * 1e-3, 1e-3);
    }
    assert!((y.a[2] - 0.5).abs() < 1e-12);
    let d = derivative(&b, &s.agents[0], &x, &u, 0.0);
    assert!(d.v.norm() < 1e-12);
}

#[test]
fn integrating_each_quadrotor_as_its_command_arrives_matches_stepping_all_together() {
    // The plant process moves quadrotor i to step k + 1 as soon as command i is in, in arrival
    // order; the in-process runner applies all commands and then advances. Bit for bit the same.
    let s = Scenario::paper();
    let mut together = Plant::from_scenario(&s);
    let mut one_by_one = Plant::from_scenario(&s);
    let n = together.n();
    for k in 0..300u64 {
        let cmd = |i: usize| ControlCommand {
            step: k,
            agent: i as u32,
            thrust_n: 9.0 + 0.3 * i as f64 + (k as f64 * 0.01).sin(),
            torque_nm: [0.01 * i as f64, -0.02, 0.005 * (k % 7) as f64],
            ..Default::default()
        };
        for i in 0..n {
            together.apply(i, &cmd(i));
        }
        together.advance();
        // A different arrival order at every step, each quadrotor integrated on arrival.
        for j in 0..n {
            let i = (j * 3 + k as usize) % n;
            one_by_one.apply(i, &cmd(i));
            one_by_one.advance_vehicle(i);
            one_by_one.advance_vehicle(i); // a repeat in the same step does nothing
        }
        one_by_one.advance();
        for i in 0..n {
            let (a, b) = (together.vehicle_state(i), one_by_one.vehicle_state(i));
            assert_eq!(a.step, b.step);
            let bits = |v: &formation_config::protocol::wire::VehicleState| {
                [v.position, v.velocity, v.attitude, v.rate].map(|c| c.map(f64::to_bits))
            };
            assert_eq!(bits(&a), bits(&b), "quadrotor {i} at step {}", a.step);
        }
    }
}
