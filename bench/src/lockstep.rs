//! The lockstep case of `formation bench`: the real product, `formation run` in lockstep (plant,
//! leader and N agent processes over iceoryx2, with the paper's control laws), timed by its own
//! orchestrator in steady state (`timing.step_us` of its summary.json), so that its cost per step
//! can be set against the bare fan-out measured in the same bench run.

use super::link::Sizes;
use super::row::Row;
use crate::error::{CaseError, ResultExt};
use formation_runtime::WARMUP_STEPS;
use serde::Serialize;
use serde_json::Value;
use std::ffi::OsString;
use std::path::Path;
use std::process::{Command, Stdio};

/// Expected pace used to size the run to the time budget, agent-steps per wall-clock second: a
/// step costs about the same per agent at any N (the paper scenario, N = 5, runs at ~10-15 k
/// steps/s on a 2-core machine; N = 100 at ~0.5-1 k). A slower machine just takes longer.
const EXPECTED_AGENT_STEPS_PER_S: f64 = 50_000.0;

/// The lockstep run's stall timeout (`--stall-timeout-ms`): a minute without a recorded step.
const BENCH_STALL_TIMEOUT_MS: u64 = 60_000;

/// Runs `formation run` with `n` agents for about `seconds` of steady state (plus the warm-up) in
/// `scratch`, and returns its row. `n = 5` runs the paper scenario; other `n` a generated path
/// scenario (`formation scenario --n N`).
pub fn run(n: usize, seconds: f64, scratch: &Path) -> Result<Row, CaseError> {
    let out = scratch.join(format!("lockstep-n{n}"));
    let _ = std::fs::remove_dir_all(&out);
    std::fs::create_dir_all(&out).map_err(|e| CaseError::file(&out, e))?;
    let mut args: Vec<OsString> = Vec::new();
    if n != 5 {
        let scenario = formation_analysis::scenario_gen::generate(
            &formation_analysis::scenario_gen::GenOptions::new(
                n,
                formation_analysis::scenario_gen::graphs::GraphKind::Path,
            ),
        )
        .map_err(CaseError::below)?;
        let path = out.join("scenario-in.toml");
        let text = toml::to_string(&scenario).ctx("scenario")?;
        std::fs::write(&path, text).map_err(|e| CaseError::file(&path, e))?;
        args.push(path.into());
    }
    // Placed like the fan-out it is set against (`block/pinned/batch`), whatever the load.
    args.extend(["--pin".into(), "always".into()]);
    let steps = WARMUP_STEPS as f64 + seconds * EXPECTED_AGENT_STEPS_PER_S / n as f64;
    let (summary, _) = run_formation(args, steps, &out)?;
    let row = row(n, &summary["timing"]).ok_or_else(|| CaseError::NoTiming {
        what: out.display().to_string(),
    })?;
    let _ = std::fs::remove_dir_all(&out);
    Ok(row)
}

/// Runs `formation run ARGS` in lockstep for about `steps` steps (whole seconds of simulated
/// time at the paper's time step) with its outputs in `out`; returns its summary.json and its
/// stderr.
pub fn run_formation(
    args: Vec<OsString>,
    steps: f64,
    out: &Path,
) -> Result<(Value, String), CaseError> {
    let exe = std::env::current_exe().ctx("cannot locate formation")?;
    let dt = formation_config::Scenario::paper().simulation.dt_s;
    let duration_s = (steps * dt).ceil();
    let output = Command::new(exe)
        .arg("run")
        .args(args)
        .arg("--out")
        .arg(out)
        .arg("--set")
        .arg(format!("simulation.duration_s={duration_s}"))
        // A benchmark on a loaded machine is slow, not hung: the run's stall detector (2 s
        // without a recorded step by default) stopped N = 100 runs at load average 30-50.
        .arg("--stall-timeout-ms")
        .arg(BENCH_STALL_TIMEOUT_MS.to_string())
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .output()
        .ctx("cannot start formation run")?;
    let err = String::from_utf8_lossy(&output.stderr).into_owned();
    if !output.status.success() {
        let last = err.lines().last().unwrap_or("").trim();
        return Err(CaseError::RunFailed {
            status: output.status,
            last: last.to_string(),
        });
    }
    let summary = out.join("summary.json");
    let text = std::fs::read_to_string(&summary).map_err(|e| CaseError::file(&summary, e))?;
    let v: Value = serde_json::from_str(&text).ctx("summary.json")?;
    Ok((v, err))
}

