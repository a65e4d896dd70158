//! One quadrotor's controller as a message-driven node: it observes messages (its own state, its
//! neighbours' states, the reference frame, delay injections) and, once it holds everything step k
//! needs, computes the command of step k. The process loop and the in-process runner drive it the
//! same way, which is what makes their trajectories bit-identical.

use crate::attitude::AttitudeLoop;
use crate::command_filter::CommandFilter;
use crate::conversion::thrust_and_attitude;
use crate::delay::{delay_steps, StepHistory};
use crate::params::AgentParams;
use crate::position::{clip_norm, consensus_errors, limit, raw_law, LeaderInfo, Member};
use crate::rbfnn::{uniform, Rbfnn};
use crate::startup::{Blend, BlendGains};
use formation_config::protocol::wire::{
    ControlCommand, ControllerTelemetry, DelayInjection, NeighbourState, ReferenceFrame,
    VehicleState, MAX_TRAFFIC,
};
use formation_config::scenario::events::{Change, Event, Timeline};
use formation_config::scenario::{DelaySpec, PositionGains, Scenario};
use formation_config::Variant;
use nalgebra::Vector3;

/// Offset Delta_j0 with its derivatives, as carried by the reference frame.
type Offsets = [[f64; 3]; 3];

/// Own position and velocity at one step.
type Kinematic = ([f64; 3], [f64; 3]);

/// The controller of agent i with its delay buffers.
#[derive(Debug, Clone)]
pub struct Agent {
    p: AgentParams,
    own: StepHistory<Kinematic>,
    neighbours: Vec<StepHistory<Kinematic>>,
    leader: StepHistory<LeaderInfo>,
    /// Index 0: this agent's offsets; then one per neighbour, in `p.neighbours` order.
    offsets: Vec<StepHistory<Offsets>>,
    nn: Rbfnn,
    attitude_filter: CommandFilter,
    attitude: AttitudeLoop,
    /// The fault timeline: which neighbour shares are delivered, the delay changes of this agent.
    timeline: Timeline,
    /// Start-up blends (D19), index 0: this agent's, then one per neighbour; set at the first step.
    startup: Vec<Option<Blend>>,
    startup_set: bool,
    /// Per member (as `startup`): the step it came back at whose re-entry generator is armed
    /// (`runtime.rejoin_reference`; 0: none yet).
    rearmed: Vec<u64>,
    /// Per neighbour (in `p.neighbours` order): the step the plant took it down from after its
    /// process was lost ([`Agent::taken_down`]), if it was.
    lost_from: Vec<Option<u64>>,
    /// How far apart the newest reference frame puts this agent's slot and the slot of each
    /// quadrotor of the last traffic report (agent index, squared distance m²; `u32::MAX`: none): the distance
    /// the separation layer does not fight (D25). Read from each frame for the quadrotors the
    /// last report named, so that a step costs the report's length, not N.
    slot_distances: [(u32, f64); MAX_TRAFFIC],
}

/// Whether the leader-relative RBFNN drive (D23) acts: the agent's own start-up generator (D19)
/// is over (`offset` `None`), or its remaining offset |e| is at or below `gate` (m,
/// `nn_leader_gate_m`; `None`: only once the generator is over).
pub fn drive_gate_open(offset: Option<crate::startup::Slot>, gate: Option<f64>) -> bool {
    match (offset, gate) {
        (None, _) => true,
        (Some(_), None) => false,
        (Some(e), Some(g)) => {
            let [x, y, z] = e[0];
            (x * x + y * y + z * z).sqrt() <= g
        }
    }
}

/// D23's leader-relative drive of the RBFNN update (15) for the leader-relative errors `e` (m)
/// and `e_dot` (m/s): K_LP,nn e + K_LV,nn e', scaled down to the norm K_LP,nn e_D when
/// `nn_leader_drive_limit_m` e_D is set (the drive of a position error of e_D alone).
pub fn leader_drive(e: [f64; 3], e_dot: [f64; 3], pg: &PositionGains) -> [f64; 3] {
    let d = std::array::from_fn(|k| pg.nn_leader_k_p * e[k] + pg.nn_leader_k_v * e_dot[k]);
    match pg.nn_leader_drive_limit_m {
        Some(e_d) => clip_norm(d, pg.nn_leader_k_p.abs() * e_d),
        None => d,
    }
}

/// The share an agent sends its neighbours for its state `s`.
pub fn share_of(s: &VehicleState) -> NeighbourState {
    NeighbourState {
        step: s.step,
        t: s.t,
        agent: s.agent,
        _pad: 0,
        sent_ns: 0,
        position: s.position,
        velocity: s.velocity,
    }
}

impl Agent {
    /// The controller of agent `id` (0-based) of a validated scenario.
    pub fn new(s: &Scenario, id: usize, variant: Variant) -> Agent {
        let mut a = Agent::from_params(AgentParams::from_scenario(s, id, variant));
        a.timeline = s.timeline();
        a
    }

