//! One plant step with N = 5 (paper scenario): apply the five commands, take the truths, integrate
//! one dt. Near hover (thrust m g, no torque), after 1 s; each iteration steps a fresh clone of the
//! plant (the clone is not timed).

use criterion::{criterion_group, criterion_main, BatchSize, Criterion};
use formation_config::protocol::wire::ControlCommand;
use formation_config::Scenario;
use formation_plant::Plant;
use std::hint::black_box;

fn plant_step(c: &mut Criterion) {
    let s = Scenario::paper();
    let n = s.n_agents();
    let hover = ControlCommand {
        thrust_n: s.vehicle.mass_kg * s.simulation.gravity_m_s2,
        ..Default::default()
    };
    let mut plant = Plant::from_scenario(&s);
    for _ in 0..1000 {
        for i in 0..n {
            plant.apply(i, &hover);
        }
        plant.advance();
    }
    c.bench_function("plant_step (paper, N = 5)", |b| {
        b.iter_batched_ref(
            || plant.clone(),
            |p| {
                for i in 0..n {
                    p.apply(i, black_box(&hover));
                    black_box(p.truth(i));
                }
                p.advance();
            },
            BatchSize::SmallInput,
        )
    });
}

criterion_group!(benches, plant_step);
criterion_main!(benches);
