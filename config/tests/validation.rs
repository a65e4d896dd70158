//! Every check of `validate`: starting from the paper scenario, break one thing at a time and assert
//! the error names the offending field and the right assumption.

use formation_config::scenario::validate::{
    validate, validate_event, ValidationError, A1, A2, A4, A5, CTRL, D11, D23, EQ15, EQ35_50,
    EQ46_49, FINITE, INDEX, MISSION, PHYS, SAT, SIM,
};
use formation_config::scenario::{Edge, PAPER_TOML};
use formation_config::{Scenario, MAX_AGENTS};

/// The errors `validate` returns (empty when the scenario is valid).
fn errors(s: &Scenario) -> Vec<ValidationError> {
    match validate(s) {
        Ok(()) => Vec::new(),
        Err(e) => e.0,
    }
}

/// Asserts one error names exactly `field` and an assumption containing `assumption`.
fn assert_rejected(s: &Scenario, field: &str, assumption: &str) {
    let errs = errors(s);
    assert!(
        errs.iter()
            .any(|e| e.field == field && e.assumption.contains(assumption)),
        "expected an error on `{field}` citing `{assumption}`, got {errs:#?}"
    );
}

/// Defines a test that breaks the paper scenario with `$break` and expects `$field` / `$assumption`.
macro_rules! rejects {
    ($name:ident, $field:expr, $assumption:expr, |$s:ident| $break:block) => {
        #[test]
        fn $name() {
            let mut $s = Scenario::paper();
            $break
            assert_rejected(&$s, $field, $assumption);
        }
    };
}

fn path_edges(n: usize) -> Vec<Edge> {
    (1..n)
        .map(|a| Edge {
            a,
            b: a + 1,
            weight: 1.0,
        })
        .collect()
}

// ---------------------------------------------------------------- embedded scenarios and parsing

#[test]
fn embedded_paper_scenario_is_valid() {
    assert_eq!(validate(&Scenario::paper()), Ok(()));
}

#[test]
fn embedded_paper_exact_scenario_is_valid() {
    assert_eq!(validate(&Scenario::paper_exact()), Ok(()));
}

#[test]
fn unknown_toml_field_is_rejected_naming_the_field() {
    let text = PAPER_TOML.replacen(
        "[controller.position]",
        "[controller.position]\nk_p_typo = 1.0",
        1,
    );
    assert_ne!(text, PAPER_TOML);
    let err = Scenario::from_toml_str(&text)
        .expect_err("unknown field accepted")
        .to_string();
    assert!(err.contains("k_p_typo"), "{err}");
}

#[test]
fn every_error_is_reported_not_just_the_first() {
    let mut s = Scenario::paper();
    s.vehicle.mass_kg = -1.0;
    s.agents[2].delay.base_s = 1.0;
    let errs = errors(&s);
    assert!(errs.iter().any(|e| e.field == "vehicle.mass_kg"));
    assert!(errs.iter().any(|e| e.field == "agents[2].delay"));
}

#[test]
fn error_display_of_an_agents_field_also_names_the_1_based_agent_id() {
    let mut s = Scenario::paper();
    s.agents[2].delay.base_s = 0.045;
    let errs = errors(&s);
    let e = errs
        .iter()
        .find(|e| e.field == "agents[2].delay")
        .expect("the delay of agents[2] is rejected");
    assert_eq!(e.agent_id(), Some(3));
    let text = e.to_string();
    assert!(text.starts_with("agents[2].delay (agent 3): "), "{text}");
    let other = ValidationError {
        field: "controller.position.k_p".into(),
        assumption: CTRL,
        message: "m".into(),
    };
    assert_eq!(other.agent_id(), None);
    assert!(!other.to_string().contains("(agent"));
}

#[test]
fn error_display_names_field_and_assumption() {
    let mut s = Scenario::paper();
    s.agents[0].delay.base_s = 0.2;
    let text = validate(&s).unwrap_err().to_string();
    assert!(
        text.contains("agents[0].delay") && text.contains("Assumption 2"),
        "{text}"
    );
}

// ---------------------------------------------------------------- finite numbers