    /// The controller for explicit parameters.
    pub fn from_params(p: AgentParams) -> Agent {
        // Room for tau_M, the staleness window and a few steps of slack: a share the control may
        // still use (at most tau_M + stale_after old) is never overwritten by a newer one.
        let capacity = (p.max_delay / p.dt).ceil() as usize + p.stale_steps as usize + 4;
        let nn_spec = &p.gains.rbfnn;
        let seed = nn_spec.seed.wrapping_add(p.id as u64 * 7919);
        let amp = nn_spec.initial_weight_amplitude;
        let nn = Rbfnn::new(
            nn_spec.neurons_per_axis,
            nn_spec.velocity_centres,
            nn_spec.position_span_m,
            nn_spec.velocity_span_m_s,
            nn_spec.spread,
            nn_spec.position_norm_sq,
            |k, j| amp * uniform(seed, k, j),
        );
        let attitude_filter =
            CommandFilter::new(&p.gains.attitude_command_filter, p.initial_attitude);
        let attitude = AttitudeLoop::new(&p);
        let n_nb = p.neighbours.len();
        Agent {
            own: StepHistory::new(capacity),
            neighbours: (0..n_nb).map(|_| StepHistory::new(capacity)).collect(),
            leader: StepHistory::new(capacity),
            offsets: (0..=n_nb).map(|_| StepHistory::new(capacity)).collect(),
            nn,
            attitude_filter,
            attitude,
            timeline: Timeline::default(),
            startup: vec![None; n_nb + 1],
            startup_set: false,
            rearmed: vec![0; n_nb + 1],
            lost_from: vec![None; n_nb],
            slot_distances: [(u32::MAX, f64::INFINITY); MAX_TRAFFIC],
            p,
        }
    }

    /// Agent index i (0-based).
    pub fn id(&self) -> usize {
        self.p.id
    }

    /// The parameters.
    pub fn params(&self) -> &AgentParams {
        &self.p
    }