/// The row of a lockstep run from the `timing` object of its summary.json.
fn row(n: usize, timing: &Value) -> Option<Row> {
    // `formation run` in lockstep: blocking waits, pinned (`--pin always`), SCHED_BATCH.
    row_as(("iox2-event", "block/pinned/batch"), n, timing)
}

/// The row of a lockstep run named (transport, wait) from the `timing` object of its
/// summary.json.
pub fn row_as((transport, wait): (&str, &str), n: usize, timing: &Value) -> Option<Row> {
    let s = &timing["step_us"];
    Some(Row {
        transport: transport.into(),
        pattern: "lockstep".into(),
        wait: wait.into(),
        n,
        payload_bytes: Sizes::lockstep_wire().down,
        payload_up_bytes: Sizes::lockstep_wire().up,
        p50_us: s["p50"].as_f64()?,
        p99_us: s["p99"].as_f64()?,
        p999_us: s["p999"].as_f64()?,
        max_us: s["max"].as_f64()?,
        mean_us: s["mean"].as_f64()?,
        samples: s["samples"].as_u64()?,
    })
}

/// The lockstep row set against one bare fan-out row of the same run.
#[derive(Debug, Clone, Serialize)]
pub struct Comparison {
    /// Agents N of both.
    pub n: usize,
    /// Waiting strategy and placement of the fan-out case (`block`, `block/batch`, ...).
    pub fan_out_wait: String,
    /// Median lockstep step, µs.
    pub lockstep_p50_us: f64,
    /// Median fan-out step, µs.
    pub fan_out_p50_us: f64,
    /// `lockstep_p50_us / fan_out_p50_us` (the headline: medians resist the shared machine's
    /// stalls).
    pub ratio: f64,
    /// Same as `ratio` (explicit name).
    pub ratio_p50: f64,
    /// Mean lockstep step, µs.
    pub lockstep_mean_us: f64,
    /// Mean fan-out step, µs.
    pub fan_out_mean_us: f64,
    /// `lockstep_mean_us / fan_out_mean_us`.
    pub ratio_mean: f64,
    /// Rounds the comparison is made of (`formation bench --rounds`). With more than one, every
    /// figure above is the median over the rounds, the ratios of each round taken within it.
    pub rounds: usize,
    /// `ratio_p50` of each round, in order.
    pub ratios: Vec<f64>,
    /// Smallest of `ratios`.
    pub ratio_min: f64,
    /// Largest of `ratios`.
    pub ratio_max: f64,
}

fn round3(x: f64) -> f64 {
    (x * 1000.0).round() / 1000.0
}

/// The lockstep step set against every bare fan-out of the same run that shares its transport
/// (iceoryx2 event), its `n` and its way of waiting (blocking: `block`, `block/batch` and their
/// pinned variants; not spin-then-block, not all-on-one-core), the fastest fan-out (smallest
/// median) first. Empty without a lockstep row or a matching fan-out.
pub fn comparisons(rows: &[Row]) -> Vec<Comparison> {
    let Some(lock) = rows.iter().find(|r| r.pattern == "lockstep") else {
        return Vec::new();
    };
    let mut fans: Vec<&Row> = rows
        .iter()
        .filter(|r| {
            r.pattern == "fan-out"
                && r.transport == lock.transport
                && r.n == lock.n
                && r.wait.starts_with("block")
                && !r.wait.contains("one-core")
                && r.p50_us > 0.0
                && r.mean_us > 0.0
        })
        .collect();
    fans.sort_by(|a, b| a.p50_us.total_cmp(&b.p50_us));
    fans.iter()
        .map(|f| {
            let ratio = round3(lock.p50_us / f.p50_us);
            Comparison {
                n: lock.n,
                fan_out_wait: f.wait.clone(),
                lockstep_p50_us: lock.p50_us,
                fan_out_p50_us: f.p50_us,
                ratio,
                ratio_p50: ratio,
                lockstep_mean_us: lock.mean_us,
                fan_out_mean_us: f.mean_us,
                ratio_mean: round3(lock.mean_us / f.mean_us),
                rounds: 1,
                ratios: vec![ratio],
                ratio_min: ratio,
                ratio_max: ratio,
            }
        })
        .collect()
}

/// The median of `v` (the lower middle one for an even count); 0 when empty.
pub fn median(v: &[f64]) -> f64 {
    let mut v = v.to_vec();
    v.sort_by(f64::total_cmp);
    v.get(v.len().saturating_sub(1) / 2).copied().unwrap_or(0.0)
}