rejects!(
    nan_inertia_is_rejected_as_not_finite_naming_the_field,
    "vehicle.inertia_kg_m2[1]",
    FINITE,
    |s| {
        s.vehicle.inertia_kg_m2[1] = f64::NAN;
    }
);
rejects!(
    infinite_delay_is_rejected_as_not_finite_naming_the_field,
    "agents[3].delay.base_s",
    FINITE,
    |s| {
        s.agents[3].delay.base_s = f64::INFINITY;
    }
);
rejects!(
    nan_gain_is_rejected_as_not_finite_naming_the_field,
    "controller.position.k_p",
    FINITE,
    |s| {
        s.controller.position.k_p = f64::NAN;
    }
);
rejects!(
    negative_infinite_torque_limit_is_rejected_as_not_finite,
    "vehicle.torque_min_nm[0]",
    FINITE,
    |s| {
        s.vehicle.torque_min_nm[0] = f64::NEG_INFINITY;
    }
);
rejects!(
    nan_edge_weight_is_rejected_as_not_finite,
    "graph.edges[2].weight",
    FINITE,
    |s| {
        s.graph.edges[2].weight = f64::NAN;
    }
);

// ---------------------------------------------------------------- Assumption 1: graph

rejects!(
    disconnected_follower_graph_is_rejected_naming_assumption_1,
    "graph.edges",
    A1,
    |s| {
        s.graph.edges.remove(1); // 1-2 | 3-4-5, both parts hear the leader
    }
);
#[test]
fn disconnected_graph_whose_parts_both_hear_the_leader_is_only_a_connectivity_error() {
    let mut s = Scenario::paper();
    s.graph.edges.remove(1);
    assert!(!errors(&s).iter().any(|e| e.field == "graph.leader_weights"));
}
rejects!(
    leader_unreachable_when_every_b_i_is_zero_is_rejected_naming_assumption_1,
    "graph.leader_weights",
    A1,
    |s| {
        s.graph.leader_weights = vec![0.0; 5];
    }
);
rejects!(
    component_without_leader_is_rejected_naming_assumption_1,
    "graph.leader_weights",
    A1,
    |s| {
        s.graph.edges.remove(1);
        s.graph.leader_weights = vec![1.0, 0.0, 0.0, 0.0, 0.0]; // 3-4-5 never hears the leader
    }
);
rejects!(
    self_loop_is_rejected_naming_assumption_1,
    "graph.edges[4]",
    A1,
    |s| {
        s.graph.edges.push(Edge {
            a: 3,
            b: 3,
            weight: 1.0,
        });
    }
);
rejects!(
    edge_listed_in_both_directions_is_rejected_naming_assumption_1,
    "graph.edges[4]",
    A1,
    |s| {
        s.graph.edges.push(Edge {
            a: 2,
            b: 1,
            weight: 1.0,
        }); // a_12 = a_21 written as two edges
    }
);
rejects!(
    edge_listed_twice_is_rejected_naming_assumption_1,
    "graph.edges[4]",
    A1,
    |s| {
        s.graph.edges.push(Edge {
            a: 3,
            b: 4,
            weight: 1.0,
        });
    }
);
rejects!(
    zero_edge_weight_is_rejected_naming_assumption_1,
    "graph.edges[0].weight",
    A1,
    |s| {
        s.graph.edges[0].weight = 0.0;
    }
);
rejects!(
    negative_edge_weight_is_rejected_naming_assumption_1,
    "graph.edges[3].weight",
    A1,
    |s| {
        s.graph.edges[3].weight = -1.0;
    }
);
rejects!(
    negative_leader_weight_is_rejected_naming_assumption_1,
    "graph.leader_weights[4]",
    A1,
    |s| {
        s.graph.leader_weights[4] = -1.0;
    }
);
rejects!(
    no_agents_is_rejected_naming_assumption_1,
    "agents",
    A1,
    |s| {
        s.agents.clear();
        s.graph.edges.clear();
        s.graph.leader_weights.clear();
    }
);

// ---------------------------------------------------------------- indices

rejects!(
    edge_index_above_n_is_rejected_naming_the_edge_end,
    "graph.edges[3].b",
    INDEX,
    |s| {
        s.graph.edges[3].b = 6;
    }
);
rejects!(
    edge_index_zero_is_rejected_naming_the_edge_end,
    "graph.edges[0].a",
    INDEX,
    |s| {
        s.graph.edges[0].a = 0;
    }
);
rejects!(
    leader_weights_length_mismatch_is_rejected,
    "graph.leader_weights",
    INDEX,
    |s| {
        s.graph.leader_weights.pop();
    }
);
rejects!(
    more_agents_than_supported_is_rejected,
    "agents",
    INDEX,
    |s| {
        let n = MAX_AGENTS + 1;
        s.agents = vec![s.agents[0].clone(); n];
        s.graph.edges = path_edges(n);
        s.graph.leader_weights = vec![1.0; n];
    }
);

// ---------------------------------------------------------------- Assumption 2: delays

