//! The closed loop of a run in one process: leader, plant and N agents stepped in the order the
//! processes of `formation run` follow, passing the same wire messages between the same library
//! calls. `formation sim`, the criterion benches and the tests drive it; a lockstep run across
//! processes produces a bit-identical trajectory.

use formation_agent::Agent;
use formation_config::protocol::wire::{
    ControlCommand, NeighbourState, PlantTruth, ReferenceFrame, VehicleState,
};
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
    dt: f64,
    k: u64,
}

impl ClosedLoop {
    /// The loop of `scenario` with `variant` at step 0.
    pub fn new(scenario: &Scenario, variant: Variant) -> ClosedLoop {
        let n = scenario.n_agents();
        let agents: Vec<Agent> = (0..n).map(|i| Agent::new(scenario, i, variant)).collect();
        let neighbours = agents.iter().map(|a| a.neighbour_ids().collect()).collect();
        ClosedLoop {
            plant: Plant::from_scenario(scenario),
            mission: Mission::from_scenario(scenario),
            agents,
            neighbours,
            reference: ReferenceFrame::default(),
            states: vec![VehicleState::default(); n],
            shares: vec![NeighbourState::default(); n],
            commands: vec![ControlCommand::default(); n],
            truths: vec![PlantTruth::default(); n],
            dt: scenario.simulation.dt_s,
            k: 0,
        }
    }

    /// The information of step k reaches the agents: the leader's reference, each quadrotor's
    /// state, and the neighbours' shares.
    pub fn observe(&mut self) {
        let k = self.k;
        self.mission
            .reference(k, k as f64 * self.dt, &mut self.reference);
        for a in self.agents.iter_mut() {
            a.observe_reference(&self.reference);
        }
        for (i, a) in self.agents.iter_mut().enumerate() {
            self.states[i] = self.plant.vehicle_state(i);
            self.shares[i] = a.observe_own(&self.states[i]);
        }
        for (a, neighbours) in self.agents.iter_mut().zip(&self.neighbours) {
            for &j in neighbours {
                a.observe_neighbour(&self.shares[j]);
            }
        }
    }

    /// Each agent computes its command of step k; the plant applies it (truths of step k).
    pub fn act(&mut self) {
        for (i, a) in self.agents.iter_mut().enumerate() {
            self.commands[i] = a.step(&self.states[i]);
            self.plant.apply(i, &self.commands[i]);
            self.truths[i] = self.plant.truth(i);
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
}