    /// Neighbour indices j (0-based) whose [`NeighbourState`] this agent needs.
    pub fn neighbour_ids(&self) -> impl Iterator<Item = usize> + '_ {
        self.p.neighbours.iter().map(|(j, _)| *j)
    }

    /// Records the agent's own state of step k and returns the message to share with its neighbours.
    pub fn observe_own(&mut self, s: &VehicleState) -> NeighbourState {
        self.own.push(s.step, (s.position, s.velocity));
        share_of(s)
    }

    /// Steps of information the delay histories hold.
    pub fn history_capacity(&self) -> usize {
        self.own.capacity()
    }

    /// True when the own state of `step` has been observed (and is still held).
    pub fn has_own(&self, step: u64) -> bool {
        self.own.has(step)
    }

    /// Records a neighbour's shared state. Messages from non-neighbours are ignored, and so are those
    /// the timeline says never arrived (a link down, a lost message, a sender that was down).
    pub fn observe_neighbour(&mut self, m: &NeighbourState) {
        let j = m.agent as usize;
        if let Some(idx) = self.p.neighbours.iter().position(|(n, _)| *n == j) {
            if self.timeline.delivered(j, self.p.id, m.step) {
                self.neighbours[idx].push(m.step, (m.position, m.velocity));
            }
        }
    }

    /// The timeline this agent follows.
    pub fn timeline(&self) -> &Timeline {
        &self.timeline
    }

    /// The timeline, to add the events of a live run (before any process reaches their step).
    pub fn timeline_mut(&mut self) -> &mut Timeline {
        &mut self.timeline
    }

    /// Adds an event of a live run to the timeline (before any process reaches its step).
    pub fn add_event(&mut self, e: &Event) {
        self.timeline.add(e);
    }

    /// Marks agent j down from step `from` (a process that died or hung outside the timeline).
    pub fn set_down(&mut self, j: usize, from: u64) {
        self.timeline.set_down(
            j,
            from,
            formation_config::scenario::events::EventKind::Crash,
        );
    }

    /// Agent j's new process takes over at step `at`.
    pub fn set_up_again(&mut self, j: usize, at: u64) {
        self.timeline.set_up_again(j, at);
    }

    /// The step of the share of neighbour `idx` the control of delayed step `kd` uses: the newest
    /// step in [kd - stale_after, kd] whose share is delivered, or `None` (the edge is dropped from
    /// the consensus terms until fresh data returns).
    fn usable_step(&self, idx: usize, kd: u64) -> Option<u64> {
        if self.timeline.is_empty() {
            return Some(kd);
        }
        let j = self.p.neighbours[idx].0;
        let oldest = kd.saturating_sub(self.p.stale_steps);
        (oldest..=kd)
            .rev()
            .find(|&m| self.timeline.delivered(j, self.p.id, m))
    }

    /// The neighbours whose shares the control of step k uses (the rest are dropped as stale).
    pub fn active_neighbours(&self, step: u64) -> usize {
        let kd = self.delayed_step(step);
        (0..self.neighbours.len())
            .filter(|&idx| self.usable_step(idx, kd).is_some())
            .count()
    }

    /// Records the part of a reference frame this agent needs (P_d and the offsets of itself and its
    /// neighbours).
    pub fn observe_reference(&mut self, r: &ReferenceFrame) {
        self.leader.push(
            r.step,
            LeaderInfo {
                p: r.p_d,
                v: r.v_d,
                a: r.a_d,
            },
        );
        let me = self.p.id;
        let n = r.n_agents as usize;
        // The ids of a report fill the array from the front; u32::MAX ends them.
        for (j, d) in self.slot_distances.iter_mut() {
            if *j == u32::MAX {
                break;
            }
            let k = *j as usize;
            *d = if k < n && me < n {
                let (a, b) = (r.offset[me], r.offset[k]);
                (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)
            } else {
                f64::INFINITY
            };
        }
        self.offsets[0].push(r.step, [r.offset[me], r.offset_vel[me], r.offset_acc[me]]);
        for (idx, (j, _)) in self.p.neighbours.iter().enumerate() {
            self.offsets[idx + 1].push(r.step, [r.offset[*j], r.offset_vel[*j], r.offset_acc[*j]]);
        }
    }

    /// Replaces the delay profile from the injection's step on.
    pub fn set_delay(&mut self, inj: &DelayInjection) {
        if inj.agent as usize == self.p.id {
            self.timeline.push_change(Change::Delay {
                step: inj.step,
                agent: self.p.id,
                base_s: inj.base_s,
                amplitude_s: inj.amplitude_s,
                angular_rate_rad_s: inj.angular_rate_rad_s,
            });
        }
    }

    /// tau_i at step k, s, clamped to [0, tau_M]: the profile of the latest delay change of this
    /// agent at or before k (the last one given wins a tie), else the scenario's.
    pub fn delay_at(&self, step: u64) -> f64 {
        let t = step as f64 * self.p.dt;
        let mut latest: Option<(u64, DelaySpec)> = None;
        for c in self.timeline.changes() {
            if let Change::Delay {
                step: from,
                agent,
                base_s,
                amplitude_s,
                angular_rate_rad_s,
            } = *c
            {
                if agent == self.p.id && from <= step && latest.as_ref().is_none_or(|l| from >= l.0)
                {
                    latest = Some((
                        from,
                        DelaySpec {
                            base_s,
                            amplitude_s,
                            angular_rate_rad_s,
                        },
                    ));
                }
            }
        }
        match latest {
            Some((_, d)) => d.tau(t, self.p.max_delay),
            None => self.p.delay_at(t),
        }
    }

    /// The step k - tau_i(t_k)/dt whose information the control of step k uses.
    pub fn delayed_step(&self, step: u64) -> u64 {
        self.delayed_step_by(step, self.delay_at(step))
    }

    /// [`Agent::delayed_step`] for tau_i(t_k) = `tau` already computed ([`Agent::delay_at`]).
    fn delayed_step_by(&self, step: u64, tau: f64) -> u64 {
        let d = delay_steps(tau, self.p.dt).min(self.own.capacity() as u64 - 2);
        step.saturating_sub(d)
    }

    /// True when everything the control of step k needs has been observed: the own state of k and the
    /// own, neighbour and leader information of the delayed step. A neighbour whose process was
    /// lost and taken down from step f ([`Agent::taken_down`]) is not waited for at steps before
    /// f: its shares of them went out before its commands or were lost with it (a host that dies
    /// or goes silent takes what it had in flight along), and the control uses its newest share
    /// delivered instead.
    pub fn ready(&self, step: u64) -> bool {
        let kd = self.delayed_step(step);
        self.own.has(step)
            && self.own.has(kd)
            && self.leader.has(kd)
            && self.offsets.iter().all(|h| h.has(kd))
            && self.neighbours.iter().enumerate().all(|(idx, h)| {
                self.usable_step(idx, kd)
                    .is_none_or(|m| h.has(m) || self.lost_from[idx].is_some_and(|f| m < f))
            })
    }

    /// Agent `j`'s process was lost and the plant took it down from step `from` (a runtime
    /// `EVENT_DOWN`, never a timeline event: a process killed on the timeline sends its last share
    /// first). Nothing for an agent that is not a neighbour.
    pub fn taken_down(&mut self, j: usize, from: u64) {
        if let Some(idx) = self.p.neighbours.iter().position(|n| n.0 == j) {
            self.lost_from[idx] = Some(from);
        }
    }

    /// The delays the control of step k applies, in steps: `(injected, effective)`. Injected:
    /// k − k_d, tau_i(t_k) on the step grid. Effective: k minus the oldest step of the information
    /// the control uses (its own delayed state, the leader's reference, the share of every
    /// neighbour it keeps), i.e. the age of the information as the histories deliver it: the
    /// injected delay, or more where the information of k_d had not arrived (a late share, a slow
    /// link) and an older one stood in.
    pub fn applied_delay_steps(&self, step: u64) -> (u64, u64) {
        let kd = self.delayed_step(step);
        let mut oldest = self.own.step_at_or_before(kd).unwrap_or(kd);
        if let Some(s) = self.leader.step_at_or_before(kd) {
            oldest = oldest.min(s);
        }
        for (idx, h) in self.neighbours.iter().enumerate() {
            if let Some(s) = self
                .usable_step(idx, kd)
                .and_then(|m| h.step_at_or_before(m))
            {
                oldest = oldest.min(s);
            }
        }
        (step - kd, step.saturating_sub(oldest))
    }

    /// The controller state without its parameters and timeline, serialised (serde + bincode): what
    /// a restarted process restores with [`Agent::restore`].
    pub fn checkpoint(&self) -> Result<Vec<u8>, crate::checkpoint::CheckpointError> {
        crate::checkpoint::encode(&(
            self.p.id as u64,
            &self.own,
            &self.neighbours,
            &self.leader,
            &self.offsets,
            &self.nn,
            &self.attitude_filter,
            &self.attitude,
            &self.startup,
            self.startup_set,
            &self.rearmed,
        ))
    }

    /// Restores a [`Agent::checkpoint`] of this agent into this controller (parameters and
    /// timeline stay as they are).
    pub fn restore(&mut self, bytes: &[u8]) -> Result<(), crate::checkpoint::CheckpointError> {
        type State = (
            u64,
            StepHistory<Kinematic>,
            Vec<StepHistory<Kinematic>>,
            StepHistory<LeaderInfo>,
            Vec<StepHistory<Offsets>>,
            Rbfnn,
            CommandFilter,
            AttitudeLoop,
            Vec<Option<Blend>>,
            bool,
            Vec<u64>,
        );
        let (id, own, neighbours, leader, offsets, nn, filter, attitude, startup, set, rearmed): State =
            crate::checkpoint::decode(bytes)?;
        if id != self.p.id as u64
            || neighbours.len() != self.neighbours.len()
            || rearmed.len() != self.rearmed.len()
            || offsets.len() != self.offsets.len()
            || own.capacity() != self.own.capacity()
        {
            return Err(crate::checkpoint::CheckpointError::Decode(format!(
                "a checkpoint of agent {} with {} neighbours, for agent {} with {}",
                id + 1,
                neighbours.len(),
                self.p.id + 1,
                self.neighbours.len()
            )));
        }
        self.own = own;
        self.neighbours = neighbours;
        self.leader = leader;
        self.offsets = offsets;
        self.nn = nn;
        self.attitude_filter = filter;
        self.attitude = attitude;
        self.startup = startup;
        self.startup_set = set;
        self.rearmed = rearmed;
        Ok(())
    }

    /// Re-synchronises the controller to the vehicle's state `own` before its first command after a
    /// restart or a hang (`docs/failures.md`, bumpless re-entry): command filter 1 at rest at the
    /// current attitude, the rate command filter at the current body rate, the auxiliary systems at
    /// 0, so that z_i1 and z_i2 start at 0 instead of at the distance between the dead process's
    /// filters and a vehicle the failsafe flew. Delay histories, RBFNN weights, adaptive estimates
    /// and the fault identifier are kept.
    pub fn resync(&mut self, own: &VehicleState) {
        self.attitude_filter.reset(own.attitude);
        self.attitude.resync(&Vector3::from(own.rate));
    }

    /// Re-seeds the RBFNN so that F-hat_iP at the quadrotor's position `p` and velocity `v` equals
    /// `observed`, the external acceleration the failsafe observed while this controller was down
    /// (`runtime.rejoin_reseed`, docs/failures.md): the smallest change of the weights, then the
    /// projection of D15. Nothing for the no-RBFNN variant.
    pub fn reseed(&mut self, p: [f64; 3], v: [f64; 3], observed: [f64; 3]) {
        if self.p.variant != Variant::NoRbfnn {
            self.nn.reseed(p, v, observed);
            self.nn.project(self.p.gains.rbfnn.max_weight_norm);
        }
    }

    /// Computes the command of step k from the current attitude and rate in `own` and the delayed
    /// information, then advances the controller's internal states by dt: the reference generators
    /// (D19), the consensus errors (8)-(9), the position law with the RBFNN (11) and its update
    /// (15), the command conversion (28), and the attitude loop on command filter 1.
    pub fn step(&mut self, own: &VehicleState) -> ControlCommand {
        let k = own.step;
        let tau = self.delay_at(k);
        let kd = self.delayed_step_by(k, tau);
        let delayed = self
            .own
            .at_or_before(kd)
            .unwrap_or((own.position, own.velocity));
        let leader = self.leader.at_or_before(kd).unwrap_or_default();
        self.advance_references(k, kd, delayed, &leader);
        let (me, ep, ev) = self.formation_errors(kd, delayed, &leader);
        let law = self.position_law(&me, ep, ev, &leader, own);
        self.learn(&law, &me, &leader, ep, ev);

        // Attitude loop on the filtered command (command filter 1).
        let a_c = Vector3::from(self.attitude_filter.value());
        let a_c_dot = Vector3::from(self.attitude_filter.derivative());
        let a = Vector3::from(own.attitude);
        let w = Vector3::from(own.rate);
        let out = self.attitude.step(&self.p, k, &a, &w, &a_c, &a_c_dot);
        self.attitude_filter.advance(law.attitude_raw, self.p.dt);

        let at = &self.attitude;
        ControlCommand {
            step: k,
            t: own.t,
            agent: self.p.id as u32,
            _pad: 0,
            sent_ns: 0,
            thrust_n: law.thrust,
            torque_nm: out.torque.into(),
            telemetry: ControllerTelemetry {
                tau_s: tau,
                e_p: ep,
                e_v: ev,
                u_p: law.u_p,
                f_hat: law.f_hat,
                nn_weight_norm: if law.use_nn {
                    self.nn.weight_norm()
                } else {
                    0.0
                },
                attitude_cmd_raw: law.attitude_raw,
                attitude_cmd: a_c.into(),
                alpha: out.alpha.into(),
                z1: out.z1.into(),
                z2: out.z2.into(),
                blf1: out.blf1,
                blf2: out.blf2,
                c1: out.c1,
                c2: out.c2,
                gamma_hat: at.gamma_hat.into(),
                delta_hat: at.delta_hat.into(),
                d_hat: at.d_hat,
                model_hat_dev: (at.model_hat - nalgebra::Matrix3::identity()).norm(),
                e1: at.e1.into(),
                e2: at.e2.into(),
                sep_correction: law.sep_correction,
                sep_predicted_m: law.sep_predicted_m,
            },
        }
    }

    /// Advances the start-up reference generators (D19) to delayed step `kd` of step `k`: every
    /// member's from its first shared state, the same on all agents, advanced on the delayed time
    /// axis with the member's delayed slot (`leader`, the offsets). `delayed`: this agent's own
    /// delayed position and velocity, the stand-in for a state not yet known. A member that came
    /// back from a down window gets a fresh one from its state then (re-entry,
    /// `runtime.rejoin_reference`, in the controllers `rejoin_reference_for` names): itself at its
    /// first step back, a neighbour at its first usable share from then on; and a controller that
    /// comes back resumes the generators still running (its neighbours', and its own when it does
    /// not re-arm it; cold, all it knows of) from their states then: it did not advance them while
    /// it was down. One that re-arms its own reference re-arms every neighbour's too, from its
    /// newest usable share, over or not (a cold one resumes them): its own offset starts at zero,
    /// so its consensus errors (8)-(9) must start at zero on the neighbours' side as well, or they
    /// charge it with its neighbours' tracking errors and the RBFNN integrates them
    /// (docs/failures.md, bumpless re-entry).
    fn advance_references(&mut self, k: u64, kd: u64, delayed: Kinematic, leader: &LeaderInfo) {
        let pg = &self.p.gains.position;
        let startup = pg.startup_blend_accel_m_s2.map(|a_s| BlendGains {
            accel: a_s,
            jerk: pg.startup_blend_jerk_m_s3,
            rate: pg.startup_blend_rate_1_s,
        });
        let zero: Offsets = [[0.0; 3]; 3];
        let t_kd = kd as f64 * self.p.dt;
        let mut itself = Reentry::default();
        for m in 0..self.startup.len() {
            let rejoin = self.rejoin_of(m, k, kd, &mut itself);
            let resume = itself.back && (!self.startup_set || self.startup[m].is_some());
            if rejoin.is_none() && !resume && self.startup_set && self.startup[m].is_none() {
                continue; // off, or over: nothing to look up
            }
            let o = self.offsets[m].at_or_before(kd).unwrap_or(zero);
            let s = std::array::from_fn(|d| {
                std::array::from_fn(|k| [leader.p, leader.v, leader.a][d][k] + o[d][k])
            });
            let state_at = |m: usize, step: u64| match m {
                0 => delayed,
                _ => self.neighbours[m - 1].at_or_before(step).unwrap_or(delayed),
            };
            if let Some((gains, seen)) = rejoin {
                let (p, v) = state_at(m, seen);
                self.startup[m] = Blend::resumed(p, v, t_kd, &s, gains);
            } else if resume {
                let (p, v) = state_at(m, kd);
                self.startup[m] = startup.and_then(|g| Blend::resumed(p, v, t_kd, &s, g));
            } else if !self.startup_set {
                let (p, v) = state_at(m, kd);
                self.startup[m] = startup.and_then(|g| Blend::new(p, v, t_kd, &s, g));
            } else if let Some(b) = &mut self.startup[m] {
                if b.advance(t_kd, &s).is_none() {
                    self.startup[m] = None;
                }
            }
        }
        self.startup_set = true;
    }

    /// Whether the reference generator of member `m` (0: this agent, else neighbour m - 1)
    /// re-arms at step `k` (delayed step `kd`): the re-entry gains and the step of the state it
    /// re-arms from, or `None`. Records the member's return in `rearmed`, and this agent's own in
    /// `itself` (member 0 comes first).
    fn rejoin_of(
        &mut self,
        m: usize,
        k: u64,
        kd: u64,
        itself: &mut Reentry,
    ) -> Option<(BlendGains, u64)> {
        let gains = self.p.rejoin_reference?;
        let (j, seen) = match m {
            0 => (self.p.id, Some(k)),
            _ => (self.p.neighbours[m - 1].0, self.usable_step(m - 1, kd)),
        };
        let back = seen.and_then(|s| self.timeline.latest_return(j, self.rearmed[m], s));
        if let (Some(back), Some(seen)) = (back, seen) {
            self.rearmed[m] = back;
            itself.back |= m == 0;
            let members = self.p.rejoin_members;
            let rearm = if m == 0 {
                members.itself()
            } else {
                members.neighbours()
            };
            let rejoin = rearm.then_some((gains, seen));
            itself.rearmed |= m == 0 && rejoin.is_some();
            rejoin
        } else if let (true, Some(seen)) = (m > 0 && itself.rearmed, seen) {
            Some((gains, seen))
        } else {
            None
        }
    }

    /// This agent as a member of the formation at delayed step `kd` (its delayed state `delayed`
    /// and its offsets with the start-up blend) and its consensus errors (8)-(9) against the
    /// neighbours with a usable share and the `leader`.
    fn formation_errors(
        &self,
        kd: u64,
        delayed: Kinematic,
        leader: &LeaderInfo,
    ) -> (Member, [f64; 3], [f64; 3]) {
        let (p_d, v_d) = delayed;
        let zero: Offsets = [[0.0; 3]; 3];
        let blend = |m: usize, o: Offsets| -> Offsets {
            match self.startup[m].and_then(|b| b.offset()) {
                Some(e) => std::array::from_fn(|d| std::array::from_fn(|k| o[d][k] + e[d][k])),
                None => o,
            }
        };
        let off = blend(0, self.offsets[0].at_or_before(kd).unwrap_or(zero));
        let me = Member {
            p: p_d,
            v: v_d,
            off: off[0],
            off_v: off[1],
            off_a: off[2],
        };
        let neighbours = self
            .p
            .neighbours
            .iter()
            .enumerate()
            .filter_map(|(idx, (_, a))| {
                // A neighbour without a usable share (stale beyond stale_after) is dropped.
                let m = self.usable_step(idx, kd)?;
                let (p, v) = self.neighbours[idx].at_or_before(m).unwrap_or(delayed);
                let o = blend(
                    idx + 1,
                    self.offsets[idx + 1].at_or_before(kd).unwrap_or(zero),
                );
                Some((
                    *a,
                    Member {
                        p,
                        v,
                        off: o[0],
                        off_v: o[1],
                        off_a: o[2],
                    },
                ))
            });
        let (ep, ev) = consensus_errors(&me, neighbours, self.p.leader_weight, leader);
        (me, ep, ev)
    }

    /// The position law of `me` for the consensus errors `ep`, `ev`: U_iP with F-hat_iP of the
    /// RBFNN (11), limited (D5), through the separation layer (D25) on the vehicle's current
    /// state `own` and the traffic it reports, converted (28) with psi_iC = 0 into thrust and a
    /// tilt-limited attitude command.
    fn position_law(
        &mut self,
        me: &Member,
        ep: [f64; 3],
        ev: [f64; 3],
        leader: &LeaderInfo,
        own: &VehicleState,
    ) -> Law {
        let g = &self.p.gains;
        let use_nn = self.p.variant != Variant::NoRbfnn;
        let f_hat = if use_nn {
            self.nn.evaluate(me.p, me.v)
        } else {
            [0.0; 3]
        };
        let u_raw = raw_law(&g.position, ep, ev, f_hat, me, leader, self.p.leader_data);
        let u_l = limit(&g.position, self.p.gravity, u_raw);
        let accel = if own.traffic.count > 0 {
            self.acceleration(own)
        } else {
            None
        };
        let sep =
            crate::separation::filter(&self.p.separation, own, accel, &self.slot_distances, u_l);
        // The next frame measures the slots of this report's quadrotors.
        let used = own.traffic.used();
        for (l, slot) in self.slot_distances.iter_mut().enumerate() {
            let id = used.get(l).map_or(u32::MAX, |e| e.agent);
            if slot.0 != id {
                *slot = (id, f64::INFINITY);
            }
        }
        // The layer's U_iS goes through D5's limits again only when it changed U_iP, so that
        // a step it does not act in is bit-identical with the layer off.
        let u_p = if sep.acted {
            limit(&g.position, self.p.gravity, sep.u)
        } else {
            u_l
        };
        let (thrust, mut att_raw) = thrust_and_attitude(u_p, self.p.mass, self.p.gravity, 0.0);
        let tilt = g.position.max_tilt_rad;
        att_raw[0] = att_raw[0].clamp(-tilt, tilt);
        att_raw[1] = att_raw[1].clamp(-tilt, tilt);
        // D15: the position loop's command is not what the vehicle gets while U_iP sits on the
        // acceleration limit of D5 or the attitude command it asks for moves command filter 1 at
        // its rate limit (D14); the error then measures the limits, not what F-hat misses, and
        // the network does not learn from it (conditional integration).
        // The same holds while the separation layer overrides the law (D25): the error then
        // measures the avoidance.
        let saturated = u_l != u_raw || sep.acted || self.attitude_filter.rate_limited(att_raw);
        Law {
            use_nn,
            f_hat,
            u_p,
            thrust,
            attitude_raw: att_raw,
            saturated,
            sep_correction: std::array::from_fn(|k| u_p[k] - u_l[k]),
            sep_predicted_m: sep.predicted_m,
        }
    }

    /// The vehicle's acceleration at the step of `own`, m/s²: its velocity change over the last
    /// [`crate::separation::ACCEL_WINDOW_S`] from its own states (`None` before it has any).
    fn acceleration(&self, own: &VehicleState) -> Option<[f64; 3]> {
        let k = own.step;
        let window = self.p.separation.accel_window_steps;
        let s = self
            .own
            .step_at_or_before(k.saturating_sub(window))
            .filter(|&s| s < k)?;
        let (_, v) = self.own.at_or_before(s)?;
        let span = (k - s) as f64 * self.p.dt;
        Some(std::array::from_fn(|d| (own.velocity[d] - v[d]) / span))
    }

    /// The RBFNN update (15) after the position `law` of `me`: driven by the consensus errors
    /// `ep`, `ev` and, once the start-up is through, the errors against the `leader` (D23); none
    /// without the network or while the law is saturated (D15).
    fn learn(&mut self, law: &Law, me: &Member, leader: &LeaderInfo, ep: [f64; 3], ev: [f64; 3]) {
        let g = &self.p.gains;
        if !law.use_nn || (law.saturated && g.rbfnn.freeze_when_saturated) {
            return;
        }
        let pg = &g.position;
        // The network learns from the same (shaped, D18) position error the law acts on.
        let shaped = pg.position_error_limit_m.unwrap_or(f64::INFINITY);
        let ep_nn = clip_norm(ep, shaped);
        let mut drive: [f64; 3] = std::array::from_fn(|k| pg.nn_k_p * ep_nn[k] + pg.nn_k_v * ev[k]);
        // D23: the leader-relative errors of D11 drive the network too, once this agent's own
        // start-up reference generator (D19) has brought its reference to the slot, or within
        // nn_leader_gate_m of it: the network does not integrate the shaped approach of the
        // start-up.
        // A controller that has come back (rearmed[0] > 0) gates with the re-entry gate if one
        // is set, else with the start-up gate.
        let gate = if self.rearmed[0] > 0 {
            self.p.rejoin_drive_gate.or(pg.nn_leader_gate_m)
        } else {
            pg.nn_leader_gate_m
        };
        let started = drive_gate_open(self.startup[0].and_then(|b| b.offset()), gate);
        if self.p.leader_data && started && (pg.nn_leader_k_p != 0.0 || pg.nn_leader_k_v != 0.0) {
            let lp = clip_norm(
                std::array::from_fn(|k| me.p[k] - leader.p[k] - me.off[k]),
                shaped,
            );
            let lv = std::array::from_fn(|k| me.v[k] - leader.v[k] - me.off_v[k]);
            let lead = leader_drive(lp, lv, pg);
            for (d, l) in drive.iter_mut().zip(lead) {
                *d += l;
            }
        }
        self.nn
            .update(drive, pg.nn_learning_rate, pg.nn_leakage, self.p.dt);
    }
}

