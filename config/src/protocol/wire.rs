//! Wire messages: `#[repr(C)]`, zero-copy, explicitly and versionedly named, each stamped with the
//! simulation step and time.
//!
//! The in-process runner passes exactly these structs between the same library calls that the
//! processes make, so that a lockstep run over iceoryx2 and an in-process run produce bit-identical
//! trajectories.
//!
//! Data flow of step k (lockstep):
//! 1. leader  -> agents : [`ReferenceFrame`] for t_k (and plant / orchestrator, for the metrics).
//! 2. plant   -> agent i: [`VehicleState`] of quadrotor i at t_k.
//! 3. agent i -> its neighbours: [`NeighbourState`] (P_i, V_i at t_k), published as soon as step 2 arrives.
//! 4. agent i -> plant  : [`ControlCommand`] for step k, computed from information stamped
//!    t_k - tau_i(t_k) (its own, its neighbours', the leader's) and its current attitude and rate.
//! 5. plant integrates [t_k, t_{k+1}] once all N commands of step k are in, and sends the step's
//!    N [`PlantTruth`]s with the N commands to the recorder (see `runtime::messages::StepEntry`).
//!
//! Injections from the orchestrator: [`FaultInjection`] (-> plant), [`DelayInjection`] (-> agents).

use crate::MAX_AGENTS;
#[cfg(feature = "ipc")]
use iceoryx2::prelude::ZeroCopySend;

/// Most other quadrotors one [`VehicleState`] reports in its [`Traffic`]: the nearest ones within
/// the sensing range (`controller.separation.sensing_range_m`, docs/deviations.md D25).
pub const MAX_TRAFFIC: usize = 8;

/// [`TrafficEntry::flags`]: the quadrotor's controller was down at the measurement (its onboard
/// failsafe flies it): it does not take its share of an avoidance (D25).
pub const TRAFFIC_UNCOOPERATIVE: u32 = 1;

/// One other quadrotor as quadrotor i's position broadcast receiver reports it (D25): its state at
/// the report's measurement step. Single precision, as a broadcast quantises it (1 µm at 15 m).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize, serde::Deserialize)]
#[cfg_attr(
    feature = "ipc",
    derive(ZeroCopySend),
    type_name("formation.v1.TrafficEntry")
)]
pub struct TrafficEntry {
    /// Agent index j (0-based).
    pub agent: u32,
    /// [`TRAFFIC_UNCOOPERATIVE`] or 0.
    pub flags: u32,
    /// Position P_j at the measurement, m.
    pub position: [f32; 3],
    /// Velocity V_j at the measurement, m/s.
    pub velocity: [f32; 3],
}

crate::wire_fields!(TrafficEntry {
    agent: u32 => "-",
    flags: u32 => "-",
    position: [f32; 3] => "m",
    velocity: [f32; 3] => "m/s",
});

/// The other quadrotors within the sensing range of quadrotor i, nearest first (D25).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize, serde::Deserialize)]
#[cfg_attr(
    feature = "ipc",
    derive(ZeroCopySend),
    type_name("formation.v1.Traffic")
)]
pub struct Traffic {
    /// Step of the measurement (at most k; k minus the broadcast delay in steps once past it).
    pub step: u64,
    /// Entries in use, at most [`MAX_TRAFFIC`].
    pub count: u32,
    /// Padding, zero.
    pub _pad: u32,
    /// The entries, `count` of them first, nearest first; the rest zero.
    pub entries: [TrafficEntry; MAX_TRAFFIC],
}

crate::wire_fields!(Traffic {
    step: u64 => "-",
    count: u32 => "-",
    _pad: u32 => "-",
    entries: [TrafficEntry; 8] => "-",
});

impl TrafficEntry {
    /// Position, m, in double precision.
    #[inline]
    pub fn p(&self) -> [f64; 3] {
        self.position.map(f64::from)
    }

