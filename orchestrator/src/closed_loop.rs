//! The closed loop of a run in one process: leader, plant and N agents stepped in the order the
//! processes of `formation run` follow, passing the same wire messages between the same library
//! calls. `formation sim`, the criterion benches and the tests drive it; a lockstep run across
//! processes produces a bit-identical trajectory.

use crate::history::History;
use formation_agent::restart::{rebuild, Rejoin, Replayed};
use formation_agent::Agent;
use formation_config::protocol::wire::{
    ControlCommand, FaultInjection, NeighbourState, PlantTruth, ReferenceFrame, VehicleState,
};
use formation_config::scenario::events::{EventKind, RestartState, Runtime, Timeline};
use formation_config::{Scenario, Variant};
use formation_leader::Mission;
use formation_plant::Plant;

/// Leader, plant and agents of one scenario, at step `k`.
pub struct ClosedLoop {
    plant: Plant,
    mission: Mission,
    agents: Vec<Agent>,
    neighbours: Vec<Vec<usize>>,
    reference: ReferenceFrame,
    states: Vec<VehicleState>,
    shares: Vec<NeighbourState>,
    commands: Vec<ControlCommand>,
    truths: Vec<PlantTruth>,
    /// The [`Plant::traffic_builds`] whose reports `states` and `truths` hold (`u64::MAX`: none
    /// yet): a report is copied only when the broadcast has built new ones (D25).
    states_traffic: u64,
    truths_traffic: u64,
    dt: f64,
    k: u64,
    /// The fault timeline (scenario events; the same in every process of a run).
    timeline: Timeline,
    runtime: Runtime,
    /// Scenario and variant, for the fresh controller of a restart.
    scenario: Scenario,
    variant: Variant,
    /// Per agent: the latest checkpoint (step, bytes), kept only when the timeline takes agents down.
    checkpoints: Vec<Option<(u64, Vec<u8>)>>,
    /// Per agent: the step its current controller started at (0, or its last rejoin).
    started: Vec<u64>,
    /// The recorded states and commands of the last steps (a restart rebuilds from them).
    history: History,
    /// What each restart replayed, in order.
    replays: Vec<(usize, u64, Replayed)>,
}

impl ClosedLoop {
    /// The loop of `scenario` with `variant` at step 0.
    pub fn new(scenario: &Scenario, variant: Variant) -> ClosedLoop {
        let n = scenario.n_agents();
        let agents: Vec<Agent> = (0..n).map(|i| Agent::new(scenario, i, variant)).collect();
        let neighbours = agents.iter().map(|a| a.neighbour_ids().collect()).collect();
        let timeline = scenario.timeline();
        let dt = scenario.simulation.dt_s;
        let capacity = agents.first().map_or(0, |a| a.history_capacity());
        let longest = crate::history::longest_down(&timeline, scenario.n_steps());
        let len = if longest == 0 {
            0
        } else {
            crate::history::len(&scenario.runtime, dt, capacity, longest)
        };
        ClosedLoop {
            history: History::new(if len > 0 { n } else { 0 }, len),
            timeline,
            runtime: scenario.runtime.clone(),
            scenario: scenario.clone(),
            variant,
            checkpoints: vec![None; n],
            started: vec![0; n],
            replays: Vec::new(),
            plant: Plant::from_scenario(scenario),
            mission: Mission::from_scenario(scenario),
            agents,
            neighbours,
            reference: ReferenceFrame::default(),
            states: vec![VehicleState::default(); n],
            shares: vec![NeighbourState::default(); n],
            commands: vec![ControlCommand::default(); n],
            truths: vec![PlantTruth::default(); n],
            states_traffic: u64::MAX,
            truths_traffic: u64::MAX,
            dt: scenario.simulation.dt_s,
            k: 0,
        }
    }

