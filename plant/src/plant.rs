//! N quadrotors stepped together: the plant of a run.

use crate::dynamics::{rk4_with, Body, HeldInput, RigidState, TimeTerms};
use crate::fallback::{Airframe, Failsafe, Target};
use crate::faults::{actuate, FaultModel};
use crate::memo::Memo;
use crate::perturbations::uncertainty;
use crate::traffic::{Beacon, Broadcast};
use formation_config::protocol::wire::{
    ControlCommand, FaultInjection, PlantTruth, ReferenceFrame, VehicleState,
};
use formation_config::scenario::events::{Fallback, Runtime};
use formation_config::scenario::{AgentSpec, Scenario};
use formation_leader::Mission;
use nalgebra::Vector3;

/// One quadrotor: its body, its perturbation profiles, its faults, its state and held input.
#[derive(Debug, Clone)]
struct Vehicle {
    spec: AgentSpec,
    faults: FaultModel,
    state: RigidState,
    input: HeldInput,
    gamma: Vector3<f64>,
    delta: Vector3<f64>,
    /// Time-only terms of eq. (2) at the start of the current step (the end of the previous one).
    terms_now: TimeTerms,
    /// F_iP (61) of `state`: the step's truth and the first RK4 stage both need it.
    f_p_now: Vector3<f64>,
    /// The last command its controller sent (held by the fallback while the controller is down).
    last_command: ControlCommand,
    /// True once [`Plant::advance_vehicle`] has integrated this quadrotor over the current step:
    /// `state` and `terms_now` then already belong to step k + 1.
    advanced: bool,
    /// Its position at the start of the current step (what the others' failsafes see of it once
    /// it is integrated).
    p_step: Vector3<f64>,
    /// The onboard failsafe's state while it flies the quadrotor (None: its controller does).
    failsafe: Option<Failsafe>,
    /// Its fallback flew it over the current step (its controller is down): what its broadcast
    /// says at the next step (D25).
    on_fallback: bool,
}

impl Vehicle {
    /// What its position broadcast says of it now (D25).
    fn beacon(&self) -> Beacon {
        Beacon {
            position: self.state.p.into(),
            velocity: self.state.v.into(),
            uncooperative: self.on_fallback,
        }
    }
}

/// The plant: N quadrotors, the step counter and the shared body parameters.
#[derive(Debug, Clone)]
pub struct Plant {
    body: Body,
    dt: f64,
    step: u64,
    vehicles: Vec<Vehicle>,
    /// The mission, whose reference of each step the leader broadcasts to every quadrotor: what
    /// the `slot` failsafe flies (the leader process computes the same frame from it).
    mission: Mission,
    /// Mass properties and input limits: what every input is clamped to (thrust to [0, T_max],
    /// torque by (3)) and what the failsafe flies.
    airframe: Airframe,
    /// The safety distance the failsafe keeps from the other quadrotors, m.
    safety_m: f64,
    /// exp, sin and cos of the time profiles (faults, disturbance, model perturbation) by
    /// argument: what the quadrotors share in a step is evaluated once (`memo`).
    memo: Memo,
    /// The position broadcast the quadrotors receive: what each state message reports of the
    /// others (D25).
    broadcast: Broadcast,
}

impl Plant {
    /// Builds the plant of a (validated) scenario at step 0, every quadrotor at its initial state
    /// with hover thrust held.
    pub fn from_scenario(s: &Scenario) -> Plant {
        let v = &s.vehicle;
        let body = Body {
            mass: v.mass_kg,
            inertia: Vector3::from(v.inertia_kg_m2),
            drag: Vector3::from(v.rotational_drag),
            gravity: s.simulation.gravity_m_s2,
        };
        let vehicles = s
            .agents
            .iter()
            .map(|a| {
                let faults = FaultModel::new(&a.fault);
                let (gamma, delta) = faults.at(0, 0.0);
                let state = RigidState {
                    p: Vector3::from(a.initial_position_m),
                    v: Vector3::zeros(),
                    a: Vector3::from(a.initial_attitude_rad),
                    w: Vector3::zeros(),
                };
                Vehicle {
                    spec: a.clone(),
                    faults,
                    f_p_now: uncertainty(&a.uncertainty, &state.p, &state.v),
                    state,
                    input: HeldInput {
                        thrust: body.mass * body.gravity,
                        torque: Vector3::zeros(),
                    },
                    gamma,
                    delta,
                    terms_now: TimeTerms::at(a, 0.0),
                    last_command: ControlCommand {
                        thrust_n: body.mass * body.gravity,
                        ..ControlCommand::default()
                    },
                    advanced: false,
                    p_step: Vector3::from(a.initial_position_m),
                    failsafe: None,
                    on_fallback: false,
                }
            })
            .collect::<Vec<Vehicle>>();
        let sep = &s.controller.separation;
        let beacons: Vec<Beacon> = vehicles.iter().map(Vehicle::beacon).collect();
        let broadcast = Broadcast::new(
            &beacons,
            sep.sensing_range_m,
            (sep.broadcast_delay_s / s.simulation.dt_s).round() as u64,
            (sep.broadcast_period_s / s.simulation.dt_s).round() as u64,
        );
        Plant {
            dt: s.simulation.dt_s,
            step: 0,
            vehicles,
            mission: Mission::from_scenario(s),
            airframe: Airframe {
                mass: body.mass,
                gravity: body.gravity,
                inertia: body.inertia,
                torque_lo: Vector3::from(v.torque_min_nm),
                torque_hi: Vector3::from(v.torque_max_nm),
                thrust_max: v.thrust_max_n,
            },
            safety_m: s.metrics.safety_distance_m,
            memo: Memo::default(),
            broadcast,
            body,
        }
    }