rejects!(
    delay_above_tau_m_is_rejected_naming_assumption_2,
    "agents[2].delay",
    A2,
    |s| {
        s.agents[2].delay.base_s = 0.045; // 0.045 + 0.015 > 0.05
    }
);
rejects!(
    negative_delay_is_rejected_naming_assumption_2,
    "agents[0].delay",
    A2,
    |s| {
        s.agents[0].delay.base_s = 0.005; // 0.005 - 0.01 < 0
    }
);
rejects!(
    non_positive_tau_m_is_rejected_naming_assumption_2,
    "simulation.max_delay_s",
    A2,
    |s| {
        s.simulation.max_delay_s = 0.0;
    }
);
rejects!(
    tau_m_spanning_too_many_steps_is_rejected_naming_assumption_2,
    "simulation.max_delay_s",
    A2,
    |s| {
        s.simulation.max_delay_s = 200.0;
    }
);
#[test]
fn delay_exactly_at_tau_m_is_accepted() {
    let mut s = Scenario::paper();
    s.agents[2].delay.base_s = 0.035; // 0.035 + 0.015 = tau_M
    assert!(!errors(&s).iter().any(|e| e.field == "agents[2].delay"));
}

// ---------------------------------------------------------------- Assumption 4: attitude constraints

rejects!(
    initial_roll_outside_constraints_is_rejected_naming_assumption_4,
    "agents[1].initial_attitude_rad[0]",
    A4,
    |s| {
        s.agents[1].initial_attitude_rad[0] = 0.5;
    }
);
rejects!(
    initial_pitch_outside_constraints_is_rejected_naming_assumption_4,
    "agents[4].initial_attitude_rad[1]",
    A4,
    |s| {
        s.agents[4].initial_attitude_rad[1] = -0.5;
    }
);
rejects!(
    non_positive_attitude_margin_is_rejected_naming_assumption_4,
    "controller.attitude.attitude_margin_rad",
    A4,
    |s| {
        s.controller.attitude.attitude_margin_rad = 0.0;
    }
);
rejects!(
    non_positive_rate_constraint_is_rejected_naming_assumption_4,
    "controller.attitude.rate_limit_rad_s",
    A4,
    |s| {
        s.controller.attitude.rate_limit_rad_s = -1.0;
    }
);
rejects!(
    alpha_magnitude_bound_at_or_above_rate_constraint_is_rejected_naming_eq_40,
    "controller.rate_command_filter.magnitude_limit",
    "eq. (40)",
    |s| {
        s.controller.rate_command_filter.magnitude_limit = [1.0, 1.0, 0.3];
    }
);

// ---------------------------------------------------------------- Assumption 5: faults

rejects!(
    total_actuator_failure_is_rejected_naming_assumption_5,
    "agents[1].fault.gamma_final[2]",
    A5,
    |s| {
        s.agents[1].fault.gamma_final[2] = 0.0;
        s.agents[1].fault.gamma_initial_excess[2] = 0.0;
    }
);
rejects!(
    gamma_below_gamma_min_is_rejected_naming_assumption_5,
    "agents[0].fault.gamma_final[0]",
    A5,
    |s| {
        s.agents[0].fault.gamma_final[0] = 0.2;
    }
);
rejects!(
    gamma_above_gamma_max_is_rejected_naming_assumption_5,
    "agents[3].fault.gamma_initial_excess[1]",
    A5,
    |s| {
        s.agents[3].fault.gamma_initial_excess[1] = 0.5; // 0.8 + 0.5 > 1.05
    }
);
rejects!(
    gamma_min_above_gamma_max_is_rejected_naming_assumption_5,
    "controller.adaptive.gamma_min",
    A5,
    |s| {
        s.controller.adaptive.gamma_min = 1.2;
    }
);
rejects!(
    non_positive_gamma_min_is_rejected_naming_assumption_5,
    "controller.adaptive.gamma_min",
    A5,
    |s| {
        s.controller.adaptive.gamma_min = 0.0;
    }
);
rejects!(
    gamma_hat_initial_out_of_range_is_rejected_naming_assumption_5,
    "controller.adaptive.gamma_hat_initial",
    A5,
    |s| {
        s.controller.adaptive.gamma_hat_initial = 1.5;
    }
);
rejects!(
    negative_gamma_decay_rate_is_rejected_naming_assumption_5,
    "agents[2].fault.gamma_decay_rate",
    A5,
    |s| {
        s.agents[2].fault.gamma_decay_rate = -1.0;
    }
);
rejects!(
    negative_delta_ramp_rate_is_rejected_naming_assumption_5,
    "agents[2].fault.delta_ramp_rate",
    A5,
    |s| {
        s.agents[2].fault.delta_ramp_rate = -1.0;
    }
);
rejects!(
    growing_additive_fault_is_rejected_as_unbounded,
    "agents[0].fault.delta_osc_decay[1]",
    "delta_i(t) is bounded",
    |s| {
        s.agents[0].fault.delta_osc_decay[1] = -0.1;
    }
);
rejects!(
    negative_ramp_decay_is_rejected_as_unbounded,
    "agents[2].fault.delta_ramp_decay[2]",
    "delta_i(t) is bounded",
    |s| {
        s.agents[2].fault.delta_ramp_decay[2] = -0.05;
    }
);
rejects!(
    additive_fault_of_half_the_torque_range_is_rejected_as_leaving_no_authority,
    "agents[1].fault.delta_ramp_nm[0]",
    "additive fault must leave torque authority",
    |s| {
        s.agents[1].fault.delta_ramp_nm[0] = 0.4; // half of the 0.8 N m range
    }
);

