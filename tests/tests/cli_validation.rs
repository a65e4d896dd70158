//! End to end: the real `formation` binary rejects an invalid scenario with exit code 2 and an error
//! naming the field and the assumption, never with a panic.

use formation_config::Scenario;
use formation_tests::{bin, temp_dir};
use std::process::Command;

/// Writes `s` to `<tmp>/<file>` and runs `formation <args...> <that file>`.
fn run_with_scenario(s: &Scenario, file: &str, args: &[&str]) -> std::process::Output {
    let dir = temp_dir(file);
    let path = dir.join(file);
    std::fs::write(&path, s.to_toml_string()).expect("can write the scenario");
    let out = Command::new(bin("formation"))
        .args(args)
        .arg(&path)
        .output()
        .expect("formation starts");
    let _ = std::fs::remove_dir_all(&dir);
    out
}

#[test]
fn check_with_a_delay_above_tau_m_exits_2_naming_the_field_and_assumption_2() {
    let mut s = Scenario::paper();
    s.agents[2].delay.base_s = 0.045; // 0.045 + 0.015 > tau_M = 0.05
    let out = run_with_scenario(&s, "delay-above-tau-m.toml", &["check"]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "stderr: {stderr}");
    assert!(stderr.contains("agents[2].delay"), "stderr: {stderr}");
    assert!(stderr.contains("Assumption 2"), "stderr: {stderr}");
    assert!(!stderr.contains("panicked"), "stderr: {stderr}");
}

#[test]
fn check_with_a_nan_inertia_exits_2_naming_the_field() {
    let mut s = Scenario::paper();
    s.vehicle.inertia_kg_m2[0] = f64::NAN;
    let out = run_with_scenario(&s, "nan-inertia.toml", &["check"]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "stderr: {stderr}");
    assert!(
        stderr.contains("vehicle.inertia_kg_m2[0]"),
        "stderr: {stderr}"
    );
    assert!(!stderr.contains("panicked"), "stderr: {stderr}");
}

#[test]
fn check_with_an_unknown_field_exits_2_naming_it() {
    let dir = temp_dir("unknown-field");
    let path = dir.join("typo.toml");
    let text = formation_config::scenario::PAPER_TOML.replacen(
        "[controller.position]",
        "[controller.position]\nk_p_typo = 1.0",
        1,
    );
    std::fs::write(&path, text).expect("can write the scenario");
    let out = Command::new(bin("formation"))
        .arg("check")
        .arg(&path)
        .output()
        .expect("formation starts");
    let _ = std::fs::remove_dir_all(&dir);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "stderr: {stderr}");
    assert!(stderr.contains("k_p_typo"), "stderr: {stderr}");
    assert!(!stderr.contains("panicked"), "stderr: {stderr}");
}

#[test]
fn check_of_the_embedded_paper_exact_scenario_prints_json_with_verdicts() {
    let out = Command::new(bin("formation"))
        .args(["check", "paper-exact", "--json"])
        .output()
        .expect("formation starts");
    assert_eq!(
        out.status.code(),
        Some(0),
        "stderr: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value =
        serde_json::from_slice(&out.stdout).expect("stdout is one JSON object");
    assert_eq!(v["scenario"], "paper-exact");
    assert_eq!(v["theorem1"]["search"]["positive_definite"], false);
    assert!(!v["verdicts"].as_array().expect("verdicts array").is_empty());
}
