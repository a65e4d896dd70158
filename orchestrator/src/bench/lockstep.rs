//! The lockstep case of `formation bench`: the real product, `formation run` in lockstep (plant,
//! leader and N agent processes over iceoryx2, with the paper's control laws), timed by its own
//! orchestrator in steady state (`timing.step_us` of its summary.json), so that its cost per step
//! can be set against the bare fan-out measured in the same bench run.

use super::report::Row;
use crate::run::step_timing::WARMUP_STEPS;
use formation_config::wire::ControlCommand;
use serde_json::Value;
use std::path::Path;
use std::process::{Command, Stdio};

/// Expected pace used to size the run to the time budget, steps per wall-clock second (the paper
/// scenario runs at ~10-12 k steps/s on a 2-core machine; a slower machine just takes longer).
const EXPECTED_STEPS_PER_S: f64 = 10_000.0;

/// Runs `formation run` with `n` agents for about `seconds` of steady state (plus the warm-up) in
/// `scratch`, and returns its row. `n = 5` runs the paper scenario; other `n` a generated path
/// scenario (`formation scenario --n N`).
pub fn run(n: usize, seconds: f64, scratch: &Path) -> Result<Row, String> {
    let exe = std::env::current_exe().map_err(|e| format!("cannot locate formation: {e}"))?;
    let out = scratch.join(format!("lockstep-n{n}"));
    let _ = std::fs::remove_dir_all(&out);
    std::fs::create_dir_all(&out).map_err(|e| format!("{}: {e}", out.display()))?;
    let mut cmd = Command::new(exe);
    cmd.arg("run");
    if n != 5 {
        let scenario = crate::scenario_gen::generate(n, "path")?;
        let path = out.join("scenario-in.toml");
        let text = toml::to_string(&scenario).map_err(|e| format!("scenario: {e}"))?;
        std::fs::write(&path, text).map_err(|e| format!("{}: {e}", path.display()))?;
        cmd.arg(&path);
    }
    let dt = formation_config::Scenario::paper().simulation.dt_s;
    let steps = WARMUP_STEPS as f64 + seconds * EXPECTED_STEPS_PER_S;
    let duration_s = (steps * dt).ceil();
    cmd.arg("--out")
        .arg(&out)
        .arg("--set")
        .arg(format!("simulation.duration_s={duration_s}"))
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped());
    let output = cmd
        .output()
        .map_err(|e| format!("cannot start formation run: {e}"))?;
    if !output.status.success() {
        let err = String::from_utf8_lossy(&output.stderr);
        let last = err.lines().last().unwrap_or("").trim();
        return Err(format!("formation run failed ({}): {last}", output.status));
    }
    let summary = out.join("summary.json");
    let text =
        std::fs::read_to_string(&summary).map_err(|e| format!("{}: {e}", summary.display()))?;
    let v: Value = serde_json::from_str(&text).map_err(|e| format!("summary.json: {e}"))?;
    let row = row(n, &v["timing"])
        .ok_or_else(|| format!("{} has no lockstep step timing", summary.display()))?;
    let _ = std::fs::remove_dir_all(&out);
    Ok(row)
}

/// The row of a lockstep run from the `timing` object of its summary.json.
fn row(n: usize, timing: &Value) -> Option<Row> {
    let s = &timing["step_us"];
    Some(Row {
        transport: "iox2-event".into(),
        pattern: "lockstep".into(),
        wait: "block/batch".into(),
        n,
        payload_bytes: std::mem::size_of::<ControlCommand>(),
        p50_us: s["p50"].as_f64()?,
        p99_us: s["p99"].as_f64()?,
        p999_us: s["p999"].as_f64()?,
        max_us: s["max"].as_f64()?,
        mean_us: s["mean"].as_f64()?,
        samples: s["samples"].as_u64()?,
    })
}

/// Lockstep step cost over the bare fan-out's measured in the same run, with the same transport,
/// waiting and scheduling (iceoryx2 event, blocking, unpinned, `SCHED_BATCH` as `formation run`
/// uses in lockstep) and the same `n`: `(lockstep mean µs, fan-out mean µs, ratio)`.
pub fn ratio(rows: &[Row]) -> Option<(f64, f64, f64)> {
    let lock = rows.iter().find(|r| r.pattern == "lockstep")?;
    let fan = rows.iter().find(|r| {
        r.pattern == "fan-out"
            && r.transport == lock.transport
            && r.wait == lock.wait
            && r.n == lock.n
    })?;
    (fan.mean_us > 0.0).then(|| (lock.mean_us, fan.mean_us, lock.mean_us / fan.mean_us))
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn ratio_compares_lockstep_with_the_blocking_fan_out_of_the_same_n() {
        let t = json!({"step_us": {"mean": 90.0, "p50": 88.0, "p99": 120.0, "p999": 150.0,
                                   "max": 400.0, "samples": 5000}});
        let lock = row(5, &t).unwrap();
        let mut fan = lock.clone();
        fan.pattern = "fan-out".into();
        fan.mean_us = 60.0;
        let mut pinned = fan.clone();
        pinned.wait = "block/one-core".into();
        pinned.mean_us = 30.0;
        let mut other_policy = fan.clone();
        other_policy.wait = "block".into();
        other_policy.mean_us = 45.0;
        let (l, f, r) = ratio(&[pinned, other_policy, lock, fan]).unwrap();
        assert_eq!((l, f), (90.0, 60.0));
        assert!((r - 1.5).abs() < 1e-12);
    }

    #[test]
    fn a_summary_without_step_timing_gives_no_row() {
        assert!(row(5, &json!(null)).is_none());
    }
}