    /// Number of quadrotors.
    pub fn n(&self) -> usize {
        self.vehicles.len()
    }

    /// Current step k.
    pub fn step_index(&self) -> u64 {
        self.step
    }

    /// Current time t_k = k dt, s.
    pub fn time(&self) -> f64 {
        self.step as f64 * self.dt
    }

    /// The state message of quadrotor `i` at the current step.
    pub fn vehicle_state(&self, i: usize) -> VehicleState {
        let mut s = VehicleState::default();
        self.vehicle_state_into(i, &mut s, true);
        s
    }

    /// How many times the position broadcast's reports were built so far (D25): while it is the
    /// same, every quadrotor's report is the same, bit for bit.
    pub fn traffic_builds(&self) -> u64 {
        self.broadcast.builds()
    }

    /// [`Plant::vehicle_state`] written into `out`, its traffic report only if `traffic` (the
    /// caller keeps the report it copied while [`Plant::traffic_builds`] has not changed).
    pub fn vehicle_state_into(&self, i: usize, out: &mut VehicleState, traffic: bool) {
        debug_assert!(
            !self.vehicles[i].advanced,
            "quadrotor {i} is already at step k + 1"
        );
        let x = &self.vehicles[i].state;
        out.step = self.step;
        out.t = self.time();
        out.agent = i as u32;
        out._pad = 0;
        out.sent_ns = 0;
        out.position = x.p.into();
        out.velocity = x.v.into();
        out.attitude = x.a.into();
        out.rate = x.w.into();
        if traffic {
            out.traffic = self.broadcast.report(i);
        }
    }

    /// The rigid-body state of quadrotor `i`.
    pub fn rigid_state(&self, i: usize) -> &RigidState {
        &self.vehicles[i].state
    }

    /// Sets the inputs of quadrotor `i` for the current step from its command: the thrust is clamped
    /// to [0, T_max], the torque goes through the faults (4) and the saturation (3). Its controller
    /// flies it: the failsafe, if it flew it, lets go.
    pub fn apply(&mut self, i: usize, cmd: &ControlCommand) {
        self.vehicles[i].last_command = *cmd;
        self.vehicles[i].failsafe = None;
        self.vehicles[i].on_fallback = false;
        self.set_input(i, cmd);
    }

    /// Flies quadrotor `i` on its fallback at the current step, its controller down for
    /// `since_steps` steps (`fallback::command`, `rt.fallback`): returns the command applied.
    pub fn apply_fallback(&mut self, i: usize, since_steps: u64, rt: &Runtime) -> ControlCommand {
        let dt = self.dt;
        let step = self.step;
        self.vehicles[i].on_fallback = true;
        let held = crate::fallback::held(rt, since_steps, dt);
        let (target, push) = if held || rt.fallback == Fallback::Hover {
            (None, Vector3::zeros())
        } else {
            (self.slot(i, rt), self.push(i))
        };
        let body = &self.body;
        let frame = &self.airframe;
        let veh = &mut self.vehicles[i];
        let x = veh.state;
        let last = veh.last_command;
        let failsafe = &mut veh.failsafe;
        let cmd =
            crate::fallback::command(rt, &last, since_steps, dt, step, i, || match rt.fallback {
                Fallback::Hover => {
                    let (thrust, torque) = crate::fallback::level_hover(
                        rt,
                        body.mass,
                        body.gravity,
                        &body.inertia,
                        &x,
                    );
                    (thrust, torque, [0.0, 0.0, x.a[2]])
                }
                Fallback::Slot | Fallback::Hold => {
                    let fs = failsafe.get_or_insert_with(|| {
                        Failsafe::take_over(
                            &x,
                            Vector3::from(last.torque_nm),
                            Vector3::from(last.telemetry.f_hat),
                        )
                    });
                    let target = target.unwrap_or(Target {
                        p: fs.hold,
                        v: Vector3::zeros(),
                        a: Vector3::zeros(),
                    });
                    let heading = fs.heading;
                    let (thrust, torque, setpoint) =
                        crate::fallback::fly_to(fs, &target, push, heading, &x, frame, dt);
                    (thrust, torque.into(), setpoint.into())
                }
            });
        self.set_input(i, &cmd);
        cmd
    }

