//! `Agent::step` of agent 1 of the paper scenario, in a realistic state: the closed loop (leader,
//! plant, 5 agents, as the in-process runner drives them) is run for 3 s first. Each iteration steps
//! a fresh clone of the agent (the clone is not timed).

use criterion::{criterion_group, criterion_main, BatchSize, Criterion};
use formation_agent::Agent;
use formation_config::protocol::wire::{NeighborState, ReferenceFrame, VehicleState};
use formation_config::{Scenario, Variant};
use formation_leader::mission::Mission;
use formation_plant::Plant;
use std::hint::black_box;

/// Agents and plant after `steps` closed-loop steps, with the next state of every agent.
fn warmed_up(steps: u64) -> (Vec<Agent>, Vec<VehicleState>) {
    let s = Scenario::paper();
    let n = s.n_agents();
    let dt = s.simulation.dt_s;
    let mut plant = Plant::from_scenario(&s);
    let mission = Mission::from_scenario(&s);
    let mut agents: Vec<Agent> = (0..n)
        .map(|i| Agent::new(&s, i, Variant::Proposed))
        .collect();
    let neighbours: Vec<Vec<usize>> = agents.iter().map(|a| a.neighbour_ids().collect()).collect();
    let mut reference = ReferenceFrame::default();
    let mut states = vec![VehicleState::default(); n];
    let mut shares = vec![NeighborState::default(); n];
    for k in 0..=steps {
        mission.reference(k, k as f64 * dt, &mut reference);
        for a in agents.iter_mut() {
            a.observe_reference(&reference);
        }
        for i in 0..n {
            states[i] = plant.vehicle_state(i);
            shares[i] = agents[i].observe_own(&states[i]);
        }
        for i in 0..n {
            for &j in &neighbours[i] {
                agents[i].observe_neighbor(&shares[j]);
            }
        }
        if k == steps {
            break;
        }
        for i in 0..n {
            let c = agents[i].step(&states[i]);
            plant.apply(i, &c);
        }
        plant.advance();
    }
    (agents, states)
}

fn agent_step(c: &mut Criterion) {
    let (agents, states) = warmed_up(3000);
    c.bench_function("agent_step (paper, agent 1)", |b| {
        b.iter_batched_ref(
            || agents[0].clone(),
            |a| a.step(black_box(&states[0])),
            BatchSize::SmallInput,
        )
    });
}

criterion_group!(benches, agent_step);
criterion_main!(benches);
