//! Validation of a scenario against the paper's assumptions and basic physical sense.
//!
//! Every error names the offending field (as a TOML path) and the assumption it breaks, so that a
//! user sees at once what to fix. Commands exit with code 2 on a validation error.

// `!(x > 0.0)` rather than `x <= 0.0` throughout: the negated form also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use crate::scenario::graph::Topology;
use crate::scenario::{AgentSpec, Scenario, MAX_PROBE_PERIOD_STEPS};
use crate::MAX_AGENTS;

/// One reason a scenario is rejected.
#[derive(Debug, Clone, PartialEq)]
pub struct ValidationError {
    /// TOML path of the offending field, e.g. `agents[2].fault.gamma_final[0]`.
    pub field: String,
    /// The paper assumption or physical requirement it breaks.
    pub assumption: &'static str,
    /// What is wrong, with the offending value.
    pub message: String,
}

impl ValidationError {
    /// The 1-based agent id of a field under `agents[k]` (TOML indices are 0-based).
    pub fn agent_id(&self) -> Option<usize> {
        let rest = self.field.strip_prefix("agents[")?;
        let (k, _) = rest.split_once(']')?;
        k.parse::<usize>().ok().map(|k| k + 1)
    }
}

impl std::fmt::Display for ValidationError {
    /// `field: message (assumption)`; a field under `agents[k]` is followed by `(agent k+1)`.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.agent_id() {
            Some(id) => write!(
                f,
                "{} (agent {id}): {} ({})",
                self.field, self.message, self.assumption
            ),
            None => write!(f, "{}: {} ({})", self.field, self.message, self.assumption),
        }
    }
}

/// All the reasons a scenario is rejected.
#[derive(Debug, Clone, PartialEq)]
pub struct ValidationErrors(pub Vec<ValidationError>);

impl std::fmt::Display for ValidationErrors {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        for (k, e) in self.0.iter().enumerate() {
            if k > 0 {
                writeln!(f)?;
            }
            write!(f, "{e}")?;
        }
        Ok(())
    }
}

impl std::error::Error for ValidationErrors {}

/// Assumption 1 of the paper.
pub const A1: &str = "Assumption 1: the graph is connected and the leader reaches every agent";
/// Assumption 2 of the paper.
pub const A2: &str = "Assumption 2: delays are bounded, 0 <= tau_i(t) <= tau_M";
/// Assumption 4 of the paper.
pub const A4: &str = "Assumption 4: the initial attitude lies inside the constraints";
/// Assumption 5 of the paper.
pub const A5: &str = "Assumption 5: 0 < Gamma_min <= Gamma_ik(t) <= Gamma_max";
/// Input saturation (3).
pub const SAT: &str = "eq. (3): U_ik,L < U_ik,H";
/// Physical sense.
pub const PHYS: &str = "physical parameters must be positive";
/// Finite numbers.
pub const FINITE: &str = "every number must be finite";
/// Graph indices.
pub const INDEX: &str = "agent and neighbour indices must be in range 1..=N";
/// Simulation settings.
pub const SIM: &str = "simulation settings must be positive and consistent";
/// Controller settings.
pub const CTRL: &str = "controller gains must be positive where the paper requires it";
/// The RBFNN update law (15).
pub const EQ15: &str =
    "eq. (15): K_P, K_V, K_W and kappa_ik are positive design constants (0 switches a term off)";
/// The leader-relative terms of the position law (docs/deviations.md, D11).
pub const D11: &str =
    "D11: k_L and k_LP add damping and stiffness to every consensus mode, so they cannot be negative";
/// D23: the RBFNN's leader-relative drive.
pub const D23: &str =
    "D23: the leader-relative drive of the RBFNN update (15) weighs an error, so it cannot be negative";
/// The adaptive laws (46)-(49).
pub const EQ46_49: &str =
    "eq. (46)-(49): adaptation rates and leakages are non-negative design constants";
/// The auxiliary systems (35), (50).
pub const EQ35_50: &str = "eq. (35), (50): K_iE > 1 and gamma_iE > 0";
/// The separation layer and its position broadcast (docs/deviations.md D25).
pub const SEPARATION: &str =
    "D25: the separation layer's barrier needs a positive braking, jerk, rate and sensing range, non-negative margins, lag and repulsive gain (finite), and a broadcast delay within the delay bound tau_M";
/// The shaping of the transitions (docs/deviations.md D26).
pub const SHAPING: &str = "D26: a transition is capped to a positive acceleration and jerk";
/// The mission of Section 4.
pub const MISSION: &str =
    "Section 4: the leader's convergence terms (1 - e^{-r t}) converge only for r > 0; sharpness and radii are >= 0";

struct Collector(Vec<ValidationError>);

impl Collector {
    fn push(
        &mut self,
        field: impl Into<String>,
        assumption: &'static str,
        message: impl Into<String>,
    ) {
        self.0.push(ValidationError {
            field: field.into(),
            assumption,
            message: message.into(),
        });
    }
    fn positive(&mut self, field: &str, v: f64, assumption: &'static str) {
        if !(v > 0.0) {
            self.push(field, assumption, format!("must be > 0, got {v}"));
        }
    }
    fn non_negative(&mut self, field: &str, v: f64, assumption: &'static str) {
        if !(v >= 0.0) {
            self.push(field, assumption, format!("must be >= 0, got {v}"));
        }
    }
}