/// This agent's return from a down window as its reference generators see it in one step.
#[derive(Debug, Default)]
struct Reentry {
    /// It came back at this step.
    back: bool,
    /// It re-armed its own reference generator at this step.
    rearmed: bool,
}

/// The position loop's output of one step ([`Agent::step`]).
#[derive(Debug)]
struct Law {
    /// The RBFNN is used (every variant but the no-RBFNN one).
    use_nn: bool,
    /// F-hat_iP, m/s² (zero without the RBFNN).
    f_hat: [f64; 3],
    /// U_iP after the acceleration limit of D5, m/s².
    u_p: [f64; 3],
    /// Collective thrust, N.
    thrust: f64,
    /// Attitude command (28), roll and pitch tilt-limited, rad.
    attitude_raw: [f64; 3],
    /// U_iP was limited, the separation layer acted (D25), or the attitude command moves command
    /// filter 1 at its rate limit (D15).
    saturated: bool,
    /// U_iS - U_iP, m/s² (D25; zero while the layer does not act).
    sep_correction: [f64; 3],
    /// The smallest predicted separation this step, m (D25).
    sep_predicted_m: f64,
}

#[cfg(test)]
mod lost_neighbour_tests {
    use super::*;
    use formation_config::protocol::messages::{RuntimeEvent, EVENT_ANY, EVENT_DOWN};