    /// The information of step k reaches the agents: the leader's reference, each quadrotor's
    /// state, and the neighbours' shares.
    pub fn observe(&mut self) {
        let k = self.k;
        for c in self.timeline.changes() {
            if let Some(f) = FaultInjection::of_change(c, self.dt).filter(|f| f.step == k) {
                self.plant.inject_fault(&f);
            }
        }
        for i in 0..self.agents.len() {
            if k > 0 && self.timeline.up(i, k) && !self.timeline.up(i, k - 1) {
                self.rejoin(i, k);
            }
        }
        self.mission
            .reference(k, k as f64 * self.dt, &mut self.reference);
        let builds = self.plant.traffic_builds();
        let fresh = builds != self.states_traffic;
        self.states_traffic = builds;
        for (i, a) in self.agents.iter_mut().enumerate() {
            self.plant.vehicle_state_into(i, &mut self.states[i], fresh);
            // A down agent's process observes nothing (it is dead or stopped).
            if self.timeline.up(i, k) {
                a.observe_reference(&self.reference);
                self.shares[i] = a.observe_own(&self.states[i]);
            }
        }
        for (i, (a, neighbours)) in self.agents.iter_mut().zip(&self.neighbours).enumerate() {
            if !self.timeline.up(i, k) {
                continue;
            }
            for &j in neighbours {
                if self.timeline.up(j, k) {
                    a.observe_neighbour(&self.shares[j]);
                }
            }
        }
        if !self.history.is_empty() {
            for (i, st) in self.states.iter().enumerate() {
                self.history.set_state(k, i, *st);
            }
        }
    }

    /// Agent i's new controller takes over at step k: restored from its checkpoint and replayed up
    /// to the step it went down at (warm; a hang always resumes warm), or fresh (cold); its delay
    /// histories refilled from the recorded states (`formation_agent::restart`).
    fn rejoin(&mut self, i: usize, k: u64) {
        let Some(w) = self.timeline.down_window(i, k - 1) else {
            return;
        };
        let warm = w.kind == EventKind::Hang || self.runtime.restart_state == RestartState::Warm;
        let mut fresh = Agent::new(&self.scenario, i, self.variant);
        let checkpoint = match (&self.checkpoints[i], warm) {
            (Some((s, bytes)), true) if fresh.restore(bytes).is_ok() => Some(*s),
            _ => None,
        };
        let plan = Rejoin {
            checkpoint,
            down_from: w.from,
            rejoin_at: k,
            recorded_from: self.history.oldest(),
        };
        let mission = &self.mission;
        let dt = self.dt;
        let h = &self.history;
        let replayed = rebuild(
            &mut fresh,
            &plan,
            |s| {
                let mut r = ReferenceFrame::default();
                mission.reference(s, s as f64 * dt, &mut r);
                r
            },
            |s, j| h.state(s, j),
            |s| h.command(s, i),
        );
        self.replays.push((i, k, replayed));
        self.agents[i] = fresh;
        self.started[i] = k;
    }

    /// What each restart replayed: (agent, rejoin step, replay).
    pub fn replays(&self) -> &[(usize, u64, Replayed)] {
        &self.replays
    }

    /// The fault timeline the loop follows.
    pub fn timeline(&self) -> &Timeline {
        &self.timeline
    }

    /// Each agent computes its command of step k; the plant applies it (truths of step k).
    pub fn act(&mut self) {
        let k = self.k;
        let every = self.runtime.checkpoint_steps(self.dt);
        let builds = self.plant.traffic_builds();
        let fresh = builds != self.truths_traffic;
        self.truths_traffic = builds;
        for (i, a) in self.agents.iter_mut().enumerate() {
            match self.timeline.down_window(i, k) {
                None => {
                    // The agent process checkpoints before the control of every checkpoint step
                    // and of its first step (agent node); only a loop that takes agents down
                    // needs them here.
                    if !self.history.is_empty() && (k.is_multiple_of(every) || k == self.started[i])
                    {
                        if let Ok(bytes) = a.checkpoint() {
                            self.checkpoints[i] = Some((k, bytes));
                        }
                    }
                    self.commands[i] = a.step(&self.states[i]);
                    self.plant.apply(i, &self.commands[i]);
                }
                Some(w) => {
                    self.commands[i] = self.plant.apply_fallback(i, k - w.from, &self.runtime);
                }
            }
            self.plant.truth_into(i, &mut self.truths[i], fresh);
            if !self.history.is_empty() {
                self.history.set_command(
                    k,
                    i,
                    (self.commands[i].thrust_n, self.commands[i].torque_nm),
                );
            }
        }
    }