/// Validates a scenario; returns every error found (not just the first).
pub fn validate(s: &Scenario) -> Result<(), ValidationErrors> {
    let mut c = Collector(Vec::new());
    if s.events.len() > MAX_EVENTS {
        c.push(
            "events",
            TIMELINE,
            format!(
                "{} events; a timeline holds at most {MAX_EVENTS} (every process asks it about every step)",
                s.events.len()
            ),
        );
        return Err(ValidationErrors(c.0));
    }
    check_finite(s, &mut c);
    if !c.0.is_empty() {
        return Err(ValidationErrors(c.0));
    }
    check_simulation(s, &mut c);
    check_metrics(s, &mut c);
    check_mission(s, &mut c);
    check_vehicle(s, &mut c);
    check_graph(s, &mut c);
    check_position_and_filters(s, &mut c);
    check_attitude(s, &mut c);
    check_adaptive_and_auxiliary(s, &mut c);
    // Agents.
    for (i, a) in s.agents.iter().enumerate() {
        check_agent(s, i, a, &mut c);
    }
    check_runtime(s, &mut c);
    check_separation(s, &mut c);
    for (k, e) in s.events.iter().enumerate() {
        check_event(s, &format!("events[{k}]"), e, &mut c);
    }
    if c.0.is_empty() {
        Ok(())
    } else {
        Err(ValidationErrors(c.0))
    }
}

/// D25 and D26: the separation layer's and the shaping's parameters.
fn check_separation(s: &Scenario, c: &mut Collector) {
    let sp = &s.controller.separation;
    let f = |name: &str| format!("controller.separation.{name}");
    c.non_negative(&f("margin_m"), sp.margin_m, SEPARATION);
    c.non_negative(&f("activation_m"), sp.activation_m, SEPARATION);
    c.positive(&f("braking_accel_m_s2"), sp.braking_accel_m_s2, SEPARATION);
    c.positive(&f("jerk_m_s3"), sp.jerk_m_s3, SEPARATION);
    c.non_negative(&f("response_time_s"), sp.response_time_s, SEPARATION);
    c.positive(&f("barrier_rate_1_s"), sp.barrier_rate_1_s, SEPARATION);
    c.non_negative(&f("sidestep_ratio"), sp.sidestep_ratio, SEPARATION);
    c.positive(&f("sensing_range_m"), sp.sensing_range_m, SEPARATION);
    let k_r = sp.repulsive_gain_m3_s2;
    if !(k_r >= 0.0 && k_r.is_finite()) {
        c.push(
            f("repulsive_gain_m3_s2"),
            SEPARATION,
            format!("must be finite and >= 0, got {k_r}"),
        );
    }
    let tau_m = s.simulation.max_delay_s;
    if !(sp.broadcast_delay_s >= 0.0 && sp.broadcast_delay_s <= tau_m) {
        c.push(
            f("broadcast_delay_s"),
            SEPARATION,
            format!(
                "must be in [0, tau_M = {tau_m}] s, got {}",
                sp.broadcast_delay_s
            ),
        );
    }
    let dt = s.simulation.dt_s;
    if !(sp.broadcast_period_s >= dt && sp.broadcast_period_s <= 1.0) {
        c.push(
            f("broadcast_period_s"),
            SEPARATION,
            format!("must be in [dt = {dt}, 1] s, got {}", sp.broadcast_period_s),
        );
    }
    let sh = &s.mission.shaping;
    c.positive("mission.shaping.accel_m_s2", sh.accel_m_s2, SHAPING);
    c.positive("mission.shaping.jerk_m_s3", sh.jerk_m_s3, SHAPING);
}

/// D16: the probe must fit the torque range and the identifier's one-period buffer.
fn check_fault_identification(s: &Scenario, c: &mut Collector) {
    let id = &s.controller.fault_identification;
    let v = &s.vehicle;
    let active = id.probe_amplitude_nm.iter().any(|a| *a != 0.0);
    for k in 0..3 {
        let half_range = 0.5 * (v.torque_max_nm[k] - v.torque_min_nm[k]);
        let a = id.probe_amplitude_nm[k];
        if !(a >= 0.0 && a <= 0.25 * half_range) {
            c.push(
                format!("controller.fault_identification.probe_amplitude_nm[{k}]"),
                SAT,
                format!(
                    "{a} N m must lie in [0, a quarter of the half torque range = {}]",
                    0.25 * half_range
                ),
            );
        }
    }
    if !active {
        return;
    }
    let dt = s.simulation.dt_s;
    let steps = id.probe_period_s / dt;
    if !(steps >= 4.0
        && steps <= MAX_PROBE_PERIOD_STEPS as f64
        && (steps - steps.round()).abs() < 1e-6)
    {
        c.push(
            "controller.fault_identification.probe_period_s",
            CTRL,
            format!(
                "{} s must be a whole number of steps (dt = {dt} s) between 4 and {MAX_PROBE_PERIOD_STEPS}",
                id.probe_period_s
            ),
        );
    }
    c.positive(
        "controller.fault_identification.gamma_averaging_s",
        id.gamma_averaging_s,
        CTRL,
    );
    c.positive(
        "controller.fault_identification.delta_averaging_s",
        id.delta_averaging_s,
        CTRL,
    );
    c.non_negative(
        "controller.fault_identification.composite_rate",
        id.composite_rate,
        CTRL,
    );
    if !(id.excitation_ratio > 0.0 && id.excitation_ratio <= 1.0) {
        c.push(
            "controller.fault_identification.excitation_ratio",
            CTRL,
            format!("{} must lie in (0, 1]", id.excitation_ratio),
        );
    }
}

fn check_agent(s: &Scenario, i: usize, a: &AgentSpec, c: &mut Collector) {
    let p = format!("agents[{i}]");
    check_agent_delay_and_attitude(s, i, a, c);
    check_agent_fault(s, i, a, c);
    for k in 0..3 {
        if !(a.uncertainty.velocity_power[k] == 1 || a.uncertainty.velocity_power[k] == 2) {
            c.push(
                format!("{p}.uncertainty.velocity_power[{k}]"),
                PHYS,
                "must be 1 or 2 (eq. (61))",
            );
        }
    }
    if norm3(a.disturbance.direction) == 0.0 {
        c.push(
            format!("{p}.disturbance.direction"),
            PHYS,
            "must be a non-zero vector",
        );
    }
}