    /// Velocity, m/s, in double precision.
    #[inline]
    pub fn v(&self) -> [f64; 3] {
        self.velocity.map(f64::from)
    }
}

impl Traffic {
    /// The entries in use.
    #[inline]
    pub fn used(&self) -> &[TrafficEntry] {
        &self.entries[..(self.count as usize).min(MAX_TRAFFIC)]
    }
}

/// Plant -> agent i: the state of quadrotor i at step k (eq. (1)-(2) states), with the other
/// quadrotors its position broadcast receiver reports (D25).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize, serde::Deserialize)]
#[cfg_attr(
    feature = "ipc",
    derive(ZeroCopySend),
    type_name("formation.v3.VehicleState")
)]
pub struct VehicleState {
    /// Simulation step k.
    pub step: u64,
    /// Simulation time t_k, s.
    pub t: f64,
    /// Agent index i (0-based).
    pub agent: u32,
    /// Padding, zero.
    pub _pad: u32,
    /// CLOCK_MONOTONIC time the sender published this message, ns (realtime runs; 0 in lockstep).
    pub sent_ns: u64,
    /// Position P_i, m (inertial frame).
    pub position: [f64; 3],
    /// Velocity V_i, m/s.
    pub velocity: [f64; 3],
    /// Attitude A_i = [phi, theta, psi], rad.
    pub attitude: [f64; 3],
    /// Body rate Omega_i = [p, q, r], rad/s.
    pub rate: [f64; 3],
    /// The other quadrotors within the sensing range, up to the broadcast delay old (D25).
    pub traffic: Traffic,
}

crate::wire_fields!(VehicleState {
    step: u64 => "-",
    t: f64 => "s",
    agent: u32 => "-",
    _pad: u32 => "-",
    sent_ns: u64 => "ns",
    position: [f64; 3] => "m",
    velocity: [f64; 3] => "m/s",
    attitude: [f64; 3] => "rad",
    rate: [f64; 3] => "rad/s",
    traffic: Traffic => "-",
});

/// Agent i -> neighbours: the information the paper exchanges, (P_i, V_i) at step k.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq)]
#[cfg_attr(
    feature = "ipc",
    derive(ZeroCopySend),
    type_name("formation.v3.NeighbourState")
)]
pub struct NeighbourState {
    /// Simulation step k at which the state was measured.
    pub step: u64,
    /// Simulation time t_k, s.
    pub t: f64,
    /// Sender agent index j (0-based).
    pub agent: u32,
    /// Padding, zero.
    pub _pad: u32,
    /// CLOCK_MONOTONIC time the sender published this message, ns (realtime runs; 0 in lockstep).
    pub sent_ns: u64,
    /// Position P_j, m.
    pub position: [f64; 3],
    /// Velocity V_j, m/s.
    pub velocity: [f64; 3],
}

crate::wire_fields!(NeighbourState {
    step: u64 => "-",
    t: f64 => "s",
    agent: u32 => "-",
    _pad: u32 => "-",
    sent_ns: u64 => "ns",
    position: [f64; 3] => "m",
    velocity: [f64; 3] => "m/s",
});

/// Leader -> agents: virtual leader P_d and the formation offsets Delta_i0 = Lambda_i - Lambda_0 with
/// their first and second derivatives, at step k.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(
    feature = "ipc",
    derive(ZeroCopySend),
    type_name("formation.v1.ReferenceFrame")
)]
pub struct ReferenceFrame {
    /// Simulation step k.
    pub step: u64,
    /// Simulation time t_k, s.
    pub t: f64,
    /// Number of valid entries in the offset arrays.
    pub n_agents: u32,
    /// Padding, zero.
    pub _pad: u32,
    /// Ground target T_g, m.
    pub target: [f64; 3],
    /// Virtual leader P_d, m.
    pub p_d: [f64; 3],
    /// P_d', m/s.
    pub v_d: [f64; 3],
    /// P_d'', m/s².
    pub a_d: [f64; 3],
    /// Delta_i0, m.
    pub offset: [[f64; 3]; MAX_AGENTS],
    /// Delta_i0', m/s.
    pub offset_vel: [[f64; 3]; MAX_AGENTS],
    /// Delta_i0'', m/s².
    pub offset_acc: [[f64; 3]; MAX_AGENTS],
}

