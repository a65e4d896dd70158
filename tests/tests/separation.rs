//! End-to-end: the separation layer (docs/deviations.md D25) and the shaped transitions (D26)
//! through the real `formation sim` binary: the shipped abrupt-fault case keeps every pair apart,
//! a run in which no pair comes within the activation distance is byte-identical with the layer
//! on and off, crossing starts are flown apart, and a run under the safety distance fails with
//! exit code 3 and the verdict `fail`.

use formation_tests::{formation, stderr_of, summary, temp_dir, TempDir};
use serde_json::Value;

/// Runs `formation sim <args>` into a fresh folder: (exit code, summary.json, the folder (removed
/// when dropped), stderr).
fn sim(args: &[&str], tag: &str) -> (Option<i32>, Value, TempDir, String) {
    let out = temp_dir(tag);
    let path = out.display().to_string();
    let mut all = vec!["sim"];
    all.extend_from_slice(args);
    all.extend(["--out", path.as_str()]);
    let o = formation(&all);
    let stderr = stderr_of(&o);
    assert!(!stderr.contains("panicked"), "{stderr}");
    (o.status.code(), summary(&out), out, stderr)
}

fn steps_below(v: &Value) -> u64 {
    v["separation"]["steps_below_safety"].as_u64().unwrap()
}

fn closest(v: &Value) -> f64 {
    v["separation"]["min_distance"]["whole"]["distance_m"]
        .as_f64()
        .unwrap()
}

/// A formation whose pairs stay beyond the 0.9 m activation distance (rings of 4 and 2 m, 45 s).
const WIDE: [&str; 6] = [
    "--set",
    "mission.formation.cover_radius_m=4.0",
    "--set",
    "mission.formation.enclose_radius_m=2.0",
    "--set",
    "simulation.duration_s=45",
];

/// Swaps the start positions of two pairs of agents (1-based) of the paper scenario.
fn swapped(pairs: &[(usize, usize)]) -> Vec<String> {
    let starts = [
        "[0.0, 17.64, 0.0]",
        "[-2.5, 15.83, 0.0]",
        "[-1.56, 12.88, 0.0]",
        "[1.54, 12.86, 0.0]",
        "[2.51, 15.8, 0.0]",
    ];
    let mut sets = Vec::new();
    for &(a, b) in pairs {
        sets.push("--set".to_string());
        sets.push(format!(
            "agents[{}].initial_position_m={}",
            a - 1,
            starts[b - 1]
        ));
        sets.push("--set".to_string());
        sets.push(format!(
            "agents[{}].initial_position_m={}",
            b - 1,
            starts[a - 1]
        ));
    }
    sets
}

#[test]
fn the_shipped_abrupt_fault_case_keeps_every_pair_beyond_the_safety_distance() {
    let scenario = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../config/scenarios/abrupt-faults.toml"
    );
    let (code, v, _out, stderr) = sim(&[scenario], "sep-abrupt");
    assert_eq!(code, Some(0), "{stderr}");
    assert_eq!(steps_below(&v), 0);
    assert_eq!(v["separation"]["verdict"], "ok");
    assert!(closest(&v) > 0.5, "closest {}", closest(&v));
    for a in v["agents"].as_array().unwrap() {
        let s = &a["separation"];
        assert!(s["min_actual_m"].as_f64().unwrap() >= closest(&v) - 1e-12);
        assert!(s["layer_active_s"].as_f64().unwrap() >= 0.0);
    }
}

/// A formation twice as wide as the paper's (neighbours 2.4 m apart when enclosing, more than the
/// 0.9 m activation distance plus any stopping distance it flies at): the layer never acts, and
/// the trajectory is the same, byte for byte, with it off.
#[test]
fn a_run_whose_pairs_stay_beyond_the_activation_distance_is_byte_identical_with_the_layer_off() {
    let wide = WIDE;
    let (code_on, on, dir_on, e1) = sim(&wide, "sep-inert-on");
    let mut off_args = wide.to_vec();
    off_args.extend(["--set", "controller.separation.enabled=false"]);
    let (code_off, off, dir_off, e2) = sim(&off_args, "sep-inert-off");
    assert_eq!((code_on, code_off), (Some(0), Some(0)), "{e1}{e2}");
    for a in on["agents"].as_array().unwrap() {
        assert_eq!(a["separation"]["layer_active_s"].as_f64(), Some(0.0));
    }
    assert!(closest(&on) > 1.5, "closest {}", closest(&on));
    let a = std::fs::read(dir_on.join("trajectory.csv")).unwrap();
    let b = std::fs::read(dir_off.join("trajectory.csv")).unwrap();
    assert!(a == b, "trajectory.csv differs with the layer on and off");
    assert_eq!(on["agents"], off["agents"]);
}