/// Agent i's delay within [0, tau_M] (Assumption 2) and initial attitude inside the constraints
/// (Assumption 4).
fn check_agent_delay_and_attitude(s: &Scenario, i: usize, a: &AgentSpec, c: &mut Collector) {
    let p = format!("agents[{i}]");
    // Assumption 2: tau_i(t) in [0, tau_M] for all t.
    let d = &a.delay;
    let hi = d.base_s + d.amplitude_s.abs();
    let lo = d.base_s - d.amplitude_s.abs();
    if hi > s.simulation.max_delay_s + 1e-12 {
        c.push(
            format!("{p}.delay"),
            A2,
            format!(
                "tau_{} reaches {:.4} s above tau_M = {:.4} s",
                i + 1,
                hi,
                s.simulation.max_delay_s
            ),
        );
    }
    if lo < 0.0 {
        c.push(
            format!("{p}.delay"),
            A2,
            format!("tau_{} goes negative ({lo:.4} s)", i + 1),
        );
    }
    // Assumption 4: initial attitude inside the constraints. With C-bar_i1 = ||A_iC|| + margin and the
    // command starting at the initial attitude, the roll/pitch must stay clear of the R_r singularity
    // and the initial rate (zero) is inside C-bar_i2.
    let att = a.initial_attitude_rad;
    let tilt_limit = s.controller.position.max_tilt_rad;
    for (k, name) in [(0usize, "phi"), (1, "theta")] {
        if att[k].abs() > tilt_limit {
            c.push(
                format!("{p}.initial_attitude_rad[{k}]"),
                A4,
                format!(
                    "initial {name} = {} rad exceeds the tilt limit {tilt_limit} rad",
                    att[k]
                ),
            );
        }
    }
}

/// Agent i's actuator faults within the bounds of Assumption 5, leaving torque authority.
fn check_agent_fault(s: &Scenario, i: usize, a: &AgentSpec, c: &mut Collector) {
    let p = format!("agents[{i}]");
    let ad = &s.controller.adaptive;
    let f = &a.fault;
    for k in 0..3 {
        let g_final = f.gamma_final[k];
        let g_start = f.gamma_final[k] + f.gamma_initial_excess[k];
        let (g_lo, g_hi) = (g_final.min(g_start), g_final.max(g_start));
        if !(g_lo > 0.0) {
            c.push(
                format!("{p}.fault.gamma_final[{k}]"),
                A5,
                format!(
                    "Gamma_{}{} reaches {g_lo} <= 0 (total failure)",
                    i + 1,
                    k + 1
                ),
            );
        } else if g_lo < ad.gamma_min - 1e-12 {
            c.push(
                format!("{p}.fault.gamma_final[{k}]"),
                A5,
                format!(
                    "Gamma_{}{} reaches {g_lo} below Gamma_min = {}",
                    i + 1,
                    k + 1,
                    ad.gamma_min
                ),
            );
        }
        if g_hi > ad.gamma_max + 1e-12 {
            c.push(
                format!("{p}.fault.gamma_initial_excess[{k}]"),
                A5,
                format!(
                    "Gamma_{}{} reaches {g_hi} above Gamma_max = {}",
                    i + 1,
                    k + 1,
                    ad.gamma_max
                ),
            );
        }
    }
    c.non_negative(
        &format!("{p}.fault.gamma_decay_rate"),
        f.gamma_decay_rate,
        A5,
    );
    c.non_negative(&format!("{p}.fault.delta_ramp_rate"), f.delta_ramp_rate, A5);
    for k in 0..3 {
        for (name, v) in [
            ("delta_ramp_decay", f.delta_ramp_decay[k]),
            ("delta_osc_grow", f.delta_osc_grow[k]),
            ("delta_osc_decay", f.delta_osc_decay[k]),
            ("delta_bias_decay", f.delta_bias_decay[k]),
        ] {
            c.non_negative(
                &format!("{p}.fault.{name}[{k}]"),
                v,
                "Assumption 5: delta_i(t) is bounded",
            );
        }
        let span = s.vehicle.torque_max_nm[k] - s.vehicle.torque_min_nm[k];
        let bound =
            f.delta_ramp_nm[k].abs() + f.delta_osc_amplitude_nm[k].abs() + f.delta_bias_nm[k].abs();
        if span > 0.0 && bound >= 0.5 * span {
            c.push(
                format!("{p}.fault.delta_ramp_nm[{k}]"),
                "Assumption 5 with eq. (3): the additive fault must leave torque authority",
                format!(
                    "|delta_{}{}| can reach {bound:.3} N m, half the torque range or more",
                    i + 1,
                    k + 1
                ),
            );
        }
    }
}

fn norm3(v: [f64; 3]) -> f64 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}

/// Rejects NaN and infinities anywhere in the scenario (checked through its TOML form, so no field is
/// forgotten).
fn check_finite(s: &Scenario, c: &mut Collector) {
    let value = match toml::Value::try_from(s) {
        Ok(v) => v,
        Err(e) => {
            c.push("<scenario>", FINITE, format!("cannot inspect: {e}"));
            return;
        }
    };
    fn walk(path: &str, v: &toml::Value, c: &mut Collector) {
        match v {
            toml::Value::Float(f) if !f.is_finite() => c.push(path, FINITE, format!("got {f}")),
            toml::Value::Array(items) => {
                for (k, it) in items.iter().enumerate() {
                    walk(&format!("{path}[{k}]"), it, c);
                }
            }
            toml::Value::Table(t) => {
                for (k, it) in t {
                    let p = if path.is_empty() {
                        k.clone()
                    } else {
                        format!("{path}.{k}")
                    };
                    walk(&p, it, c);
                }
            }
            _ => {}
        }
    }
    walk("", &value, c);
}