crate::wire_fields!(ReferenceFrame {
    step: u64 => "-",
    t: f64 => "s",
    n_agents: u32 => "-",
    _pad: u32 => "-",
    target: [f64; 3] => "m",
    p_d: [f64; 3] => "m",
    v_d: [f64; 3] => "m/s",
    a_d: [f64; 3] => "m/s^2",
    offset: [[f64; 3]; 128] => "m",
    offset_vel: [[f64; 3]; 128] => "m/s",
    offset_acc: [[f64; 3]; 128] => "m/s^2",
});

impl ReferenceFrame {
    /// Copies everything of `src` but the entry arrays; returns its valid entries, at most
    /// `MAX_AGENTS`.
    fn copy_header_from(&mut self, src: &ReferenceFrame) -> usize {
        self.step = src.step;
        self.t = src.t;
        self.n_agents = src.n_agents;
        self._pad = src._pad;
        self.target = src.target;
        self.p_d = src.p_d;
        self.v_d = src.v_d;
        self.a_d = src.a_d;
        (src.n_agents as usize).min(MAX_AGENTS)
    }

    /// Copies `src` into `self` up to its `n_agents` valid entries (the rest of `self` is left as
    /// it was: nobody reads past `n_agents`). A whole frame is ~9.3 kB for `MAX_AGENTS` (128)
    /// entries, the valid part of a 5-agent frame is under 0.5 kB.
    pub fn copy_valid_from(&mut self, src: &ReferenceFrame) {
        let n = self.copy_header_from(src);
        self.offset[..n].copy_from_slice(&src.offset[..n]);
        self.offset_vel[..n].copy_from_slice(&src.offset_vel[..n]);
        self.offset_acc[..n].copy_from_slice(&src.offset_acc[..n]);
    }

    /// Copies the header of `src` and only the entries at `ids` (those below its `n_agents`) into
    /// `self`; every other entry of `self` is left as it was. An agent reads only its own entry and
    /// its neighbours': copying those keeps its per-step copy independent of N (the valid part of
    /// a 128-agent frame is 9.2 kB, 128 agents copying it every step is 1.2 MB per step).
    pub fn copy_entries_from(&mut self, src: &ReferenceFrame, ids: &[usize]) {
        let n = self.copy_header_from(src);
        for &i in ids.iter().filter(|&&i| i < n) {
            self.offset[i] = src.offset[i];
            self.offset_vel[i] = src.offset_vel[i];
            self.offset_acc[i] = src.offset_acc[i];
        }
    }
}

impl Default for ReferenceFrame {
    fn default() -> Self {
        ReferenceFrame {
            step: 0,
            t: 0.0,
            n_agents: 0,
            _pad: 0,
            target: [0.0; 3],
            p_d: [0.0; 3],
            v_d: [0.0; 3],
            a_d: [0.0; 3],
            offset: [[0.0; 3]; MAX_AGENTS],
            offset_vel: [[0.0; 3]; MAX_AGENTS],
            offset_acc: [[0.0; 3]; MAX_AGENTS],
        }
    }
}