// ---------------------------------------------------------------- eq. (3) and physical parameters

rejects!(
    torque_min_equal_to_torque_max_is_rejected_naming_eq_3,
    "vehicle.torque_min_nm[2]",
    SAT,
    |s| {
        s.vehicle.torque_min_nm[2] = 2.0;
    }
);
rejects!(
    torque_min_above_torque_max_is_rejected_naming_eq_3,
    "vehicle.torque_min_nm[0]",
    SAT,
    |s| {
        s.vehicle.torque_min_nm[0] = 0.5;
    }
);
rejects!(
    non_positive_mass_is_rejected,
    "vehicle.mass_kg",
    PHYS,
    |s| {
        s.vehicle.mass_kg = 0.0;
    }
);
rejects!(
    non_positive_inertia_is_rejected,
    "vehicle.inertia_kg_m2[2]",
    PHYS,
    |s| {
        s.vehicle.inertia_kg_m2[2] = -0.04;
    }
);
rejects!(
    negative_rotational_drag_is_rejected,
    "vehicle.rotational_drag[1]",
    PHYS,
    |s| {
        s.vehicle.rotational_drag[1] = -0.003;
    }
);
rejects!(
    thrust_limit_below_weight_is_rejected,
    "vehicle.thrust_max_n",
    PHYS,
    |s| {
        s.vehicle.thrust_max_n = 8.0; // m g = 8.4 N
    }
);
rejects!(
    non_positive_gravity_is_rejected,
    "simulation.gravity_m_s2",
    PHYS,
    |s| {
        s.simulation.gravity_m_s2 = 0.0;
    }
);
rejects!(
    non_positive_target_radius_is_rejected,
    "metrics.target_radius_m",
    PHYS,
    |s| {
        s.metrics.target_radius_m = 0.0;
    }
);
rejects!(
    non_positive_divergence_position_is_rejected,
    "metrics.divergence_position_m",
    SIM,
    |s| {
        s.metrics.divergence_position_m = 0.0;
    }
);
rejects!(
    non_positive_divergence_tilt_is_rejected,
    "metrics.divergence_tilt_rad",
    SIM,
    |s| {
        s.metrics.divergence_tilt_rad = -1.4;
    }
);
rejects!(
    negative_rbfnn_initial_weight_amplitude_is_rejected,
    "controller.rbfnn.initial_weight_amplitude",
    CTRL,
    |s| {
        s.controller.rbfnn.initial_weight_amplitude = -0.05;
    }
);
rejects!(
    sensor_field_of_view_of_180_degrees_is_rejected,
    "metrics.sensor_fov_deg",
    PHYS,
    |s| {
        s.metrics.sensor_fov_deg = 180.0;
    }
);
rejects!(
    velocity_power_other_than_one_or_two_is_rejected,
    "agents[3].uncertainty.velocity_power[1]",
    PHYS,
    |s| {
        s.agents[3].uncertainty.velocity_power[1] = 3;
    }
);
rejects!(
    zero_disturbance_direction_is_rejected,
    "agents[4].disturbance.direction",
    PHYS,
    |s| {
        s.agents[4].disturbance.direction = [0.0; 3];
    }
);

// ---------------------------------------------------------------- simulation settings