/// Checks the simulation section: step, duration, output rate, delay bound.
fn check_simulation(s: &Scenario, c: &mut Collector) {
    let sim = &s.simulation;
    c.positive("simulation.dt_s", sim.dt_s, SIM);
    c.positive("simulation.duration_s", sim.duration_s, SIM);
    if sim.dt_s > 0.0 && sim.duration_s > 0.0 && sim.duration_s < sim.dt_s {
        c.push(
            "simulation.duration_s",
            SIM,
            format!(
                "{} s is shorter than one step dt = {} s: the run would have no step",
                sim.duration_s, sim.dt_s
            ),
        );
    }
    c.positive("simulation.output_rate_hz", sim.output_rate_hz, SIM);
    c.positive("simulation.gravity_m_s2", sim.gravity_m_s2, PHYS);
    c.positive("simulation.max_delay_s", sim.max_delay_s, A2);
    if sim.dt_s > 0.0 && sim.output_rate_hz > 0.0 && 1.0 / sim.output_rate_hz < sim.dt_s {
        c.push(
            "simulation.output_rate_hz",
            SIM,
            format!(
                "output rate {} Hz exceeds the step rate {} Hz",
                sim.output_rate_hz,
                1.0 / sim.dt_s
            ),
        );
    }
    if sim.max_delay_s > 0.0 && sim.dt_s > 0.0 && sim.max_delay_s / sim.dt_s > 100_000.0 {
        c.push(
            "simulation.max_delay_s",
            A2,
            "delay bound spans more than 100000 steps",
        );
    }
}

/// Checks the metrics section: windows and sensor.
fn check_metrics(s: &Scenario, c: &mut Collector) {
    // Metrics windows.
    for (name, w) in [
        ("metrics.cover_window_s", s.metrics.cover_window_s),
        ("metrics.enclose_window_s", s.metrics.enclose_window_s),
    ] {
        if !(w[0] >= 0.0 && w[1] > w[0]) {
            c.push(
                name,
                SIM,
                format!(
                    "window must satisfy 0 <= start < end, got [{}, {}]",
                    w[0], w[1]
                ),
            );
        }
    }
    c.positive("metrics.target_radius_m", s.metrics.target_radius_m, PHYS);
    c.positive(
        "metrics.safety_distance_m",
        s.metrics.safety_distance_m,
        PHYS,
    );
    c.positive(
        "metrics.divergence_position_m",
        s.metrics.divergence_position_m,
        SIM,
    );
    c.positive(
        "metrics.divergence_tilt_rad",
        s.metrics.divergence_tilt_rad,
        SIM,
    );
    if !(s.metrics.sensor_fov_deg > 0.0 && s.metrics.sensor_fov_deg < 180.0) {
        c.push(
            "metrics.sensor_fov_deg",
            PHYS,
            format!("must be in (0, 180), got {}", s.metrics.sensor_fov_deg),
        );
    }
}

/// Checks the concentric rings of the formation function: one slot per agent, radii >= 0.
fn check_rings(s: &Scenario, c: &mut Collector) {
    let rings = &s.mission.formation.rings;
    if rings.is_empty() {
        return;
    }
    for (j, r) in rings.iter().enumerate() {
        if r.agents == 0 {
            c.push(
                format!("mission.formation.rings[{j}].agents"),
                MISSION,
                "a ring holds at least one agent".to_string(),
            );
        }
        c.non_negative(
            &format!("mission.formation.rings[{j}].cover_radius_m"),
            r.cover_radius_m,
            MISSION,
        );
        c.non_negative(
            &format!("mission.formation.rings[{j}].enclose_radius_m"),
            r.enclose_radius_m,
            MISSION,
        );
        if !r.phase_rad.is_finite() {
            c.push(
                format!("mission.formation.rings[{j}].phase_rad"),
                FINITE,
                format!("{} is not a finite number", r.phase_rad),
            );
        }
    }
    let total: usize = rings.iter().map(|r| r.agents).sum();
    if total != s.n_agents() {
        c.push(
            "mission.formation.rings",
            MISSION,
            format!(
                "the rings hold {total} slots for {} agents: Lambda_F needs exactly one slot per agent",
                s.n_agents()
            ),
        );
    }
}

/// Checks the mission section: leader and formation.
fn check_mission(s: &Scenario, c: &mut Collector) {
    // Mission.
    let (leader, formation) = (&s.mission.leader, &s.mission.formation);
    c.positive(
        "mission.leader.convergence_rate",
        leader.convergence_rate,
        MISSION,
    );
    c.positive("mission.leader.climb_rate", leader.climb_rate, MISSION);
    for (name, val) in [
        ("mission.leader.descent_sharpness", leader.descent_sharpness),
        ("mission.formation.cover_radius_m", formation.cover_radius_m),
        (
            "mission.formation.enclose_radius_m",
            formation.enclose_radius_m,
        ),
        (
            "mission.formation.radius_sharpness",
            formation.radius_sharpness,
        ),
        (
            "mission.formation.spin_onset_sharpness",
            formation.spin_onset_sharpness,
        ),
    ] {
        c.non_negative(name, val, MISSION);
    }
    check_rings(s, c);
}

/// Checks the vehicle section: mass, inertia, thrust and torque limits.
fn check_vehicle(s: &Scenario, c: &mut Collector) {
    let sim = &s.simulation;
    // Vehicle.
    let v = &s.vehicle;
    c.positive("vehicle.mass_kg", v.mass_kg, PHYS);
    for k in 0..3 {
        c.positive(
            &format!("vehicle.inertia_kg_m2[{k}]"),
            v.inertia_kg_m2[k],
            PHYS,
        );
        c.non_negative(
            &format!("vehicle.rotational_drag[{k}]"),
            v.rotational_drag[k],
            PHYS,
        );
        if !(v.torque_min_nm[k] < v.torque_max_nm[k]) {
            c.push(
                format!("vehicle.torque_min_nm[{k}]"),
                SAT,
                format!(
                    "U_min {} must be below U_max {}",
                    v.torque_min_nm[k], v.torque_max_nm[k]
                ),
            );
        }
    }
    if v.mass_kg > 0.0 && !(v.thrust_max_n > v.mass_kg * sim.gravity_m_s2) {
        c.push(
            "vehicle.thrust_max_n",
            PHYS,
            format!(
                "{} N cannot lift m g = {:.3} N",
                v.thrust_max_n,
                v.mass_kg * sim.gravity_m_s2
            ),
        );
    }
}

