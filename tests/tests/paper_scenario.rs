//! End-to-end: the real `formation sim` binary on the embedded scenarios meets the numbers the
//! control-core issue promises (measured on every step, from summary.json).

use formation_tests::{bin, temp_dir};
use serde_json::Value;
use std::process::Command;

/// Runs `formation sim <args>`, expecting exit code 0 (completed) or 3 (diverged, outputs written)
/// as `diverges` says; returns summary.json.
fn sim_expecting(args: &[&str], tag: &str, diverges: bool) -> Value {
    let out = temp_dir(tag);
    let o = Command::new(bin("formation"))
        .arg("sim")
        .args(args)
        .arg("--out")
        .arg(&out)
        .output()
        .expect("formation runs");
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(
        o.status.code(),
        Some(if diverges { 3 } else { 0 }),
        "formation sim {args:?}: {stderr}"
    );
    assert!(!stderr.contains("panicked"), "{stderr}");
    let text = std::fs::read_to_string(out.join("summary.json")).expect("summary.json written");
    let v: Value = serde_json::from_str(&text).expect("summary.json is JSON");
    let csv = std::fs::read_to_string(out.join("trajectory.csv")).expect("trajectory.csv written");
    assert!(!csv.contains("NaN"), "NaN in trajectory.csv");
    let _ = std::fs::remove_dir_all(&out);
    v
}

fn sim(args: &[&str], tag: &str) -> Value {
    sim_expecting(args, tag, false)
}

fn worst(v: &Value, key: &str, window: &str) -> f64 {
    v["agents"]
        .as_array()
        .unwrap()
        .iter()
        .map(|a| a[key][window].as_f64().expect("window has a value"))
        .fold(0.0, f64::max)
}

fn violations(v: &Value) -> (u64, u64) {
    v["agents"]
        .as_array()
        .unwrap()
        .iter()
        .fold((0, 0), |(a, r), x| {
            (
                a + x["attitude_constraint_violations"].as_u64().unwrap(),
                r + x["rate_constraint_violations"].as_u64().unwrap(),
            )
        })
}

#[test]
fn proposed_controller_flies_the_paper_mission_within_the_contract() {
    let v = sim(&[], "proposed");
    assert_eq!(v["scenario"], "paper");
    assert_eq!(v["variant"], "proposed");
    assert_eq!(v["mode"], "in-process");
    assert_eq!(v["n_agents"], 5);
    assert_eq!(v["diverged"], false);
    assert!(v["divergence"].is_null());
    assert_eq!(v["steps"], 60_000);
    assert_eq!(violations(&v), (0, 0), "constraint violations");
    for window in ["cover", "enclose"] {
        let rms = worst(&v, "rms_formation_error_m", window);
        assert!(
            rms <= 0.25,
            "worst RMS formation error in {window}: {rms} m"
        );
    }
    let coverage = v["coverage_fraction"].as_f64().unwrap();
    assert!(coverage >= 0.95, "coverage {coverage}");
}

#[test]
fn removing_the_rbfnn_makes_the_worst_covering_error_at_least_one_and_a_half_times_larger() {
    let with = worst(&sim(&[], "with-nn"), "rms_formation_error_m", "cover");
    let without = worst(
        &sim(&["--variant", "no-rbfnn"], "no-nn"),
        "rms_formation_error_m",
        "cover",
    );
    assert!(
        without >= 1.5 * with,
        "no-rbfnn {without} vs proposed {with}"
    );
}

#[test]
fn paper_exact_gains_diverge_and_the_summary_names_time_agent_and_cause() {
    let v = sim_expecting(&["paper-exact"], "exact", true);
    assert_eq!(
        v["diverged"], true,
        "the printed gains are known not to close the loop"
    );
    let d = &v["divergence"];
    assert!(d["time_s"].as_f64().unwrap() > 0.0);
    let agent = d["agent"].as_u64().unwrap();
    assert!((1..=5).contains(&agent));
    assert!(!d["cause"].as_str().unwrap().is_empty());
}