rejects!(non_positive_step_is_rejected, "simulation.dt_s", SIM, |s| {
    s.simulation.dt_s = 0.0;
});
rejects!(
    non_positive_duration_is_rejected,
    "simulation.duration_s",
    SIM,
    |s| {
        s.simulation.duration_s = -1.0;
    }
);
rejects!(
    non_positive_output_rate_is_rejected,
    "simulation.output_rate_hz",
    SIM,
    |s| {
        s.simulation.output_rate_hz = 0.0;
    }
);
rejects!(
    output_rate_above_step_rate_is_rejected,
    "simulation.output_rate_hz",
    SIM,
    |s| {
        s.simulation.output_rate_hz = 2000.0;
    }
);
rejects!(
    reversed_cover_window_is_rejected,
    "metrics.cover_window_s",
    SIM,
    |s| {
        s.metrics.cover_window_s = [35.0, 15.0];
    }
);
rejects!(
    negative_enclose_window_start_is_rejected,
    "metrics.enclose_window_s",
    SIM,
    |s| {
        s.metrics.enclose_window_s = [-1.0, 60.0];
    }
);
rejects!(
    command_filter_unresolved_by_the_step_is_rejected,
    "controller.attitude_command_filter.natural_frequency_rad_s",
    SIM,
    |s| {
        s.controller.attitude_command_filter.natural_frequency_rad_s = 600.0; // w dt = 0.6
    }
);

// ---------------------------------------------------------------- controller gains

rejects!(
    non_positive_k_p_is_rejected_naming_theorem_1,
    "controller.position.k_p",
    "Theorem 1",
    |s| {
        s.controller.position.k_p = 0.0;
    }
);
rejects!(
    non_positive_k_v_is_rejected_naming_theorem_1,
    "controller.position.k_v",
    "Theorem 1",
    |s| {
        s.controller.position.k_v = -2.0;
    }
);
rejects!(
    negative_rbfnn_learning_rate_is_rejected_naming_eq_15,
    "controller.position.nn_learning_rate",
    EQ15,
    |s| {
        s.controller.position.nn_learning_rate = -1.0;
    }
);
rejects!(
    negative_rbfnn_leakage_is_rejected_naming_eq_15,
    "controller.position.nn_leakage",
    EQ15,
    |s| {
        s.controller.position.nn_leakage = -0.001;
    }
);
rejects!(
    non_positive_horizontal_acceleration_limit_is_rejected,
    "controller.position.max_horizontal_accel_m_s2",
    CTRL,
    |s| {
        s.controller.position.max_horizontal_accel_m_s2 = 0.0;
    }
);
rejects!(
    non_positive_up_acceleration_limit_is_rejected,
    "controller.position.max_up_accel_m_s2",
    CTRL,
    |s| {
        s.controller.position.max_up_accel_m_s2 = 0.0;
    }
);
rejects!(
    down_acceleration_limit_of_g_is_rejected_naming_remark_3,
    "controller.position.max_down_accel_m_s2",
    "Remark 3",
    |s| {
        s.controller.position.max_down_accel_m_s2 = 9.81;
    }
);
rejects!(
    tilt_limit_of_pi_over_2_is_rejected,
    "controller.position.max_tilt_rad",
    CTRL,
    |s| {
        s.controller.position.max_tilt_rad = std::f64::consts::FRAC_PI_2;
    }
);
rejects!(
    zero_neurons_per_axis_is_rejected,
    "controller.rbfnn.neurons_per_axis",
    CTRL,
    |s| {
        s.controller.rbfnn.neurons_per_axis = 0;
    }
);
rejects!(
    more_than_64_neurons_per_axis_is_rejected,
    "controller.rbfnn.neurons_per_axis",
    CTRL,
    |s| {
        s.controller.rbfnn.neurons_per_axis = 65;
    }
);
rejects!(
    non_positive_rbfnn_spread_is_rejected,
    "controller.rbfnn.spread",
    CTRL,
    |s| {
        s.controller.rbfnn.spread = 0.0;
    }
);
rejects!(
    non_positive_rbfnn_position_span_is_rejected,
    "controller.rbfnn.position_span_m",
    CTRL,
    |s| {
        s.controller.rbfnn.position_span_m = 0.0;
    }
);
rejects!(
    non_positive_rbfnn_velocity_span_is_rejected,
    "controller.rbfnn.velocity_span_m_s",
    CTRL,
    |s| {
        s.controller.rbfnn.velocity_span_m_s = -3.0;
    }
);
rejects!(
    non_positive_filter_frequency_is_rejected,
    "controller.rate_command_filter.natural_frequency_rad_s",
    CTRL,
    |s| {
        s.controller.rate_command_filter.natural_frequency_rad_s = 0.0;
    }
);
rejects!(
    non_positive_filter_damping_is_rejected,
    "controller.attitude_command_filter.damping",
    CTRL,
    |s| {
        s.controller.attitude_command_filter.damping = 0.0;
    }
);
rejects!(
    non_positive_filter_magnitude_limit_is_rejected,
    "controller.attitude_command_filter.magnitude_limit[1]",
    CTRL,
    |s| {
        s.controller.attitude_command_filter.magnitude_limit[1] = 0.0;
    }
);
rejects!(
    non_positive_filter_rate_limit_is_rejected,
    "controller.rate_command_filter.rate_limit[2]",
    CTRL,
    |s| {
        s.controller.rate_command_filter.rate_limit[2] = -1.0;
    }
);
rejects!(
    non_positive_k1_alpha_is_rejected_naming_eq_34,
    "controller.attitude.k1_alpha",
    "eq. (34)",
    |s| {
        s.controller.attitude.k1_alpha = 0.0;
    }
);
rejects!(
    k1_alpha_not_above_twice_k1c_is_rejected_naming_eq_34,
    "controller.attitude.k1_alpha",
    "K_i1alpha > 2 K_i1C",
    |s| {
        s.controller.attitude.k1_alpha = 0.1; // 2 sqrt(0.01) = 0.2
    }
);
rejects!(
    non_positive_k2_phi_is_rejected_naming_eq_45,
    "controller.attitude.k2_phi",
    "eq. (45)",
    |s| {
        s.controller.attitude.k2_phi = -1.0;
    }
);
rejects!(
    k2_phi_not_above_twice_k2c_is_rejected_naming_eq_45,
    "controller.attitude.k2_phi",
    "K_i2Phi > 2 K_i2C",
    |s| {
        s.controller.attitude.k2_phi = 0.2; // = 2 sqrt(0.01)
    }
);
rejects!(
    non_positive_eps1_c_is_rejected,
    "controller.attitude.eps1_c",
    CTRL,
    |s| {
        s.controller.attitude.eps1_c = 0.0;
    }
);
rejects!(
    non_positive_eps2_c_is_rejected,
    "controller.attitude.eps2_c",
    CTRL,
    |s| {
        s.controller.attitude.eps2_c = 0.0;
    }
);
rejects!(
    non_positive_mu2_is_rejected,
    "controller.attitude.mu2",
    CTRL,
    |s| {
        s.controller.attitude.mu2 = 0.0;
    }
);
rejects!(
    negative_adaptive_rate_is_rejected_naming_eq_46_49,
    "controller.adaptive.delta_rate",
    EQ46_49,
    |s| {
        s.controller.adaptive.delta_rate = -0.31;
    }
);
rejects!(
    negative_adaptive_leakage_is_rejected_naming_eq_46_49,
    "controller.adaptive.gamma_leakage",
    EQ46_49,
    |s| {
        s.controller.adaptive.gamma_leakage = -0.85;
    }
);
rejects!(
    negative_auxiliary_gain_is_rejected_naming_eq_50,
    "controller.auxiliary.k2_e",
    EQ35_50,
    |s| {
        s.controller.auxiliary.k2_e = -2.0;
    }
);
rejects!(
    non_positive_auxiliary_threshold_is_rejected,
    "controller.auxiliary.e1_threshold",
    CTRL,
    |s| {
        s.controller.auxiliary.e1_threshold = 0.0;
    }
);
rejects!(
    non_positive_unconstrained_attitude_gain_is_rejected,
    "controller.unconstrained.attitude_gain",
    CTRL,
    |s| {
        s.controller.unconstrained.attitude_gain = 0.0;
    }
);
rejects!(
    non_positive_unconstrained_rate_gain_is_rejected,
    "controller.unconstrained.rate_gain",
    CTRL,
    |s| {
        s.controller.unconstrained.rate_gain = 0.0;
    }
);