/// [`comparisons`] over several rounds of the same cases (`formation bench --rounds`), each ratio
/// taken within its round, where fan-out and lockstep ran minutes apart at most, so that the
/// shared machine's slow and fast phases cancel; then, per fan-out, the median over the rounds of
/// every figure, the fastest fan-out (smallest median) first. A fan-out missing from a round (a
/// failed case) is compared over the rounds that have it.
pub fn across_rounds(rounds: &[Vec<Row>]) -> Vec<Comparison> {
    let per_round: Vec<Vec<Comparison>> = rounds.iter().map(|r| comparisons(r)).collect();
    let mut waits: Vec<String> = Vec::new();
    for c in per_round.iter().flatten() {
        if !waits.contains(&c.fan_out_wait) {
            waits.push(c.fan_out_wait.clone());
        }
    }
    let mut out: Vec<Comparison> = waits
        .into_iter()
        .map(|wait| {
            let of: Vec<&Comparison> = per_round
                .iter()
                .flatten()
                .filter(|c| c.fan_out_wait == wait)
                .collect();
            let m =
                |f: fn(&Comparison) -> f64| median(&of.iter().map(|c| f(c)).collect::<Vec<_>>());
            let ratios: Vec<f64> = of.iter().map(|c| c.ratio_p50).collect();
            let ratio = m(|c| c.ratio_p50);
            Comparison {
                n: of.first().map_or(0, |c| c.n),
                fan_out_wait: wait,
                lockstep_p50_us: m(|c| c.lockstep_p50_us),
                fan_out_p50_us: m(|c| c.fan_out_p50_us),
                ratio,
                ratio_p50: ratio,
                lockstep_mean_us: m(|c| c.lockstep_mean_us),
                fan_out_mean_us: m(|c| c.fan_out_mean_us),
                ratio_mean: m(|c| c.ratio_mean),
                rounds: of.len(),
                ratio_min: ratios.iter().copied().fold(f64::INFINITY, f64::min),
                ratio_max: ratios.iter().copied().fold(f64::NEG_INFINITY, f64::max),
                ratios,
            }
        })
        .collect();
    out.sort_by(|a, b| a.fan_out_p50_us.total_cmp(&b.fan_out_p50_us));
    out
}

/// [`across_rounds`] for each N of the rounds' lockstep rows, in the order of their first
/// appearance: each round's rows of one N (its fan-outs and its lockstep run) compared within that
/// round.
pub fn across_rounds_per_n(rounds: &[Vec<Row>]) -> Vec<Comparison> {
    let mut ns: Vec<usize> = Vec::new();
    for r in rounds.iter().flatten() {
        if r.pattern == "lockstep" && !ns.contains(&r.n) {
            ns.push(r.n);
        }
    }
    ns.into_iter()
        .flat_map(|n| {
            let of_n: Vec<Vec<Row>> = rounds
                .iter()
                .map(|r| r.iter().filter(|r| r.n == n).cloned().collect())
                .collect();
            across_rounds(&of_n)
        })
        .collect()
}

