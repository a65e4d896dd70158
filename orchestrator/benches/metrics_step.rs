//! The recorder's per-step metrics (`record::metrics::Metrics::record`: formation error windows,
//! constraint margins, saturation, finiteness, separation, coverage) on the states of a real run
//! in the cover window, for the paper scenario (N = 5) and generated rings of N = 20, 100 and 128;
//! and their two geometric parts alone (separation: closest pair of N; coverage: the grid of the
//! target disk against N footprints).

use criterion::{criterion_group, criterion_main, Criterion};
use formation::record::coverage::CoverageGrid;
use formation::record::metrics::Metrics;
use formation::record::separation::Separation;
use formation::scenario_gen::{generate, graphs::GraphKind, GenOptions};
use formation::ClosedLoop;
use formation_config::{Scenario, Variant};
use std::hint::black_box;

/// The closed loop of `s` run to `t_s` seconds, one step observed and acted (its records ready).
fn at(s: &Scenario, t_s: f64) -> ClosedLoop {
    let mut lp = ClosedLoop::new(s, Variant::Proposed);
    let steps = (t_s / s.simulation.dt_s) as u64;
    for _ in 0..steps {
        lp.observe();
        lp.act();
        lp.advance();
    }
    lp.observe();
    lp.act();
    lp
}

fn scenarios() -> Vec<(String, Scenario)> {
    let mut out = vec![("paper N=5".to_string(), Scenario::paper())];
    for n in [20, 100, 128] {
        let s = generate(&GenOptions::new(n, GraphKind::Ring)).expect("generated scenario");
        out.push((format!("ring N={n}"), s));
    }
    out
}

fn metrics_step(c: &mut Criterion) {
    for (name, s) in scenarios() {
        // 16 s: in the cover window [15, 35] s, where coverage is measured too.
        let lp = at(&s, 16.0);
        let (r, truths, commands) = (lp.reference(), lp.truths(), lp.commands());
        let step = lp.k();
        let mut m = Metrics::new(&s);
        c.bench_function(&format!("metrics_record ({name})"), |b| {
            b.iter(|| m.record(step, black_box(r), black_box(truths), black_box(commands)))
        });
        let positions: Vec<[f64; 3]> = truths.iter().map(|t| t.state.position).collect();
        let mut sep = Separation::with_capacity(s.metrics.safety_distance_m, positions.len());
        c.bench_function(&format!("separation ({name})"), |b| {
            b.iter(|| sep.record(16.0, true, false, black_box(&positions).iter().copied()))
        });
        let mut grid = CoverageGrid::new(s.metrics.target_radius_m, s.metrics.sensor_fov_deg);
        let target = [r.target[0], r.target[1]];
        c.bench_function(&format!("coverage ({name})"), |b| {
            b.iter(|| grid.covered_fraction(black_box(target), positions.iter().copied()))
        });
    }
}

criterion_group!(benches, metrics_step);
criterion_main!(benches);