// ---------------------------------------------------------------- fault identification (D16)

rejects!(
    probe_period_that_is_not_a_whole_number_of_steps_is_rejected,
    "controller.fault_identification.probe_period_s",
    CTRL,
    |s| {
        s.controller.fault_identification.probe_period_s = 0.0255;
    }
);

rejects!(
    probe_period_longer_than_the_identifier_buffer_is_rejected,
    "controller.fault_identification.probe_period_s",
    CTRL,
    |s| {
        s.controller.fault_identification.probe_period_s = 0.2;
    }
);

rejects!(
    probe_amplitude_beyond_a_quarter_of_the_torque_range_is_rejected,
    "controller.fault_identification.probe_amplitude_nm[0]",
    SAT,
    |s| {
        s.controller.fault_identification.probe_amplitude_nm[0] = 0.3;
    }
);

rejects!(
    excitation_ratio_above_one_is_rejected,
    "controller.fault_identification.excitation_ratio",
    CTRL,
    |s| {
        s.controller.fault_identification.excitation_ratio = 1.5;
    }
);

#[test]
fn scenario_without_fault_identification_section_parses_with_identification_off() {
    let text = PAPER_TOML.replace(
        "[controller.fault_identification]",
        "[controller.unused_section]",
    );
    // Drop the whole section: its keys would otherwise land in the renamed table.
    let start = text.find("[controller.unused_section]").unwrap();
    let end = text[start..].find("[controller.auxiliary]").unwrap() + start;
    let text = format!("{}{}", &text[..start], &text[end..]);
    let s = Scenario::from_toml_str(&text).unwrap();
    assert_eq!(
        s.controller.fault_identification.probe_amplitude_nm,
        [0.0; 3]
    );
    assert_eq!(s.controller.fault_identification.composite_rate, 0.0);
}