    /// Agent `me` of the paper scenario fed every input of steps 0..=k, less neighbour `j`'s
    /// shares from step `gap` on.
    fn fed(me: usize, j: usize, k: u64, gap: u64) -> Agent {
        let s = Scenario::paper();
        let mut a = Agent::new(&s, me, Variant::Proposed);
        for step in 0..=k {
            a.observe_reference(&ReferenceFrame {
                step,
                n_agents: s.n_agents() as u32,
                ..ReferenceFrame::default()
            });
            a.observe_own(&VehicleState {
                step,
                agent: me as u32,
                ..VehicleState::default()
            });
            for &(n, _) in &a.p.neighbours.clone() {
                if n != j || step < gap {
                    a.observe_neighbour(&share_of(&VehicleState {
                        step,
                        agent: n as u32,
                        ..VehicleState::default()
                    }));
                }
            }
        }
        a
    }

    #[test]
    fn a_neighbour_lost_with_its_host_is_not_waited_for_at_the_steps_before_its_take_down() {
        let (me, j) = (2, 3);
        let mut a = fed(me, j, 200, 150);
        // Taken down from 151: its share of 150 was lost in flight.
        RuntimeEvent {
            step: 151,
            kind: EVENT_DOWN,
            agent: j as u32,
            other: EVENT_ANY,
            ..RuntimeEvent::default()
        }
        .apply(a.timeline_mut());
        assert!(
            a.delayed_step(200) >= 150,
            "the control of 200 needs its share of 150"
        );
        assert!(
            !a.ready(200),
            "the share of 150 is awaited until the take-down is known"
        );
        a.taken_down(j, 151);
        assert!(a.ready(200), "not awaited once its process is known lost");
        a.taken_down(99, 151);
    }
}