/// Checks the graph section: N, edges, leader weights, Assumption 1.
fn check_graph(s: &Scenario, c: &mut Collector) {
    let n = s.n_agents();
    // Graph.
    if n == 0 {
        c.push("agents", A1, "at least one agent is needed");
    }
    if n > MAX_AGENTS {
        c.push(
            "agents",
            INDEX,
            format!("{n} agents exceed the supported maximum {MAX_AGENTS}"),
        );
    }
    if s.graph.leader_weights.len() != n {
        c.push(
            "graph.leader_weights",
            INDEX,
            format!(
                "has {} entries for {n} agents",
                s.graph.leader_weights.len()
            ),
        );
    }
    let mut graph_ok = s.graph.leader_weights.len() == n && n > 0;
    let mut seen_edges: Vec<(usize, usize)> = Vec::with_capacity(s.graph.edges.len());
    for (k, e) in s.graph.edges.iter().enumerate() {
        // An undirected edge carries one weight a_ij = a_ji: listing (a, b) and (b, a), or (a, b)
        // twice, would silently add the weights in L.
        let pair = (e.a.min(e.b), e.a.max(e.b));
        if let Some(first) = seen_edges.iter().position(|&p| p == pair) {
            c.push(
                format!("graph.edges[{k}]"),
                A1,
                format!("edge ({}, {}) repeats graph.edges[{first}]: list each undirected edge once (a_ij = a_ji)", e.a, e.b),
            );
            graph_ok = false;
        }
        seen_edges.push(pair);
        for (end, idx) in [("a", e.a), ("b", e.b)] {
            if idx < 1 || idx > n {
                c.push(
                    format!("graph.edges[{k}].{end}"),
                    INDEX,
                    format!("agent {idx} is not in 1..={n}"),
                );
                graph_ok = false;
            }
        }
        if e.a == e.b {
            c.push(
                format!("graph.edges[{k}]"),
                A1,
                format!("self-loop on agent {} (a_ii = 0)", e.a),
            );
            graph_ok = false;
        }
        if !(e.weight > 0.0) {
            c.push(
                format!("graph.edges[{k}].weight"),
                A1,
                format!("a_ij must be > 0, got {}", e.weight),
            );
            graph_ok = false;
        }
    }
    for (i, b) in s.graph.leader_weights.iter().enumerate() {
        c.non_negative(&format!("graph.leader_weights[{i}]"), *b, A1);
    }
    if graph_ok {
        let topo = Topology::from_scenario(s);
        if !topo.connected() {
            c.push("graph.edges", A1, "the follower graph is not connected");
        }
        if !topo.leader_reaches_all() {
            c.push(
                "graph.leader_weights",
                A1,
                "no agent with b_i > 0 reaches every agent (the leader is unreachable)",
            );
        }
    }
}

/// Checks the position loop, RBFNN and command filters.
fn check_position_and_filters(s: &Scenario, c: &mut Collector) {
    check_position(s, c);
    check_rbfnn(s, c);
    check_command_filters(s, c);
}

/// Checks the position loop's gains and limits.
fn check_position(s: &Scenario, c: &mut Collector) {
    let sim = &s.simulation;
    let ctl = &s.controller;
    c.positive(
        "controller.position.k_p",
        ctl.position.k_p,
        "Theorem 1: k_P > 0",
    );
    c.positive(
        "controller.position.k_v",
        ctl.position.k_v,
        "Theorem 1: k_V > 0",
    );
    for (name, val) in [
        ("controller.position.nn_k_p", ctl.position.nn_k_p),
        ("controller.position.nn_k_v", ctl.position.nn_k_v),
        ("controller.position.nn_leakage", ctl.position.nn_leakage),
        (
            "controller.position.nn_learning_rate",
            ctl.position.nn_learning_rate,
        ),
    ] {
        c.non_negative(name, val, EQ15);
    }
    c.non_negative(
        "controller.position.leader_velocity_damping",
        ctl.position.leader_velocity_damping,
        D11,
    );
    c.non_negative(
        "controller.position.leader_position_gain",
        ctl.position.leader_position_gain,
        D11,
    );
    c.non_negative(
        "controller.position.nn_leader_k_p",
        ctl.position.nn_leader_k_p,
        D23,
    );
    c.non_negative(
        "controller.position.nn_leader_k_v",
        ctl.position.nn_leader_k_v,
        D23,
    );
    c.positive(
        "controller.position.max_horizontal_accel_m_s2",
        ctl.position.max_horizontal_accel_m_s2,
        CTRL,
    );
    c.positive(
        "controller.position.max_up_accel_m_s2",
        ctl.position.max_up_accel_m_s2,
        CTRL,
    );
    if !(ctl.position.max_down_accel_m_s2 > 0.0
        && ctl.position.max_down_accel_m_s2 < sim.gravity_m_s2)
    {
        c.push(
            "controller.position.max_down_accel_m_s2",
            "Remark 3: U_i3P + g > 0",
            format!(
                "must be in (0, g), got {}",
                ctl.position.max_down_accel_m_s2
            ),
        );
    }
    if !(ctl.position.max_tilt_rad > 0.0 && ctl.position.max_tilt_rad < std::f64::consts::FRAC_PI_2)
    {
        c.push(
            "controller.position.max_tilt_rad",
            CTRL,
            format!("must be in (0, pi/2), got {}", ctl.position.max_tilt_rad),
        );
    }
}

