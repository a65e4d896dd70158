//! Lockstep runs: the wall-clock cost of one simulation step in steady state, measured by the
//! orchestrator from the times at which it records batches of steps, and written to
//! `summary.json` under `timing` (see docs/formats.md).
//!
//! The first [`WARMUP_STEPS`] steps are left out (process start, page faults, caches). A batch of
//! `m` steps recorded `dt` after the previous one contributes `m` samples of `dt / m` to the
//! histogram, so the histogram's mean is exactly the steady-state wall time per step; its
//! quantiles show how even the pace is at the recorder's granularity (a few steps, since the
//! plant runs up to `PLANT_LEAD` steps ahead of the recorder).

use formation_config::node::timing::NsHistogram;
use serde_json::{json, Value};
use std::time::Instant;

/// Steps left out at the start of a run before timing begins.
pub const WARMUP_STEPS: u64 = 1000;

/// Steady-state step timing of a lockstep run.
#[derive(Debug, Default)]
pub struct StepTiming {
    /// Time and recorded-step count of the last batch seen after the warm-up.
    last: Option<(Instant, u64)>,
    /// Time and step count when timing began.
    first: Option<(Instant, u64)>,
    /// Per-step wall time, ns, one sample per step.
    per_step_ns: NsHistogram,
}

impl StepTiming {
    /// Notes that `recorded` steps are recorded at `now`.
    pub fn on_recorded(&mut self, now: Instant, recorded: u64) {
        if recorded < WARMUP_STEPS {
            return;
        }
        match self.last {
            None => {
                self.first = Some((now, recorded));
                self.last = Some((now, recorded));
            }
            Some((t, k)) if recorded > k => {
                let m = recorded - k;
                let per_step = (now.duration_since(t).as_nanos() as u64 / m).max(1);
                self.per_step_ns.record_n(per_step, m);
                self.last = Some((now, recorded));
            }
            Some(_) => {}
        }
    }

    /// The `timing` object of a lockstep `summary.json`, or `None` when the run was too short to
    /// time anything.
    pub fn summary(&self) -> Option<Value> {
        let ((t0, k0), (t1, k1)) = (self.first?, self.last?);
        if k1 <= k0 {
            return None;
        }
        let wall = t1.duration_since(t0).as_secs_f64();
        let mut step_us = super::timing::quantiles(&self.per_step_ns);
        step_us["mean"] = json!((wall * 1e7 / (k1 - k0) as f64).round() / 10.0);
        Some(json!({
            "warmup_steps": WARMUP_STEPS,
            "timed_steps": k1 - k0,
            "steady_steps_per_s": ((k1 - k0) as f64 / wall).round(),
            "step_us": step_us,
        }))
    }
}

/// Prints the `timing` object of a lockstep run on one line.
pub fn print(t: &Value) {
    let v = &t["step_us"];
    let f = |q: &str| v[q].as_f64().map_or("-".to_string(), |x| format!("{x:.1}"));
    println!(
        "lockstep step (steady state, {} steps): mean {} µs, p50 {} µs, p99 {} µs; {} steps/s",
        t["timed_steps"],
        f("mean"),
        f("p50"),
        f("p99"),
        t["steady_steps_per_s"]
    );
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    #[test]
    fn mean_step_time_is_wall_time_over_steps_after_the_warm_up() {
        let mut t = StepTiming::default();
        let t0 = Instant::now();
        // Warm-up batches are ignored, whatever their timing.
        t.on_recorded(t0, 8);
        t.on_recorded(t0 + Duration::from_secs(5), WARMUP_STEPS - 1);
        let start = t0 + Duration::from_secs(10);
        t.on_recorded(start, WARMUP_STEPS);
        // 100 batches of 8 steps, 80 µs per step.
        for b in 1..=100u64 {
            t.on_recorded(start + Duration::from_micros(640 * b), WARMUP_STEPS + 8 * b);
        }
        let s = t.summary().expect("timed");
        assert_eq!(s["timed_steps"], 800);
        assert_eq!(s["step_us"]["mean"], 80.0);
        let p50 = s["step_us"]["p50"].as_f64().unwrap();
        assert!((p50 - 80.0).abs() < 0.2, "{p50}");
    }

    #[test]
    fn a_run_shorter_than_the_warm_up_has_no_step_timing() {
        let mut t = StepTiming::default();
        t.on_recorded(Instant::now(), 10);
        assert!(t.summary().is_none());
    }
}