// ---------------------------------------------------------------- signs of the remaining gains

rejects!(
    duration_shorter_than_one_step_is_rejected_as_a_run_without_steps,
    "simulation.duration_s",
    SIM,
    |s| {
        s.simulation.duration_s = 0.0004; // dt = 0.001: round(0.4) = 0 steps
    }
);
#[test]
fn duration_of_exactly_one_step_is_accepted() {
    let mut s = Scenario::paper();
    s.simulation.duration_s = s.simulation.dt_s;
    assert!(!errors(&s)
        .iter()
        .any(|e| e.field == "simulation.duration_s"));
}
rejects!(
    negative_rbfnn_position_weight_k_p_is_rejected_naming_eq_15,
    "controller.position.nn_k_p",
    "eq. (15)",
    |s| {
        s.controller.position.nn_k_p = -5.0;
    }
);
rejects!(
    negative_rbfnn_velocity_weight_k_v_is_rejected_naming_eq_15,
    "controller.position.nn_k_v",
    "eq. (15)",
    |s| {
        s.controller.position.nn_k_v = -1e308;
    }
);
rejects!(
    negative_leader_velocity_damping_is_rejected_naming_d11,
    "controller.position.leader_velocity_damping",
    D11,
    |s| {
        s.controller.position.leader_velocity_damping = -1.6;
    }
);
rejects!(
    negative_leader_position_gain_is_rejected_naming_d11,
    "controller.position.leader_position_gain",
    D11,
    |s| {
        s.controller.position.leader_position_gain = -1.0;
    }
);
rejects!(
    negative_leader_relative_rbfnn_drive_is_rejected_naming_d23,
    "controller.position.nn_leader_k_v",
    D23,
    |s| {
        s.controller.position.nn_leader_k_v = -0.3;
    }
);
rejects!(
    a_zero_limit_of_the_leader_relative_rbfnn_drive_is_rejected_naming_d23,
    "controller.position.nn_leader_drive_limit_m",
    D23,
    |s| {
        s.controller.position.nn_leader_drive_limit_m = Some(0.0);
    }
);
rejects!(
    negative_initial_disturbance_bound_estimate_is_rejected_naming_eq_49,
    "controller.adaptive.disturbance_hat_initial",
    "eq. (49)",
    |s| {
        s.controller.adaptive.disturbance_hat_initial = -0.1;
    }
);
rejects!(
    auxiliary_gain_k1_e_of_one_is_rejected_naming_eq_35,
    "controller.auxiliary.k1_e",
    "K_iE > 1",
    |s| {
        s.controller.auxiliary.k1_e = 1.0;
    }
);
rejects!(
    non_positive_auxiliary_gamma1_e_is_rejected_naming_eq_35,
    "controller.auxiliary.gamma1_e",
    EQ35_50,
    |s| {
        s.controller.auxiliary.gamma1_e = 0.0;
    }
);
rejects!(
    negative_auxiliary_gamma2_e_is_rejected_naming_eq_50,
    "controller.auxiliary.gamma2_e",
    EQ35_50,
    |s| {
        s.controller.auxiliary.gamma2_e = -0.2;
    }
);
rejects!(
    non_positive_leader_convergence_rate_is_rejected_naming_section_4,
    "mission.leader.convergence_rate",
    MISSION,
    |s| {
        s.mission.leader.convergence_rate = -2.0;
    }
);
rejects!(
    non_positive_leader_climb_rate_is_rejected_naming_section_4,
    "mission.leader.climb_rate",
    MISSION,
    |s| {
        s.mission.leader.climb_rate = 0.0;
    }
);
rejects!(
    negative_formation_radius_is_rejected_naming_section_4,
    "mission.formation.cover_radius_m",
    MISSION,
    |s| {
        s.mission.formation.cover_radius_m = -2.0;
    }
);
rejects!(
    negative_spin_onset_sharpness_is_rejected_naming_section_4,
    "mission.formation.spin_onset_sharpness",
    MISSION,
    |s| {
        s.mission.formation.spin_onset_sharpness = -1.0;
    }
);
#[test]
fn zero_rbfnn_gains_switch_the_update_off_and_are_accepted() {
    let mut s = Scenario::paper();
    s.controller.position.nn_k_p = 0.0;
    s.controller.position.nn_k_v = 0.0;
    assert_eq!(validate(&s), Ok(()));
}

