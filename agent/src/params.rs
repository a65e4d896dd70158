//! Parameters of one agent, taken from the scenario once at construction.

use crate::startup::BlendGains;
use formation_config::scenario::events::RejoinMembers;
use formation_config::scenario::graph::Topology;
use formation_config::scenario::{Controller, DelaySpec, Scenario};
use formation_config::Variant;

/// Everything agent i needs to know that does not change during a run (except the delay profile,
/// which the orchestrator may replace).
#[derive(Debug, Clone)]
pub struct AgentParams {
    /// Agent index i (0-based).
    pub id: usize,
    /// Controller variant.
    pub variant: Variant,
    /// Neighbours j with weights a_ij (0-based, ascending).
    pub neighbours: Vec<(usize, f64)>,
    /// Leader weight b_i.
    pub leader_weight: f64,
    /// This agent receives the leader's data (D17): `leader_broadcast = "all"`, or b_i > 0. Without it
    /// the leader-relative terms (D11) and the feedforward (D4) are dropped.
    pub leader_data: bool,
    /// Step dt, s.
    pub dt: f64,
    /// Delay bound tau_M, s.
    pub max_delay: f64,
    /// Gravity g, m/s².
    pub gravity: f64,
    /// Mass m_i (nominal, known to the controller), kg.
    pub mass: f64,
    /// Inertia diagonal J_i (nominal), kg m².
    pub inertia: [f64; 3],
    /// Rotational drag K_iD (nominal).
    pub drag: [f64; 3],
    /// Torque limits (the controller knows its actuators' ranges), N m.
    pub torque_min: [f64; 3],
    /// Torque limits, N m.
    pub torque_max: [f64; 3],
    /// Initial attitude, rad (the command filter starts there).
    pub initial_attitude: [f64; 3],
    /// Delay profile tau_i(t).
    pub delay: DelaySpec,
    /// All controller gains.
    pub gains: Controller,
    /// A neighbour share older than the delayed step by more than this many steps is not used
    /// (`runtime.stale_after_s`).
    pub stale_steps: u64,
    /// A new or resumed controller re-synchronises its filters to the vehicle before its first
    /// command (`runtime.rejoin_resync`, [`crate::Agent::resync`]).
    pub rejoin_resync: bool,
    /// A new or resumed controller re-seeds its RBFNN to the disturbance the failsafe observed
    /// (`runtime.rejoin_reseed`, [`crate::Agent::reseed`]).
    pub rejoin_reseed: bool,
    /// The gains of the reference generator re-armed for a member that comes back
    /// (`runtime.rejoin_reference`, docs/failures.md); `None`: off.
    pub rejoin_reference: Option<BlendGains>,
    /// In whose controllers it is re-armed (`runtime.rejoin_reference_for`).
    pub rejoin_members: RejoinMembers,
    /// Gate of D23's drive once this controller has come back (`runtime.rejoin_drive_gate_m`, m;
    /// `None`: the start-up gate `nn_leader_gate_m`; 0: held until its re-armed generator is over).
    pub rejoin_drive_gate: Option<f64>,
    /// The separation layer (D25).
    pub separation: crate::separation::SeparationParams,
}

impl AgentParams {
    /// Parameters of agent `id` (0-based) of a validated scenario.
    pub fn from_scenario(s: &Scenario, id: usize, variant: Variant) -> AgentParams {
        let topo = Topology::from_scenario(s);
        AgentParams {
            id,
            variant,
            neighbours: topo.neighbours[id].clone(),
            leader_weight: topo.leader_weights[id],
            leader_data: s.graph.leader_broadcast.reaches(topo.leader_weights[id]),
            dt: s.simulation.dt_s,
            max_delay: s.simulation.max_delay_s,
            gravity: s.simulation.gravity_m_s2,
            mass: s.vehicle.mass_kg,
            inertia: s.vehicle.inertia_kg_m2,
            drag: s.vehicle.rotational_drag,
            torque_min: s.vehicle.torque_min_nm,
            torque_max: s.vehicle.torque_max_nm,
            initial_attitude: s.agents[id].initial_attitude_rad,
            delay: s.agents[id].delay.clone(),
            gains: s.controller.clone(),
            stale_steps: s.runtime.stale_steps(s.simulation.dt_s),
            rejoin_resync: s.runtime.rejoin_resync,
            rejoin_reseed: s.runtime.rejoin_reseed,
            rejoin_reference: s.runtime.rejoin_reference.then_some(BlendGains {
                accel: s.runtime.rejoin_reference_accel_m_s2,
                jerk: f64::INFINITY, // unused: a re-armed generator starts with its limit up
                rate: s.runtime.rejoin_reference_rate_1_s,
            }),
            rejoin_members: s.runtime.rejoin_reference_for,
            rejoin_drive_gate: s.runtime.rejoin_drive_gate_m,
            separation: crate::separation::SeparationParams::new(
                &s.controller.separation,
                s.metrics.safety_distance_m,
                &s.controller.position,
                s.simulation.dt_s,
                s.simulation.gravity_m_s2,
            ),
        }
    }

    /// tau_i(t), s, clamped to [0, tau_M] (Assumption 2).
    pub fn delay_at(&self, t: f64) -> f64 {
        self.delay.tau(t, self.max_delay)
    }
}
