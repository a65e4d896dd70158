//! One lockstep step of the paper scenario (N = 5) across processes: the real `formation run`
//! (plant, leader, five agents and the recording orchestrator over iceoryx2).
//!
//! Each measurement starts one run of `WARMUP_STEPS + iters` steps and takes the orchestrator's own
//! steady-state timing (`timing.step_us.mean` of its summary.json: wall time per step after the
//! warm-up, process start excluded); the measured time of `iters` steps is that mean times
//! `iters`. Compare with `formation bench --n 5 --transports iox2-event` (bare fan-out) run in the
//! same session: the bench prints the ratio itself.

use criterion::{criterion_group, criterion_main, Criterion};
use std::process::{Command, Stdio};
use std::time::Duration;

/// Steps the orchestrator leaves out before timing (`run::step_timing::WARMUP_STEPS`).
const WARMUP_STEPS: u64 = 1000;
/// Simulation step of the paper scenario, s.
const DT_S: f64 = 0.001;

/// Fewest steady-state steps timed per run: criterion sizes its iteration counts from the wall
/// time of whole runs (process start included), so they are small; each run still times at least
/// this many steps.
const MIN_TIMED_STEPS: u64 = 5000;

/// Runs at least `steps` steady-state steps and returns the mean wall time per step.
fn mean_step(steps: u64, out: &std::path::Path) -> Duration {
    let duration_s = ((WARMUP_STEPS + steps.max(MIN_TIMED_STEPS)) as f64 * DT_S).ceil();
    let status = Command::new(env!("CARGO_BIN_EXE_formation"))
        .args(["run", "--out"])
        .arg(out)
        .args(["--set", &format!("simulation.duration_s={duration_s}")])
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .expect("formation run starts");
    assert!(status.success(), "formation run failed: {status}");
    let text = std::fs::read_to_string(out.join("summary.json")).expect("summary.json");
    let v: serde_json::Value = serde_json::from_str(&text).expect("summary.json parses");
    let mean_us = v["timing"]["step_us"]["mean"]
        .as_f64()
        .expect("lockstep step timing in summary.json");
    Duration::from_secs_f64(mean_us * 1e-6)
}

fn lockstep_step(c: &mut Criterion) {
    let out = std::env::temp_dir().join(format!("formation-lockstep-bench-{}", std::process::id()));
    let mut g = c.benchmark_group("lockstep");
    g.sample_size(10)
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(10));
    g.bench_function("lockstep_step (paper, N = 5, 7 processes)", |b| {
        b.iter_custom(|iters| mean_step(iters, &out).mul_f64(iters as f64))
    });
    g.finish();
    let _ = std::fs::remove_dir_all(&out);
}

criterion_group!(benches, lockstep_step);
criterion_main!(benches);