    /// The plant integrates step k; the loop is at step k + 1.
    pub fn advance(&mut self) {
        self.plant.advance();
        self.k += 1;
    }

    /// The current step k.
    pub fn k(&self) -> u64 {
        self.k
    }

    /// The reference of step k (after [`ClosedLoop::observe`]).
    pub fn reference(&self) -> &ReferenceFrame {
        &self.reference
    }

    /// The states of step k (after [`ClosedLoop::observe`]).
    pub fn states(&self) -> &[VehicleState] {
        &self.states
    }

    /// The commands of step k (after [`ClosedLoop::act`]).
    pub fn commands(&self) -> &[ControlCommand] {
        &self.commands
    }

    /// The plant's truths of step k (after [`ClosedLoop::act`]).
    pub fn truths(&self) -> &[PlantTruth] {
        &self.truths
    }

    /// The agents.
    pub fn agents(&self) -> &[Agent] {
        &self.agents
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn two_loops_of_the_same_scenario_produce_bit_identical_commands() {
        let s = Scenario::paper();
        let mut a = ClosedLoop::new(&s, Variant::Proposed);
        let mut b = ClosedLoop::new(&s, Variant::Proposed);
        for _ in 0..200 {
            a.observe();
            a.act();
            b.observe();
            b.act();
            assert_eq!(a.commands(), b.commands());
            assert_eq!(a.truths(), b.truths());
            a.advance();
            b.advance();
        }
        assert_eq!(a.k(), 200);
    }

    #[test]
    fn after_observe_every_agent_sees_the_state_the_plant_holds_for_it() {
        let s = Scenario::paper();
        let mut l = ClosedLoop::new(&s, Variant::Proposed);
        l.observe();
        l.act();
        l.advance();
        l.observe();
        for (i, st) in l.states().iter().enumerate() {
            assert_eq!(st.step, 1, "agent {}", i + 1);
            assert_eq!(st.agent as usize, i);
        }
        assert_eq!(l.reference().step, 1);
    }

    fn crash_scenario(state: RestartState) -> Scenario {
        let mut s = Scenario::paper();
        s.simulation.duration_s = 4.0;
        s.runtime.restart_state = state;
        let mut e = formation_config::scenario::events::Event::new(2.3, EventKind::Crash);
        e.agent = Some(3);
        e.down_s = Some(0.5);
        s.events.push(e);
        s
    }

    fn run(s: &Scenario) -> ClosedLoop {
        let mut l = ClosedLoop::new(s, Variant::Proposed);
        for _ in 0..s.n_steps() {
            l.observe();
            l.act();
            l.advance();
        }
        l
    }

    #[test]
    fn a_warm_restart_replays_every_command_since_its_checkpoint_exactly() {
        let l = run(&crash_scenario(RestartState::Warm));
        let &(agent, at, r) = l.replays().first().expect("one restart");
        assert_eq!((agent, at), (2, 2800));
        assert_eq!(r.steps, 300, "checkpoint at 2.0 s, down at 2.3 s");
        assert_eq!(r.mismatches, 0);
        assert!(l
            .truths()
            .iter()
            .all(|t| t.state.position.iter().all(|p| p.is_finite())));
    }

    #[test]
    fn while_an_agent_is_down_the_plant_flies_its_fallback_and_a_cold_restart_replays_nothing() {
        let s = crash_scenario(RestartState::Cold);
        let mut l = ClosedLoop::new(&s, Variant::Proposed);
        let mut held = 0;
        let mut last = (0.0, [0.0; 3]);
        for k in 0..s.n_steps() {
            l.observe();
            l.act();
            if k == 2299 {
                last = (l.commands()[2].thrust_n, l.commands()[2].torque_nm);
            }
            if (2300..2500).contains(&k) {
                // Within hold_s the last command of step 2299 is held.
                held += (l.commands()[2].thrust_n == last.0) as usize;
            }
            l.advance();
        }
        assert_eq!(held, 200);
        assert_eq!(l.replays()[0].2.steps, 0);
    }
}