/// An event of `kind` for agent 1 at 1 s.
fn event(
    kind: formation_config::scenario::events::EventKind,
) -> formation_config::scenario::events::Event {
    let mut e = formation_config::scenario::events::Event::new(1.0, kind);
    e.agent = Some(1);
    e
}

#[test]
fn down_times_that_are_infinite_nan_negative_or_beyond_the_runs_end_are_refused() {
    use formation_config::scenario::events::EventKind;
    let s = Scenario::paper();
    let remaining = s.simulation.duration_s - 1.0;
    for kind in [EventKind::Crash, EventKind::Hang] {
        for bad in [
            f64::INFINITY,
            f64::NAN,
            -1.0,
            0.0,
            1e9,
            1e15,
            remaining + 0.5,
        ] {
            let mut with = s.clone();
            let mut e = event(kind);
            e.down_s = Some(bad);
            with.events.push(e.clone());
            let assumption = if bad.is_finite() {
                "timeline"
            } else {
                "finite"
            };
            assert_rejected(&with, "events[0].down_s", assumption);
            // What `formation inject` and the orchestrator check for a live event.
            let live = validate_event(&s, "inject", &e).unwrap_err();
            assert!(
                live.0.iter().any(|x| x.field == "inject.down_s"),
                "{bad}: {live:?}"
            );
        }
        let mut ok = s.clone();
        let mut e = event(kind);
        e.down_s = Some(remaining);
        ok.events.push(e);
        assert!(errors(&ok).is_empty(), "{:?}", errors(&ok));
    }
}

#[test]
fn a_timeline_fault_has_the_live_injections_limits_and_times_must_be_finite() {
    use formation_config::scenario::events::EventKind;
    use formation_config::scenario::validate::max_fault_delta_nm;
    let s = Scenario::paper();
    let mut f = s.clone();
    let mut e = event(EventKind::Fault);
    e.gamma = Some([1.0; 3]);
    e.delta = Some([1e308, 0.0, 0.0]);
    f.events.push(e.clone());
    assert_rejected(&f, "events[0].delta[0]", "eq. (3)");
    e.delta = Some([max_fault_delta_nm(&s, 0), 0.0, f64::NAN]);
    f.events[0] = e.clone();
    assert_rejected(&f, "events[0].delta[2]", "finite");
    let live = validate_event(&s, "inject", &e).unwrap_err();
    assert!(
        live.0.iter().any(|x| x.field == "inject.delta[2]"),
        "{live:?}"
    );
    e.delta = Some([max_fault_delta_nm(&s, 0), 0.0, 0.0]);
    f.events[0] = e;
    assert!(errors(&f).is_empty(), "{:?}", errors(&f));
    let mut d = s.clone();
    let mut e = event(EventKind::Delay);
    e.base_s = Some(0.0);
    e.angular_rate_rad_s = Some(f64::INFINITY);
    d.events.push(e.clone());
    assert_rejected(&d, "events[0].angular_rate_rad_s", "finite");
    let live = validate_event(&s, "inject", &e).unwrap_err();
    assert!(
        live.0
            .iter()
            .any(|x| x.field == "inject.angular_rate_rad_s"),
        "{live:?}"
    );
    let mut t = s.clone();
    let mut e = event(EventKind::LinkDown);
    e.agent = None;
    e.agents = Some([1, 2]);
    e.at_s = f64::INFINITY;
    t.events.push(e.clone());
    assert_rejected(&t, "events[0].at_s", "finite");
    let live = validate_event(&s, "inject", &e).unwrap_err();
    assert!(live.0.iter().any(|x| x.field == "inject.at_s"), "{live:?}");
}

#[test]
fn a_timeline_longer_than_the_cap_is_one_error_not_one_per_event() {
    use formation_config::scenario::events::EventKind;
    use formation_config::scenario::validate::MAX_EVENTS;
    let mut s = Scenario::paper();
    let mut e = event(EventKind::Crash);
    e.down_s = Some(f64::INFINITY);
    s.events = vec![e; MAX_EVENTS + 1];
    let errs = errors(&s);
    assert_eq!(errs.len(), 1, "{errs:?}");
    assert_eq!(errs[0].field, "events");
}