/// One row per case over several rounds: for each case (transport, pattern, wait, n, in the order
/// of the first round it appears in) the row of the round with its median `p50_us`.
pub fn median_rows(rounds: &[Vec<Row>]) -> Vec<Row> {
    let key = |r: &Row| (r.transport.clone(), r.pattern.clone(), r.wait.clone(), r.n);
    let mut keys = Vec::new();
    for r in rounds.iter().flatten() {
        if !keys.contains(&key(r)) {
            keys.push(key(r));
        }
    }
    keys.iter()
        .filter_map(|k| {
            let mut of: Vec<&Row> = rounds.iter().flatten().filter(|r| key(r) == *k).collect();
            of.sort_by(|a, b| a.p50_us.total_cmp(&b.p50_us));
            of.get(of.len().saturating_sub(1) / 2).map(|r| (*r).clone())
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn lockstep_is_compared_with_every_blocking_fan_out_of_the_same_n_fastest_first() {
        let t = json!({"step_us": {"mean": 90.0, "p50": 88.0, "p99": 120.0, "p999": 150.0,
                                   "max": 400.0, "samples": 5000}});
        let lock = row(5, &t).unwrap();
        let fan = |wait: &str, p50: f64, n: usize| Row {
            pattern: "fan-out".into(),
            wait: wait.into(),
            p50_us: p50,
            mean_us: p50 + 2.0,
            n,
            ..lock.clone()
        };
        let rows = [
            fan("block/one-core", 30.0, 5),
            fan("spin-block", 20.0, 5),
            fan("block/batch", 44.0, 10),
            fan("block", 48.0, 5),
            lock.clone(),
            fan("block/batch", 44.0, 5),
        ];
        let c = comparisons(&rows);
        let waits: Vec<&str> = c.iter().map(|c| c.fan_out_wait.as_str()).collect();
        assert_eq!(waits, ["block/batch", "block"]);
        assert_eq!((c[0].lockstep_p50_us, c[0].fan_out_p50_us), (88.0, 44.0));
        assert_eq!(
            (c[0].ratio, c[0].ratio_p50, c[0].ratio_mean),
            (2.0, 2.0, 1.957)
        );
        assert!(
            comparisons(&rows[..4]).is_empty(),
            "no lockstep row, no comparison"
        );
    }

    #[test]
    fn over_rounds_each_ratio_is_taken_within_its_round_and_the_median_reported() {
        let t = |p50: f64| {
            json!({"step_us": {"mean": p50, "p50": p50, "p99": 120.0,
                                              "p999": 150.0, "max": 400.0, "samples": 5000}})
        };
        let lock = |p50: f64| row(5, &t(p50)).unwrap();
        let fan = |wait: &str, p50: f64| Row {
            pattern: "fan-out".into(),
            wait: wait.into(),
            p50_us: p50,
            mean_us: p50,
            ..lock(p50)
        };
        // A slow round (everything 2x) must not move the ratio; a round without `block` is
        // compared over the rounds that have it.
        let rounds = vec![
            vec![fan("block", 50.0), fan("block/batch", 40.0), lock(60.0)],
            vec![fan("block", 100.0), fan("block/batch", 80.0), lock(120.0)],
            vec![fan("block/batch", 40.0), lock(56.0)],
        ];
        let c = across_rounds(&rounds);
        assert_eq!(c[0].fan_out_wait, "block/batch");
        assert_eq!(c[0].ratios, vec![1.5, 1.5, 1.4]);
        assert_eq!(
            (c[0].ratio, c[0].ratio_min, c[0].ratio_max),
            (1.5, 1.4, 1.5)
        );
        assert_eq!(
            (c[0].rounds, c[0].fan_out_p50_us, c[0].lockstep_p50_us),
            (3, 40.0, 60.0)
        );
        assert_eq!((c[1].fan_out_wait.as_str(), c[1].rounds), ("block", 2));
        assert_eq!(c[1].ratio, 1.2);
        let rows = median_rows(&rounds);
        let waits: Vec<(&str, f64)> = rows.iter().map(|r| (r.wait.as_str(), r.p50_us)).collect();
        assert_eq!(
            waits,
            [
                ("block", 50.0),
                ("block/batch", 40.0),
                ("block/pinned/batch", 60.0)
            ]
        );
    }

    #[test]
    fn several_n_in_one_run_are_compared_each_with_its_own_fan_outs_round_by_round() {
        let t = |p50: f64| {
            json!({"step_us": {"mean": p50, "p50": p50, "p99": 1.0, "p999": 1.0,
                               "max": 1.0, "samples": 5000}})
        };
        let lock = |n: usize, p50: f64| row(n, &t(p50)).unwrap();
        let fan = |n: usize, p50: f64| Row {
            pattern: "fan-out".into(),
            wait: "block".into(),
            ..lock(n, p50)
        };
        let ping = Row {
            pattern: "ping-pong".into(),
            n: 1,
            ..fan(1, 30.0)
        };
        let rounds = vec![
            vec![
                ping.clone(),
                fan(20, 200.0),
                lock(20, 260.0),
                fan(100, 900.0),
                lock(100, 1800.0),
            ],
            vec![
                fan(20, 400.0),
                lock(20, 480.0),
                fan(100, 1000.0),
                lock(100, 1100.0),
            ],
            vec![
                fan(20, 200.0),
                lock(20, 220.0),
                fan(100, 800.0),
                lock(100, 1200.0),
            ],
        ];
        let c = across_rounds_per_n(&rounds);
        let got: Vec<(usize, f64, Vec<f64>)> =
            c.iter().map(|c| (c.n, c.ratio, c.ratios.clone())).collect();
        assert_eq!(
            got,
            [
                (20, 1.2, vec![1.3, 1.2, 1.1]),
                (100, 1.5, vec![2.0, 1.1, 1.5]),
            ]
        );
    }

    #[test]
    fn a_summary_without_step_timing_gives_no_row() {
        assert!(row(5, &json!(null)).is_none());
    }
}