/// What the controller computed at step k besides the command (recorded and shown by `inspect`).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq)]
#[cfg_attr(
    feature = "ipc",
    derive(ZeroCopySend),
    type_name("formation.v2.ControllerTelemetry")
)]
pub struct ControllerTelemetry {
    /// Delay tau_i(t_k) the agent applied, s.
    pub tau_s: f64,
    /// Delayed local consensus error e_iP(t - tau_i), eq. (8), m.
    pub e_p: [f64; 3],
    /// Delayed local consensus error e_iV(t - tau_i), eq. (9), m/s.
    pub e_v: [f64; 3],
    /// Position control U_iP after the acceleration limits, eq. (14), m/s².
    pub u_p: [f64; 3],
    /// RBFNN output F-hat_iP = W-hat^T Psi, eq. (11), m/s².
    pub f_hat: [f64; 3],
    /// Frobenius norm of the RBFNN weights.
    pub nn_weight_norm: f64,
    /// Raw attitude command from eq. (28), rad.
    pub attitude_cmd_raw: [f64; 3],
    /// Filtered attitude command A_iC (command filter 1), rad.
    pub attitude_cmd: [f64; 3],
    /// Filtered virtual control alpha_i, rad/s.
    pub alpha: [f64; 3],
    /// Attitude error z_i1 = A_i - A_iC, rad.
    pub z1: [f64; 3],
    /// Rate error z_i2 = Omega_i - alpha_i, rad/s.
    pub z2: [f64; 3],
    /// Barrier value V_i1B, eq. (31).
    pub blf1: f64,
    /// Barrier value V_i2B, eq. (40).
    pub blf2: f64,
    /// Barrier width C_i1, rad.
    pub c1: f64,
    /// Barrier width C_i2, rad/s.
    pub c2: f64,
    /// Gamma-hat_i (diagonal), eq. (48).
    pub gamma_hat: [f64; 3],
    /// delta-hat_i, eq. (47), N m.
    pub delta_hat: [f64; 3],
    /// D-hat_iA, eq. (49), rad/s².
    pub d_hat: f64,
    /// Frobenius norm of Delta F-hat_i - I, eq. (46).
    pub model_hat_dev: f64,
    /// Auxiliary state E_i1, eq. (35).
    pub e1: [f64; 3],
    /// Auxiliary state E_i2, eq. (50).
    pub e2: [f64; 3],
    /// The separation layer's correction U_iS - U_iP of the virtual control (D25), m/s²; zero
    /// while it does not act.
    pub sep_correction: [f64; 3],
    /// The smallest predicted distance to another quadrotor this step (its delayed report carried
    /// forward to t_k, less the prediction's uncertainty), m; infinite with none in the sensing
    /// range (D25).
    pub sep_predicted_m: f64,
}

crate::wire_fields!(ControllerTelemetry {
    tau_s: f64 => "s",
    e_p: [f64; 3] => "m",
    e_v: [f64; 3] => "m/s",
    u_p: [f64; 3] => "m/s^2",
    f_hat: [f64; 3] => "m/s^2",
    nn_weight_norm: f64 => "-",
    attitude_cmd_raw: [f64; 3] => "rad",
    attitude_cmd: [f64; 3] => "rad",
    alpha: [f64; 3] => "rad/s",
    z1: [f64; 3] => "rad",
    z2: [f64; 3] => "rad/s",
    blf1: f64 => "-",
    blf2: f64 => "-",
    c1: f64 => "rad",
    c2: f64 => "rad/s",
    gamma_hat: [f64; 3] => "-",
    delta_hat: [f64; 3] => "N m",
    d_hat: f64 => "rad/s^2",
    model_hat_dev: f64 => "-",
    e1: [f64; 3] => "-",
    e2: [f64; 3] => "-",
    sep_correction: [f64; 3] => "m/s^2",
    sep_predicted_m: f64 => "m",
});

/// Agent i -> plant: total thrust and torque command U_iAC for step k, with the telemetry.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq)]
#[cfg_attr(
    feature = "ipc",
    derive(ZeroCopySend),
    type_name("formation.v3.ControlCommand")
)]
pub struct ControlCommand {
    /// Simulation step k the command is for.
    pub step: u64,
    /// Simulation time t_k, s.
    pub t: f64,
    /// Agent index i (0-based).
    pub agent: u32,
    /// Padding, zero.
    pub _pad: u32,
    /// CLOCK_MONOTONIC time the sender published this message, ns (realtime runs; 0 in lockstep).
    pub sent_ns: u64,
    /// Total thrust T_iC, eq. (28), N.
    pub thrust_n: f64,
    /// Torque command U_iAC, eq. (43), N m (before the actuator faults and saturation).
    pub torque_nm: [f64; 3],
    /// Controller internals at step k.
    pub telemetry: ControllerTelemetry,
}