/// Two pairs of start positions exchanged: the start-up paths cross. Without the layer two
/// quadrotors come nearer than the safety distance and the run fails (exit 3, verdict `fail`,
/// stderr names the pair); with it they are flown apart.
#[test]
fn crossing_starts_are_flown_apart_and_without_the_layer_the_run_fails_with_exit_3() {
    let sets = swapped(&[(1, 5), (2, 4)]);
    let mut args: Vec<&str> = vec!["--set", "simulation.duration_s=12"];
    args.extend(sets.iter().map(String::as_str));
    let (code, on, _dir_on, stderr) = sim(&args, "sep-swap-on");
    assert_eq!(code, Some(0), "{stderr}");
    assert_eq!(steps_below(&on), 0);
    let active: f64 = on["agents"]
        .as_array()
        .unwrap()
        .iter()
        .map(|a| a["separation"]["layer_active_s"].as_f64().unwrap())
        .sum();
    assert!(active > 0.0, "the layer acted");
    args.extend(["--set", "controller.separation.enabled=false"]);
    let (code, off, _dir_off, stderr) = sim(&args, "sep-swap-off");
    assert_eq!(code, Some(3), "{stderr}");
    assert!(steps_below(&off) > 0);
    assert_eq!(off["separation"]["verdict"], "fail");
    assert!(stderr.contains("separation failed"), "{stderr}");
}

/// A separation parameter outside its range is refused before anything runs, naming the field and
/// the deviation it breaks (exit 2).
#[test]
fn a_bad_separation_parameter_exits_2_naming_the_field() {
    let stderr = refused("controller.separation.broadcast_delay_s=0.2", "sep-bad");
    assert!(
        stderr.contains("controller.separation.broadcast_delay_s") && stderr.contains("D25"),
        "{stderr}"
    );
}

/// The repulsive term, one of the designs measured against the barrier (D25), is inert while no
/// pair is within the activation distance: the wide formation's trajectory is byte-identical with
/// the layer off. A negative gain is refused naming the field (exit 2).
#[test]
fn the_repulsive_design_is_inert_beyond_the_activation_distance_and_refuses_a_negative_gain() {
    let wide = WIDE;
    let mut rep = wide.to_vec();
    rep.extend(["--set", "controller.separation.method=\"repulsive\""]);
    let (code_on, _, dir_on, e1) = sim(&rep, "sep-rep-on");
    let mut off = wide.to_vec();
    off.extend(["--set", "controller.separation.enabled=false"]);
    let (code_off, _, dir_off, e2) = sim(&off, "sep-rep-off");
    assert_eq!((code_on, code_off), (Some(0), Some(0)), "{e1}{e2}");
    let a = std::fs::read(dir_on.join("trajectory.csv")).unwrap();
    let b = std::fs::read(dir_off.join("trajectory.csv")).unwrap();
    assert!(
        a == b,
        "trajectory.csv differs with the repulsive term and without the layer"
    );
    let stderr = refused(
        "controller.separation.repulsive_gain_m3_s2=-1",
        "sep-rep-bad",
    );
    assert!(
        stderr.contains("controller.separation.repulsive_gain_m3_s2"),
        "{stderr}"
    );
}

/// `formation sim --set SET` is refused before anything runs (exit 2); its stderr.
fn refused(set: &str, tag: &str) -> String {
    let out = temp_dir(tag);
    let path = out.display().to_string();
    let o = formation(&["sim", "--set", set, "--out", path.as_str()]);
    let (code, stderr) = (o.status.code(), stderr_of(&o));
    assert_eq!(code, Some(2), "{stderr}");
    stderr
}