    /// The slot of quadrotor `i` at the current step under `slot` (None: `hold` holds its point):
    /// P_d + Delta_i0 of the leader's reference of the step, with derivatives.
    fn slot(&self, i: usize, rt: &Runtime) -> Option<Target> {
        if rt.fallback != Fallback::Slot || i >= self.mission.n_agents() {
            return None;
        }
        let mut r = ReferenceFrame::default();
        self.mission.reference(self.step, self.time(), &mut r);
        let sum = |a: [f64; 3], b: [f64; 3]| Vector3::from(a) + Vector3::from(b);
        Some(Target {
            p: sum(r.p_d, r.offset[i]),
            v: sum(r.v_d, r.offset_vel[i]),
            a: sum(r.a_d, r.offset_acc[i]),
        })
    }

    /// The failsafe's repulsion of quadrotor `i` from the others at their positions of the current
    /// step (`fallback::repulsion`).
    fn push(&self, i: usize) -> Vector3<f64> {
        let others = self
            .vehicles
            .iter()
            .enumerate()
            .filter(|(j, _)| *j != i)
            .map(|(_, v)| if v.advanced { v.p_step } else { v.state.p });
        crate::fallback::repulsion(&self.vehicles[i].state.p, others, self.safety_m)
    }

    fn set_input(&mut self, i: usize, cmd: &ControlCommand) {
        debug_assert!(
            !self.vehicles[i].advanced,
            "quadrotor {i} is already at step k + 1"
        );
        let t = self.time();
        let step = self.step;
        let veh = &mut self.vehicles[i];
        let (gamma, delta) = veh.faults.at_with(step, t, &mut self.memo);
        veh.gamma = gamma;
        veh.delta = delta;
        let u_ac = Vector3::from(cmd.torque_nm);
        veh.input = HeldInput {
            thrust: cmd.thrust_n.clamp(0.0, self.airframe.thrust_max),
            torque: actuate(
                &u_ac,
                &gamma,
                &delta,
                &self.airframe.torque_lo,
                &self.airframe.torque_hi,
            ),
        };
        if cmd.thrust_n.is_nan() {
            veh.input.thrust = f64::NAN;
        }
    }

    /// What only the plant knows about quadrotor `i` at the current step (after [`Plant::apply`]).
    pub fn truth(&self, i: usize) -> PlantTruth {
        let mut t = PlantTruth::default();
        self.truth_into(i, &mut t, true);
        t
    }

    /// [`Plant::truth`] written into `out`, its state's traffic report only if `traffic` (as in
    /// [`Plant::vehicle_state_into`]).
    pub fn truth_into(&self, i: usize, out: &mut PlantTruth, traffic: bool) {
        let veh = &self.vehicles[i];
        self.vehicle_state_into(i, &mut out.state, traffic);
        out.thrust_n = veh.input.thrust;
        out.torque_applied_nm = veh.input.torque.into();
        out.gamma = veh.gamma.into();
        out.delta = veh.delta.into();
        // F_iP of the state of step k, computed once per state (also RK4's first stage).
        out.uncertainty = veh.f_p_now.into();
        // D_iA(t_k): the start-of-step term RK4 uses, `disturbance(spec, t_k)` computed once.
        out.disturbance = veh.terms_now.disturbance.into();
    }

    /// Integrates quadrotor `i` over [t_k, t_k+1] with its held input, once [`Plant::apply`] and
    /// [`Plant::truth`] of step k are done for it. The quadrotors do not interact, so the plant
    /// process integrates each one as soon as its command is in (only the last one is left when
    /// the last command arrives); k itself advances in [`Plant::advance`]. A second call in the same
    /// step does nothing.
    pub fn advance_vehicle(&mut self, i: usize) {
        let t = self.time();
        let t_next = (self.step + 1) as f64 * self.dt;
        let veh = &mut self.vehicles[i];
        if veh.advanced {
            return;
        }
        let h = t_next - t;
        let terms_mid = TimeTerms::at_with(&veh.spec, t + 0.5 * h, &mut self.memo);
        let terms_next = TimeTerms::at_with(&veh.spec, t_next, &mut self.memo);
        veh.p_step = veh.state.p;
        veh.state = rk4_with(
            &self.body,
            &veh.spec,
            &veh.state,
            &veh.input,
            h,
            [&veh.terms_now, &terms_mid, &terms_next],
            &veh.f_p_now,
        );
        veh.f_p_now = uncertainty(&veh.spec.uncertainty, &veh.state.p, &veh.state.v);
        veh.terms_now = terms_next;
        veh.advanced = true;
    }

    /// Integrates every quadrotor not yet integrated in this step ([`Plant::advance_vehicle`]) over
    /// [t_k, t_k+1] with its held inputs, and advances k.
    pub fn advance(&mut self) {
        for i in 0..self.vehicles.len() {
            self.advance_vehicle(i);
        }
        for veh in &mut self.vehicles {
            veh.advanced = false;
        }
        self.step += 1;
        self.broadcast
            .record(self.step, self.vehicles.iter().map(Vehicle::beacon));
    }

    /// Applies a fault injection (constant override, or back to the profile).
    pub fn inject_fault(&mut self, inj: &FaultInjection) {
        if let Some(veh) = self.vehicles.get_mut(inj.agent as usize) {
            veh.faults.override_from = if inj.mode == 1 {
                Some((inj.step, Vector3::from(inj.gamma), Vector3::from(inj.delta)))
            } else {
                None
            };
        }
    }
}