crate::wire_fields!(ControlCommand {
    step: u64 => "-",
    t: f64 => "s",
    agent: u32 => "-",
    _pad: u32 => "-",
    sent_ns: u64 => "ns",
    thrust_n: f64 => "N",
    torque_nm: [f64; 3] => "N m",
    telemetry: ControllerTelemetry => "-",
});

/// Plant -> recorder: the true quantities of quadrotor i at step k that only the plant knows.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq)]
#[cfg_attr(
    feature = "ipc",
    derive(ZeroCopySend),
    type_name("formation.v3.PlantTruth")
)]
pub struct PlantTruth {
    /// The state at step k.
    pub state: VehicleState,
    /// Thrust applied over [t_k, t_k+1), N.
    pub thrust_n: f64,
    /// Torque U_iA applied over [t_k, t_k+1) after faults (4) and saturation (3), N m.
    pub torque_applied_nm: [f64; 3],
    /// Multiplicative fault Gamma_i(t_k) (diagonal).
    pub gamma: [f64; 3],
    /// Additive fault delta_i(t_k), N m.
    pub delta: [f64; 3],
    /// True lumped uncertainty F_iP(P_i, V_i, t_k), m/s².
    pub uncertainty: [f64; 3],
    /// True attitude disturbance D_iA(t_k), rad/s².
    pub disturbance: [f64; 3],
}

crate::wire_fields!(PlantTruth {
    state: VehicleState => "-",
    thrust_n: f64 => "N",
    torque_applied_nm: [f64; 3] => "N m",
    gamma: [f64; 3] => "-",
    delta: [f64; 3] => "N m",
    uncertainty: [f64; 3] => "m/s^2",
    disturbance: [f64; 3] => "rad/s^2",
});

/// Orchestrator -> plant: actuator fault override of agent i from step `step` on.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq)]
#[cfg_attr(
    feature = "ipc",
    derive(ZeroCopySend),
    type_name("formation.v1.FaultInjection")
)]
pub struct FaultInjection {
    /// First step the new fault applies to.
    pub step: u64,
    /// Time of that step, s.
    pub t: f64,
    /// Agent index i (0-based).
    pub agent: u32,
    /// 1: constant override (gamma, delta); 0: back to the scenario's profile.
    pub mode: u32,
    /// Multiplicative fault Gamma_i (diagonal), in (0, 1].
    pub gamma: [f64; 3],
    /// Additive fault delta_i, N m.
    pub delta: [f64; 3],
}

crate::wire_fields!(FaultInjection {
    step: u64 => "-",
    t: f64 => "s",
    agent: u32 => "-",
    mode: u32 => "-",
    gamma: [f64; 3] => "-",
    delta: [f64; 3] => "N m",
});

impl FaultInjection {
    /// The injection of a timeline's fault change (None for a delay change): what the plant
    /// applies at that step, in `sim` and in `run` alike.
    pub fn of_change(c: &crate::scenario::events::Change, dt: f64) -> Option<FaultInjection> {
        match *c {
            crate::scenario::events::Change::Fault {
                step,
                agent,
                gamma,
                delta,
            } => Some(FaultInjection {
                step,
                t: step as f64 * dt,
                agent: agent as u32,
                mode: 1,
                gamma,
                delta,
            }),
            crate::scenario::events::Change::Delay { .. } => None,
        }
    }
}