#[cfg(test)]
mod rejoin_tests {
    use super::*;
    use formation_config::scenario::events::{Event, EventKind};

    /// Agent 3 (0-based 2) of the paper graph, its neighbours 0.2 m off their slots on x, itself
    /// 0.05 m off, no start-up generator (D19 off: nothing runs before the crash), down from step
    /// 200 to 300. Returns the consensus errors (e_P, e_V) of its first command back.
    fn first_errors_back(
        rejoin_for: formation_config::scenario::events::RejoinMembers,
    ) -> [[f64; 3]; 2] {
        let mut s = Scenario::paper();
        s.controller.position.startup_blend_accel_m_s2 = None;
        s.runtime.rejoin_reference_for = rejoin_for;
        let mut crash = Event::new(0.2, EventKind::Crash);
        crash.agent = Some(3);
        crash.down_s = Some(0.1);
        s.events = vec![crash];
        let me = 2;
        let mut a = Agent::new(&s, me, Variant::Proposed);
        let at = |step: u64, agent: usize, x: f64| VehicleState {
            step,
            agent: agent as u32,
            position: [x, 0.0, 0.0],
            ..VehicleState::default()
        };
        for step in 0..=300 {
            a.observe_reference(&ReferenceFrame {
                step,
                n_agents: s.n_agents() as u32,
                ..ReferenceFrame::default()
            });
            let own = at(step, me, 0.05);
            a.observe_own(&own);
            for &(n, _) in &a.p.neighbours.clone() {
                a.observe_neighbour(&share_of(&at(step, n, 0.2)));
            }
            if !(200..300).contains(&step) {
                let c = a.step(&own);
                if step == 300 {
                    return [c.telemetry.e_p, c.telemetry.e_v];
                }
            }
        }
        unreachable!()
    }