/// Checks the RBFNN's size, spread and spans.
fn check_rbfnn(s: &Scenario, c: &mut Collector) {
    let ctl = &s.controller;
    if ctl.rbfnn.neurons_per_axis == 0 || ctl.rbfnn.neurons_per_axis > 64 {
        c.push(
            "controller.rbfnn.neurons_per_axis",
            CTRL,
            format!("must be in 1..=64, got {}", ctl.rbfnn.neurons_per_axis),
        );
    }
    c.positive("controller.rbfnn.spread", ctl.rbfnn.spread, CTRL);
    if let Some(c_p) = ctl.rbfnn.position_norm_sq {
        c.positive("controller.rbfnn.position_norm_sq", c_p, CTRL);
    }
    c.positive(
        "controller.rbfnn.max_weight_norm",
        ctl.rbfnn.max_weight_norm,
        CTRL,
    );
    let nv = ctl.rbfnn.velocity_centres;
    if nv == 0 || !ctl.rbfnn.neurons_per_axis.is_multiple_of(nv.max(1)) {
        c.push(
            "controller.rbfnn.velocity_centres",
            CTRL,
            format!(
                "must be >= 1 and divide neurons_per_axis = {}, got {nv}",
                ctl.rbfnn.neurons_per_axis
            ),
        );
    }
    c.non_negative(
        "controller.rbfnn.initial_weight_amplitude",
        ctl.rbfnn.initial_weight_amplitude,
        CTRL,
    );
    c.positive(
        "controller.rbfnn.position_span_m",
        ctl.rbfnn.position_span_m,
        CTRL,
    );
    c.positive(
        "controller.rbfnn.velocity_span_m_s",
        ctl.rbfnn.velocity_span_m_s,
        CTRL,
    );
}

/// Checks the attitude and rate command filters, and that the step resolves them.
fn check_command_filters(s: &Scenario, c: &mut Collector) {
    let sim = &s.simulation;
    let ctl = &s.controller;
    for (name, f) in [
        (
            "controller.attitude_command_filter",
            &ctl.attitude_command_filter,
        ),
        ("controller.rate_command_filter", &ctl.rate_command_filter),
    ] {
        c.positive(
            &format!("{name}.natural_frequency_rad_s"),
            f.natural_frequency_rad_s,
            CTRL,
        );
        c.positive(&format!("{name}.damping"), f.damping, CTRL);
        if sim.dt_s > 0.0 && f.natural_frequency_rad_s * sim.dt_s > 0.5 {
            c.push(
                format!("{name}.natural_frequency_rad_s"),
                SIM,
                format!(
                    "omega_B dt = {:.3} > 0.5: the filter is not resolved by the step",
                    f.natural_frequency_rad_s * sim.dt_s
                ),
            );
        }
        for k in 0..3 {
            c.positive(
                &format!("{name}.magnitude_limit[{k}]"),
                f.magnitude_limit[k],
                CTRL,
            );
            c.positive(&format!("{name}.rate_limit[{k}]"), f.rate_limit[k], CTRL);
        }
    }
}

/// Checks the attitude loop (BLF-AFTAC).
fn check_attitude(s: &Scenario, c: &mut Collector) {
    let ctl = &s.controller;
    let att = &ctl.attitude;
    c.positive(
        "controller.attitude.k1_alpha",
        att.k1_alpha,
        "eq. (34): K_i1alpha > 2 K_i1C > 0",
    );
    c.positive(
        "controller.attitude.k2_phi",
        att.k2_phi,
        "eq. (45): K_i2Phi > 2 K_i2C > 0",
    );
    c.positive("controller.attitude.eps1_c", att.eps1_c, CTRL);
    c.positive("controller.attitude.eps2_c", att.eps2_c, CTRL);
    if att.k1_alpha > 0.0 && att.eps1_c > 0.0 && !(att.k1_alpha > 2.0 * att.eps1_c.sqrt()) {
        c.push(
            "controller.attitude.k1_alpha",
            "eq. (34): K_i1alpha > 2 K_i1C",
            "K_i1alpha must exceed 2 sqrt(eps1_c)",
        );
    }
    if att.k2_phi > 0.0 && att.eps2_c > 0.0 && !(att.k2_phi > 2.0 * att.eps2_c.sqrt()) {
        c.push(
            "controller.attitude.k2_phi",
            "eq. (45): K_i2Phi > 2 K_i2C",
            "K_i2Phi must exceed 2 sqrt(eps2_c)",
        );
    }
    c.positive("controller.attitude.mu2", att.mu2, CTRL);
    c.positive(
        "controller.attitude.attitude_margin_rad",
        att.attitude_margin_rad,
        A4,
    );
    c.positive(
        "controller.attitude.rate_limit_rad_s",
        att.rate_limit_rad_s,
        A4,
    );
    let alpha_bound = norm3(ctl.rate_command_filter.magnitude_limit);
    if att.rate_limit_rad_s > 0.0 && !(alpha_bound < att.rate_limit_rad_s) {
        c.push(
            "controller.rate_command_filter.magnitude_limit",
            "eq. (40): C_i2 = C-bar_i2 - alpha-bar_i > 0",
            format!(
                "||alpha||max = {alpha_bound:.4} must be below the rate constraint {:.4}",
                att.rate_limit_rad_s
            ),
        );
    }
}