/// Orchestrator -> agents: new delay profile of agent i from step `step` on.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq)]
#[cfg_attr(
    feature = "ipc",
    derive(ZeroCopySend),
    type_name("formation.v1.DelayInjection")
)]
pub struct DelayInjection {
    /// First step the new delay applies to.
    pub step: u64,
    /// Time of that step, s.
    pub t: f64,
    /// Agent index i (0-based).
    pub agent: u32,
    /// Padding, zero.
    pub _pad: u32,
    /// tau_i(t) = base + amplitude sin(rate t), s.
    pub base_s: f64,
    /// Amplitude, s.
    pub amplitude_s: f64,
    /// Angular rate, rad/s.
    pub angular_rate_rad_s: f64,
}

crate::wire_fields!(DelayInjection {
    step: u64 => "-",
    t: f64 => "s",
    agent: u32 => "-",
    _pad: u32 => "-",
    base_s: f64 => "s",
    amplitude_s: f64 => "s",
    angular_rate_rad_s: f64 => "rad/s",
});

/// Agent i -> `formation inspect` (service [`crate::protocol::services::telemetry`]): a live sample of the
/// controller, published every [`TELEMETRY_EVERY_S`] of simulation time without waiting for anyone.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq)]
#[cfg_attr(
    feature = "ipc",
    derive(ZeroCopySend),
    type_name("formation.v2.AgentTelemetry")
)]
pub struct AgentTelemetry {
    /// Simulation step k of the sample.
    pub step: u64,
    /// Simulation time t_k, s.
    pub t: f64,
    /// Agent index i (0-based).
    pub agent: u32,
    /// Padding, zero.
    pub _pad: u32,
    /// Formation error |P_i - P_d - Delta_i0| at t_k, m.
    pub formation_error_m: f64,
    /// Attitude A_i = [phi, theta, psi] at t_k, rad.
    pub attitude: [f64; 3],
    /// Body rate Omega_i at t_k, rad/s.
    pub rate: [f64; 3],
    /// Attitude constraint |A_iC| + margin that |A_i| must stay below, rad.
    pub attitude_limit_rad: f64,
    /// Body rate constraint that |Omega_i| must stay below, rad/s.
    pub rate_limit_rad_s: f64,
    /// Wall time of the controller step of this sample (`Agent::step`), µs.
    pub loop_latency_us: f64,
    /// Time the separation layer has changed U_iP since this process started (D25), s.
    pub sep_active_s: f64,
    /// Smallest separation the layer has predicted since this process started, m (infinite:
    /// none in range yet).
    pub sep_min_predicted_m: f64,
    /// The controller's internals at step k.
    pub controller: ControllerTelemetry,
}

crate::wire_fields!(AgentTelemetry {
    step: u64 => "-",
    t: f64 => "s",
    agent: u32 => "-",
    _pad: u32 => "-",
    formation_error_m: f64 => "m",
    attitude: [f64; 3] => "rad",
    rate: [f64; 3] => "rad/s",
    attitude_limit_rad: f64 => "rad",
    rate_limit_rad_s: f64 => "rad/s",
    loop_latency_us: f64 => "us",
    sep_active_s: f64 => "s",
    sep_min_predicted_m: f64 => "m",
    controller: ControllerTelemetry => "-",
});

/// Simulation time between two [`AgentTelemetry`] samples of one agent, s.
pub const TELEMETRY_EVERY_S: f64 = 0.02;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn copying_the_valid_part_of_a_reference_keeps_every_valid_field() {
        let mut src = ReferenceFrame {
            step: 7,
            t: 0.007,
            n_agents: 3,
            target: [1.0, 2.0, 0.0],
            p_d: [3.0, 4.0, 5.0],
            v_d: [0.1, 0.2, 0.3],
            a_d: [-0.1, -0.2, -0.3],
            ..ReferenceFrame::default()
        };
        for i in 0..3 {
            src.offset[i] = [i as f64, 1.0, 2.0];
            src.offset_vel[i] = [0.5 * i as f64, 0.0, 0.0];
            src.offset_acc[i] = [0.0, -(i as f64), 0.0];
        }
        let mut dst = ReferenceFrame::default();
        dst.copy_valid_from(&src);
        assert_eq!(dst, src);
    }
}