/// Fig. 9's comparison is the paper's: the printed sharp phase changes flown as written and no
/// separation layer (D25 and D26 off). The quadrotors then come nearer than the safety distance
/// (exit 3, verdict `fail`), which the comparison of the constraints does not depend on.
#[test]
fn under_abrupt_faults_only_the_unconstrained_controller_crosses_the_constraints() {
    let scenario = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../config/scenarios/abrupt-faults.toml"
    );
    let printed = [
        scenario,
        "--set",
        "mission.shaping.enabled=false",
        "--set",
        "controller.separation.enabled=false",
    ];
    let proposed = sim_expecting(&printed, "abrupt-proposed", true);
    assert_eq!(proposed["diverged"], false);
    assert_eq!(proposed["separation"]["verdict"], "fail");
    let mut args = printed.to_vec();
    args.extend(["--variant", "unconstrained"]);
    let unconstrained = sim_expecting(&args, "abrupt-unconstrained", true);
    assert_eq!(violations(&proposed), (0, 0));
    let (a, r) = violations(&unconstrained);
    assert!(
        a + r > 0,
        "the comparison controller was expected to cross a constraint"
    );
}

/// `formation sim` (the default `paper` scenario, start-up reference generator D19 on) over [0, 15] s
/// from the given start positions, with the cover window moved to [5, 15) s; `extra` are more `--set`s.
fn start_up(starts: &[[f64; 2]; 5], extra: &[&str], tag: &str) -> Value {
    let mut args: Vec<String> = Vec::new();
    for (i, p) in starts.iter().enumerate() {
        args.push("--set".into());
        args.push(format!(
            "agents[{i}].initial_position_m=[{},{},0.0]",
            p[0], p[1]
        ));
    }
    for s in [
        "simulation.duration_s=15",
        "metrics.cover_window_s=[5.0,15.0]",
    ]
    .iter()
    .chain(extra)
    {
        args.push("--set".into());
        args.push(s.to_string());
    }
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    sim(&args, tag)
}

/// Case A of docs/tuning.md section 8: every agent 4 m off its slot, each in another direction. Without
/// D19 the law rings on its acceleration limit (RMS over [5, 15) s 1.47 m, peak 4.8 m, two quadrotors
/// 0.20 m apart); with it 0.32 m, peak 0.75 m, closest approach 0.78 m.
#[test]
fn starts_four_metres_off_the_slots_settle_without_ringing_and_keep_the_quadrotors_apart() {
    let v = start_up(
        &[
            [0.0, 21.64],
            [-6.5, 15.83],
            [-1.56, 8.88],
            [5.54, 12.86],
            [2.51, 11.8],
        ],
        &[],
        "startup-offsets",
    );
    let rms = worst(&v, "rms_formation_error_m", "cover");
    let peak = worst(&v, "max_formation_error_m", "cover");
    let sep = v["separation"]["min_distance"]["whole"]["distance_m"]
        .as_f64()
        .unwrap();
    assert!(rms < 0.5, "worst RMS over [5, 15) s {rms} m");
    assert!(peak < 1.0, "worst error over [5, 15) s {peak} m");
    assert!(sep > 0.5, "closest approach {sep} m");
    assert_eq!(violations(&v), (0, 0));
}

/// Case B of docs/tuning.md section 8: a target 3x faster whose path starts 4 m beside the swarm, so that
/// P_d rushes 4 m at 8 m/s at t = 0. Without D19: RMS over [5, 15) s 2.35 m, peak 5.3 m (ringing);
/// with it 0.29 m, peak 0.73 m.
#[test]
fn a_fast_target_beside_the_swarm_is_joined_without_ringing() {
    let v = start_up(
        &[
            [4.0, 17.64],
            [1.5, 15.83],
            [2.44, 12.88],
            [5.54, 12.86],
            [6.51, 15.8],
        ],
        &["mission.target.angular_rate_rad_s=0.078"],
        "startup-fast-target",
    );
    let rms = worst(&v, "rms_formation_error_m", "cover");
    let peak = worst(&v, "max_formation_error_m", "cover");
    assert!(rms < 0.5, "worst RMS over [5, 15) s {rms} m");
    assert!(peak < 1.0, "worst error over [5, 15) s {peak} m");
    assert_eq!(violations(&v), (0, 0));
}
