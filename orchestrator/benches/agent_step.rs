//! `Agent::step` of agent 1 of the paper scenario, in a realistic state: the closed loop (leader,
//! plant, 5 agents, as the in-process runner drives them) is run for 3 s first. Each iteration steps
//! a fresh clone of the agent (the clone is not timed).

use criterion::{criterion_group, criterion_main, BatchSize, Criterion};
use formation_config::{Scenario, Variant};
use formation_runtime::ClosedLoop;
use std::hint::black_box;

/// The closed loop after `steps` steps, with the states of the next one observed.
fn warmed_up(steps: u64) -> ClosedLoop {
    let mut lp = ClosedLoop::new(&Scenario::paper(), Variant::Proposed);
    for _ in 0..steps {
        lp.observe();
        lp.act();
        lp.advance();
    }
    lp.observe();
    lp
}

fn agent_step(c: &mut Criterion) {
    let lp = warmed_up(3000);
    let (agents, states) = (lp.agents(), lp.states());
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