/// Checks the adaptive laws (46)-(49) and the auxiliary systems.
fn check_adaptive_and_auxiliary(s: &Scenario, c: &mut Collector) {
    let ctl = &s.controller;
    let ad = &ctl.adaptive;
    if !(ad.gamma_min > 0.0 && ad.gamma_min <= ad.gamma_max) {
        c.push(
            "controller.adaptive.gamma_min",
            A5,
            format!(
                "need 0 < Gamma_min <= Gamma_max, got [{}, {}]",
                ad.gamma_min, ad.gamma_max
            ),
        );
    }
    for (name, val) in [
        ("controller.adaptive.model_rate", ad.model_rate),
        ("controller.adaptive.model_leakage", ad.model_leakage),
        ("controller.adaptive.delta_rate", ad.delta_rate),
        ("controller.adaptive.delta_leakage", ad.delta_leakage),
        ("controller.adaptive.gamma_rate", ad.gamma_rate),
        ("controller.adaptive.gamma_leakage", ad.gamma_leakage),
        ("controller.adaptive.disturbance_rate", ad.disturbance_rate),
        (
            "controller.adaptive.disturbance_leakage",
            ad.disturbance_leakage,
        ),
    ] {
        c.non_negative(name, val, EQ46_49);
    }
    c.non_negative(
        "controller.adaptive.disturbance_hat_initial",
        ad.disturbance_hat_initial,
        "eq. (49): D-hat_iA estimates a bound on ||D_iA||, so it starts >= 0",
    );
    if !(ad.gamma_hat_initial >= ad.gamma_min && ad.gamma_hat_initial <= ad.gamma_max) {
        c.push(
            "controller.adaptive.gamma_hat_initial",
            A5,
            format!(
                "{} lies outside [Gamma_min, Gamma_max]",
                ad.gamma_hat_initial
            ),
        );
    }
    check_fault_identification(s, c);
    if let Some(g) = ctl.position.nn_leader_gate_m {
        c.non_negative("controller.position.nn_leader_gate_m", g, D23);
    }
    if let Some(l) = ctl.position.nn_leader_drive_limit_m {
        c.positive("controller.position.nn_leader_drive_limit_m", l, D23);
    }
    if let Some(l) = ctl.position.position_error_limit_m {
        c.positive("controller.position.position_error_limit_m", l, CTRL);
    }
    if let Some(a) = ctl.position.startup_blend_accel_m_s2 {
        c.positive("controller.position.startup_blend_accel_m_s2", a, CTRL);
        c.positive(
            "controller.position.startup_blend_jerk_m_s3",
            ctl.position.startup_blend_jerk_m_s3,
            CTRL,
        );
        c.positive(
            "controller.position.startup_blend_rate_1_s",
            ctl.position.startup_blend_rate_1_s,
            CTRL,
        );
    }
    let aux = &ctl.auxiliary;
    for (name, val) in [
        ("controller.auxiliary.k1_e", aux.k1_e),
        ("controller.auxiliary.k2_e", aux.k2_e),
    ] {
        if !(val > 1.0) {
            c.push(name, EQ35_50, format!("must be > 1, got {val}"));
        }
    }
    c.positive("controller.auxiliary.gamma1_e", aux.gamma1_e, EQ35_50);
    c.positive("controller.auxiliary.gamma2_e", aux.gamma2_e, EQ35_50);
    c.positive("controller.auxiliary.e1_threshold", aux.e1_threshold, CTRL);
    c.positive("controller.auxiliary.e2_threshold", aux.e2_threshold, CTRL);
    c.positive(
        "controller.unconstrained.attitude_gain",
        ctl.unconstrained.attitude_gain,
        CTRL,
    );
    c.positive(
        "controller.unconstrained.rate_gain",
        ctl.unconstrained.rate_gain,
        CTRL,
    );
    c.positive(
        "controller.unconstrained.command_rate_limit_rad_s",
        ctl.unconstrained.command_rate_limit_rad_s,
        CTRL,
    );
}

/// The runtime policy: supervision, checkpoints, fallbacks (docs/failures.md).
pub const RUNTIME: &str = "the failure model (docs/failures.md): periods and timeouts are positive, the fallback gains stabilise (> 0)";
/// The fault timeline.
pub const TIMELINE: &str = "the fault timeline (docs/failures.md): an event names existing agents, a graph edge, and happens inside the run";

fn check_runtime(s: &Scenario, c: &mut Collector) {
    let r = &s.runtime;
    c.positive("runtime.checkpoint_every_s", r.checkpoint_every_s, RUNTIME);
    c.non_negative("runtime.hold_s", r.hold_s, RUNTIME);
    c.positive(
        "runtime.fallback_attitude_gain",
        r.fallback_attitude_gain,
        RUNTIME,
    );
    c.positive("runtime.fallback_rate_gain", r.fallback_rate_gain, RUNTIME);
    c.non_negative("runtime.stale_after_s", r.stale_after_s, RUNTIME);
    c.positive(
        "runtime.rejoin_reference_accel_m_s2",
        r.rejoin_reference_accel_m_s2,
        RUNTIME,
    );
    c.positive(
        "runtime.rejoin_reference_rate_1_s",
        r.rejoin_reference_rate_1_s,
        RUNTIME,
    );
    if let Some(g) = r.rejoin_drive_gate_m {
        c.non_negative("runtime.rejoin_drive_gate_m", g, RUNTIME);
    }
}

/// Most events of a timeline (scenario and `--events FILE` together): every process asks the
/// timeline about every step, so its length is paid at every step.
pub const MAX_EVENTS: usize = 1000;

/// Largest |delta_ik| of an actuator fault on axis k, N m: half the torque range of eq. (3), the
/// same limit for a timeline `fault` and a live `formation inject fault`.
pub fn max_fault_delta_nm(s: &Scenario, axis: usize) -> f64 {
    0.5 * (s.vehicle.torque_max_nm[axis] - s.vehicle.torque_min_nm[axis])
}

/// Validates one event against a (valid) scenario: what `formation inject` and `--events FILE`
/// check before an event joins a run's timeline.
pub fn validate_event(
    s: &Scenario,
    path: &str,
    e: &crate::scenario::events::Event,
) -> Result<(), ValidationErrors> {
    let mut c = Collector(Vec::new());
    check_event(s, path, e, &mut c);
    if c.0.is_empty() {
        Ok(())
    } else {
        Err(ValidationErrors(c.0))
    }
}

/// One event of the timeline: the fields its kind needs, in range.
fn check_event(s: &Scenario, path: &str, e: &crate::scenario::events::Event, c: &mut Collector) {
    use crate::scenario::events::EventKind as K;
    if !(e.at_s >= 0.0 && e.at_s < s.simulation.duration_s) {
        c.push(
            format!("{path}.at_s"),
            TIMELINE,
            format!(
                "must be in [0, {}) s (the run), got {}",
                s.simulation.duration_s, e.at_s
            ),
        );
    }
    let ev = EventAt { s, path, e };
    match e.kind {
        K::Fault => ev.check_fault(c),
        K::Delay => ev.check_delay(c),
        K::Crash | K::Hang => ev.check_down(c),
        K::LinkDown | K::LinkUp => ev.check_link(c),
        K::MessageLoss => ev.check_loss(c),
    }
}

/// An event of the timeline being checked: the scenario, its path (`events[k]`) and the event.
struct EventAt<'a> {
    s: &'a Scenario,
    path: &'a str,
    e: &'a crate::scenario::events::Event,
}