    /// A controller that comes back and re-arms its own reference at the vehicle (its offset from
    /// the slot hidden) re-arms its neighbours' as well, so its first consensus errors are zero;
    /// re-arming only its own would charge it with its two neighbours' 0.2 m (e_P,x = -0.4 m).
    /// When it does not re-arm its own, it sees the true errors, 2 (0.05 - 0.2) = -0.3 m.
    #[test]
    fn a_returning_controller_that_re_arms_itself_starts_from_zero_consensus_errors() {
        use formation_config::scenario::events::RejoinMembers;
        for members in [RejoinMembers::All, RejoinMembers::Itself] {
            let [ep, ev] = first_errors_back(members);
            assert!(
                ep.iter().chain(&ev).all(|e| e.abs() < 1e-12),
                "{members:?}: {ep:?} {ev:?}"
            );
        }
        let [ep, _] = first_errors_back(RejoinMembers::Neighbours);
        assert!((ep[0] + 0.3).abs() < 1e-12, "{ep:?}");
    }
}

#[cfg(test)]
mod tests {
    use super::{drive_gate_open, leader_drive};
    use formation_config::scenario::Scenario;

    /// D23's drive: K_LP,nn e + K_LV,nn e' as it is below the limit, scaled along its own
    /// direction to K_LP,nn e_D above it, untouched without a limit.
    #[test]
    fn the_leader_relative_drive_is_limited_to_that_of_a_position_error_of_e_d() {
        let mut pg = Scenario::paper().controller.position;
        pg.nn_leader_k_p = 0.15;
        pg.nn_leader_k_v = 0.3;
        pg.nn_leader_drive_limit_m = None;
        let small = leader_drive([0.1, 0.0, 0.0], [0.0, 0.05, 0.0], &pg);
        assert_eq!(small, [0.015, 0.015, 0.0]);
        pg.nn_leader_drive_limit_m = Some(0.3);
        assert_eq!(leader_drive([0.1, 0.0, 0.0], [0.0, 0.05, 0.0], &pg), small);
        let big = leader_drive([0.0, 0.0, 0.0], [0.0, -1.0, 0.0], &pg);
        assert!((big[1] + 0.15 * 0.3).abs() < 1e-12 && big[0] == 0.0 && big[2] == 0.0);
    }

    /// D23's gate: open once the generator is over whatever the threshold; while it runs, open only
    /// with a threshold, and then exactly when |e| is at or below it (e' and e'' do not count).
    #[test]
    fn the_leader_relative_drive_opens_within_the_gate_or_once_the_generator_is_over() {
        let at = |e: [f64; 3]| Some([e, [0.3, 0.0, 0.0], [1.0, 0.0, 0.0]]);
        assert!(drive_gate_open(None, None));
        assert!(drive_gate_open(None, Some(0.05)));
        assert!(!drive_gate_open(at([1e-9, 0.0, 0.0]), None));
        assert!(drive_gate_open(at([0.03, 0.04, 0.0]), Some(0.05)));
        assert!(!drive_gate_open(at([0.03, 0.04, 1e-3]), Some(0.05)));
        assert!(!drive_gate_open(at([2.0, 0.0, -5.0]), Some(0.05)));
        assert!(drive_gate_open(at([0.0; 3]), Some(0.0)));
    }
}
