//! The recorder's per-step metrics (`record::metrics::Metrics::record`: formation error windows,
//! constraint margins, saturation, finiteness, separation, coverage) on the states of a real run,
//! for the paper scenario (N = 5) and generated rings of N = 20, 100 and 128: in the cover window
//! (every metric, coverage included) and at 5 s (outside it: the errors with their RMS windows,
//! margins, saturation, finiteness and separation); their two geometric parts alone
//! (separation: closest pair of N; coverage: the grid of the target disk against N footprints);
//! the recovery series a step appends (`record::recovery::Series`); and the fault identification
//! of one agent's step (`formation_agent::fault_id::FaultIdentifier`: close the pending sample,
//! the boxcar over one probe period, the identified values).

use criterion::{criterion_group, criterion_main, Criterion};
use formation_agent::fault_id::{FaultIdentifier, NominalBody};
use formation_analysis::scenario_gen::{generate, graphs::GraphKind, GenOptions};
use formation_config::{Scenario, Variant};
use formation_runtime::record::coverage::CoverageGrid;
use formation_runtime::record::metrics::Metrics;
use formation_runtime::record::recovery::Series;
use formation_runtime::record::separation::Separation;
use formation_runtime::ClosedLoop;
use nalgebra::Vector3;
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
        let early = at(&s, 5.0);
        let (r5, truths5, commands5) = (early.reference(), early.truths(), early.commands());
        let mut m5 = Metrics::new(&s);
        c.bench_function(
            &format!("metrics_record outside the cover window ({name})"),
            |b| {
                b.iter(|| {
                    m5.record(
                        early.k(),
                        black_box(r5),
                        black_box(truths5),
                        black_box(commands5),
                    )
                })
            },
        );
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

/// The recovery series of one step (what `Recorder::record` appends for the events' recovery):
/// reset every 60 000 steps, the length of the paper's mission.
fn recovery_series_step(c: &mut Criterion) {
    const STEPS: usize = 60_000;
    let mut series = Series::with_capacity(STEPS, 0.5);
    c.bench_function("recovery series push (one step)", |b| {
        b.iter(|| {
            if series.error.len() == STEPS {
                series = Series::with_capacity(STEPS, 0.5);
            }
            series.push(black_box(0.12), black_box(3));
            series.push_separation(black_box(1.7));
        })
    });
}

/// One agent's fault identification per step, with the probe on and its averages full (the
/// paper scenario's identifier, after two seconds of samples).
fn fault_identification_step(c: &mut Criterion) {
    let s = Scenario::paper();
    let dt = s.simulation.dt_s;
    let mut id = FaultIdentifier::new(&s.controller.fault_identification, dt);
    let body = NominalBody {
        inertia: Vector3::from(s.vehicle.inertia_kg_m2),
        drag: Vector3::from(s.vehicle.rotational_drag),
    };
    let mut k = 0u64;
    let step = |id: &mut FaultIdentifier, k: u64| {
        let unit = id.unit_probe(k);
        let u = Vector3::new(0.01, -0.02, 0.005) + id.probe_of(unit);
        let w = Vector3::new(1e-3 * (k % 7) as f64, 2e-3, -1e-3);
        id.observe(&w, &u, unit, false, &body, dt);
        id.identified()
    };
    while k < 2000 {
        step(&mut id, k);
        k += 1;
    }
    c.bench_function("fault identification (one agent step)", |b| {
        b.iter(|| {
            k += 1;
            step(black_box(&mut id), k)
        })
    });
}

criterion_group!(
    benches,
    metrics_step,
    recovery_series_step,
    fault_identification_step
);
criterion_main!(benches);