impl EventAt<'_> {
    /// Agent id `a` of the event's `field`: 1-based within the formation, present if `required`.
    fn agent_ok(&self, c: &mut Collector, field: &str, a: Option<usize>, required: bool) {
        let (path, n) = (self.path, self.s.n_agents());
        match a {
            Some(a) if a == 0 || a > n => c.push(
                format!("{path}.{field}"),
                TIMELINE,
                format!("agent ids are 1-based, 1..={n}; got {a}"),
            ),
            None if required => c.push(
                format!("{path}.{field}"),
                TIMELINE,
                format!("a `{}` event needs `{field}`", self.e.kind.name()),
            ),
            _ => {}
        }
    }

    /// A `fault` event: its agent, Gamma in (0, 1], |delta| within half the torque range.
    fn check_fault(&self, c: &mut Collector) {
        let (s, path, e) = (self.s, self.path, self.e);
        self.agent_ok(c, "agent", e.agent, true);
        match e.gamma {
            Some(g) => {
                for (k, g) in g.iter().enumerate() {
                    if !(*g > 0.0 && *g <= 1.0) {
                        c.push(
                            format!("{path}.gamma[{k}]"),
                            "eq. (4): Gamma_i in (0, 1] (a partial loss of effectiveness)",
                            format!("must be in (0, 1], got {g}"),
                        );
                    }
                }
            }
            None => c.push(
                format!("{path}.gamma"),
                TIMELINE,
                "a `fault` event needs `gamma`",
            ),
        }
        for (k, d) in e.delta.unwrap_or([0.0; 3]).iter().enumerate() {
            let max = max_fault_delta_nm(s, k);
            if !(d.is_finite() && d.abs() <= max) {
                c.push(
                    format!("{path}.delta[{k}]"),
                    SAT,
                    format!("|delta| must be at most half the torque range ({max} N m), got {d}"),
                );
            }
        }
    }

    /// A `delay` event: its agent, the delay within [0, tau_M], a finite angular rate.
    fn check_delay(&self, c: &mut Collector) {
        let (s, path, e) = (self.s, self.path, self.e);
        self.agent_ok(c, "agent", e.agent, true);
        let tau_m = s.simulation.max_delay_s;
        let base = e.base_s.unwrap_or(f64::NAN);
        let amp = e.amplitude_s.unwrap_or(0.0);
        if !(base >= 0.0 && base + amp.abs() <= tau_m) {
            c.push(
                format!("{path}.base_s"),
                "Assumption 2: 0 <= tau_i(t) <= tau_M",
                format!("base {base} + |amplitude| {amp} must be in [0, tau_M = {tau_m}] s"),
            );
        }
        let rate = e.angular_rate_rad_s.unwrap_or(0.0);
        if !rate.is_finite() {
            c.push(
                format!("{path}.angular_rate_rad_s"),
                A2,
                format!("must be a finite number, got {rate}"),
            );
        }
    }

    /// A `crash` or `hang` event: its agent, down for at least one step and at most the rest of
    /// the run.
    fn check_down(&self, c: &mut Collector) {
        let (s, path, e) = (self.s, self.path, self.e);
        self.agent_ok(c, "agent", e.agent, true);
        // Down at most until the end of the run: a longer window changes nothing the run can
        // show, and it sizes the replay history (docs/failures.md).
        let remaining = s.simulation.duration_s - e.at_s.max(0.0);
        match e.down_s {
            Some(d) if d >= s.simulation.dt_s && d <= remaining.max(s.simulation.dt_s) => {}
            Some(d) if d.is_finite() && d >= s.simulation.dt_s => c.push(
                format!("{path}.down_s"),
                TIMELINE,
                format!(
                    "must be at most the run's remaining time after at_s ({remaining} s), got {d}"
                ),
            ),
            Some(d) => c.push(
                format!("{path}.down_s"),
                TIMELINE,
                format!(
                    "must be a finite time of at least one step ({} s), got {d}",
                    s.simulation.dt_s
                ),
            ),
            None => c.push(
                format!("{path}.down_s"),
                TIMELINE,
                format!("a `{}` event needs `down_s`", e.kind.name()),
            ),
        }
    }

    /// A `link_down` or `link_up` event: two agents joined by an edge of the graph.
    fn check_link(&self, c: &mut Collector) {
        let (s, path, e) = (self.s, self.path, self.e);
        let n = s.n_agents();
        match e.agents {
            Some([a, b]) => {
                self.agent_ok(c, "agents[0]", Some(a), true);
                self.agent_ok(c, "agents[1]", Some(b), true);
                let edge = s
                    .graph
                    .edges
                    .iter()
                    .any(|x| (x.a, x.b) == (a, b) || (x.a, x.b) == (b, a));
                if a != 0 && b != 0 && a <= n && b <= n && !edge {
                    c.push(
                        format!("{path}.agents"),
                        TIMELINE,
                        format!("{a}-{b} is not an edge of the graph"),
                    );
                }
            }
            None => c.push(
                format!("{path}.agents"),
                TIMELINE,
                format!("a `{}` event needs `agents = [i, j]`", e.kind.name()),
            ),
        }
    }

    /// A `message_loss` event: both ends or neither, a probability in [0, 1], a duration > 0.
    fn check_loss(&self, c: &mut Collector) {
        let (path, e) = (self.path, self.e);
        self.agent_ok(c, "from", e.from, false);
        self.agent_ok(c, "to", e.to, false);
        if e.from.is_some() != e.to.is_some() {
            c.push(
                format!("{path}.to"),
                TIMELINE,
                "give both `from` and `to`, or neither (every edge)",
            );
        }
        match e.probability {
            Some(p) if (0.0..=1.0).contains(&p) => {}
            p => c.push(
                format!("{path}.probability"),
                TIMELINE,
                format!("must be in [0, 1], got {p:?}"),
            ),
        }
        if let Some(d) = e.duration_s {
            if !(d.is_finite() && d > 0.0) {
                c.push(
                    format!("{path}.duration_s"),
                    TIMELINE,
                    format!("must be a finite time > 0 s, got {d}"),
                );
            }
        }
    }
}
