//! End to end: the real `formation` binary rejects an invalid scenario or argument with exit code 2
//! and an error naming the field and the assumption, never with a panic; a command that ran but whose
//! result is a failure (a FAIL verdict, a divergence) exits 3 with its outputs written; bare
//! `formation` is `formation run` with its defaults.

use formation_config::Scenario;
use formation_runtime::record::csv::Column;
use formation_runtime::record::table::Trajectory;
use formation_tests::{bin, stderr_of as stderr, summary, temp_dir};
use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

/// Runs `formation <args...>` (never building anything, in the system temporary directory, with
/// its own runs directory under `dir`).
fn formation(dir: &Path, args: &[&str]) -> Output {
    Command::new(bin("formation"))
        .args(args)
        .env("FORMATION_RUNS_DIR", dir.join("runs"))
        .env_remove("CARGO")
        .current_dir(dir)
        .output()
        .expect("formation starts")
}

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
fn a_host_daemon_named_like_the_launcher_exits_2_with_one_line_before_it_opens_anything() {
    let dir = temp_dir("host-name-local");
    let o = formation(&dir, &["host", "--name", "local"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert_eq!(
        stderr(&o).trim_end(),
        "error: --name 'local': use 1..=32 characters of [A-Za-z0-9_-] (and not 'local')"
    );
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
fn check_of_the_embedded_paper_exact_scenario_prints_json_with_verdicts_and_exits_3_on_a_fail() {
    let out = Command::new(bin("formation"))
        .args(["check", "paper-exact", "--json"])
        .output()
        .expect("formation starts");
    assert_eq!(
        out.status.code(),
        Some(3),
        "a FAIL verdict exits 3; stderr: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value =
        serde_json::from_slice(&out.stdout).expect("stdout is one JSON object");
    assert_eq!(v["scenario"], "paper-exact");
    assert_eq!(v["theorem1"]["search"]["positive_definite"], false);
    assert!(!v["verdicts"].as_array().expect("verdicts array").is_empty());
    assert_eq!(v["worst"], "FAIL");
}

#[test]
fn check_exits_0_on_the_shipped_paper_design_whose_unmet_theorem1_conditions_are_information() {
    let dir = temp_dir("check-paper");
    let o = formation(&dir, &["check", "--json"]);
    assert_eq!(
        o.status.code(),
        Some(0),
        "the paper design flies: {}",
        stderr(&o)
    );
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).expect("one JSON object");
    let level = |name: &str| {
        v["verdicts"]
            .as_array()
            .unwrap()
            .iter()
            .find(|x| x["check"] == name)
            .unwrap_or_else(|| panic!("{name} in the report"))["level"]
            .clone()
    };
    assert_eq!(
        level("theorem1.m_positive_definite"),
        "INFO",
        "a sufficient condition, not met"
    );
    assert_eq!(level("inner.unconstrained.cascade_margin"), "INFO");
    assert_ne!(v["worst"], "FAIL");
    let u = formation(&dir, &["check", "--variant", "unconstrained"]);
    assert_eq!(
        u.status.code(),
        Some(3),
        "the unconstrained variant's own cascade margin is negative"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn check_exits_3_on_a_ring_pinned_at_one_agent_that_it_predicts_not_to_fly() {
    let dir = temp_dir("check-ring");
    let ring = dir.join("ring7.toml");
    let g = formation(
        &dir,
        &[
            "scenario",
            "--n",
            "7",
            "--graph",
            "ring",
            "--out",
            ring.to_str().unwrap(),
        ],
    );
    assert!(g.status.success(), "{}", stderr(&g));
    let pinned = [
        "--set",
        "graph.leader_broadcast=\"pinned\"",
        "--set",
        "graph.leader_weights=[1.0,0.0,0.0,0.0,0.0,0.0,0.0]",
    ];
    let mut args = vec!["check", ring.to_str().unwrap()];
    args.extend(pinned);
    let o = formation(&dir, &args);
    let text = String::from_utf8_lossy(&o.stdout);
    assert_eq!(o.status.code(), Some(3), "{text}");
    assert!(text.contains("FAIL outer.leader_information"), "{text}");
    // Every other agent pinned (the generator's default) flies (docs/tuning.md, section 7).
    let o = formation(
        &dir,
        &[
            "check",
            ring.to_str().unwrap(),
            "--set",
            "graph.leader_broadcast=\"pinned\"",
        ],
    );
    assert_eq!(
        o.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&o.stdout)
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn bare_formation_starts_the_default_lockstep_run_exactly_like_formation_run() {
    let dir = temp_dir("bare");
    let mut child = Command::new(bin("formation"))
        .env("FORMATION_RUNS_DIR", dir.join("runs"))
        .env_remove("CARGO")
        .current_dir(&dir)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("formation starts");
    let out = dir.join("out/paper-proposed-lockstep");
    // Kills the run whatever happens below.
    struct Guard(std::process::Child, std::path::PathBuf);
    impl Drop for Guard {
        fn drop(&mut self) {
            let _ = self.0.kill();
            let _ = self.0.wait();
            for pid in formation_tests::run::processes_mentioning(&self.1) {
                // SAFETY: kill with a pid just read from /proc; at worst it has exited.
                unsafe {
                    libc::kill(pid as i32, libc::SIGKILL);
                }
            }
        }
    }
    // Drain stderr on a thread for the whole run (a closed pipe would kill it with SIGPIPE).
    let stderr = BufReader::new(child.stderr.take().expect("stderr is piped"));
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        for line in stderr.lines().map_while(Result::ok) {
            let _ = tx.send(line);
        }
    });
    let mut guard = Guard(child, out.clone());
    let mut seen = Vec::new();
    while let Ok(line) = rx.recv_timeout(Duration::from_secs(60)) {
        seen.push(line.clone());
        if line.starts_with("formation run: id") || line.starts_with("error") {
            break;
        }
    }
    let text = seen.join("\n");
    assert!(!text.contains("error"), "bare formation failed: {text}");
    assert!(
        text.contains("5 agents, 60000 steps"),
        "the paper scenario with its defaults: {text}"
    );
    // `--pin auto`: the automatic layout, or not pinned naming the CPU others keep busy.
    assert!(
        text.contains("plant cpu") || text.contains("not pinned: cpu"),
        "placed as `--pin auto`: {text}"
    );
    // Stop it as Ctrl-C would: exit code 130 and the default output directory of `run`.
    // SAFETY: signal to our own child.
    unsafe {
        libc::kill(guard.0.id() as i32, libc::SIGINT);
    }
    let start = Instant::now();
    let status = loop {
        if let Some(st) = guard.0.try_wait().expect("can wait") {
            break st;
        }
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "no exit after SIGINT"
        );
        std::thread::sleep(Duration::from_millis(20));
    };
    assert_eq!(status.code(), Some(130));
    assert!(out.join("trajectory.csv").is_file(), "{}", out.display());
    assert!(out.join("scenario.toml").is_file());
    drop(guard);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn sim_that_diverges_exits_3_with_its_outputs_written() {
    let dir = temp_dir("sim-diverges");
    let out = dir.join("out");
    let o = formation(
        &dir,
        &["sim", "paper-exact", "--out", out.to_str().unwrap()],
    );
    assert_eq!(o.status.code(), Some(3), "stderr: {}", stderr(&o));
    assert!(stderr(&o).contains("diverged: t = "), "{}", stderr(&o));
    assert_eq!(summary(&out)["diverged"], true);
    assert!(out.join("trajectory.csv").is_file());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn run_that_diverges_exits_3_with_its_outputs_written() {
    let dir = temp_dir("run-diverges");
    let out = dir.join("out");
    let o = formation(
        &dir,
        &["run", "paper-exact", "--out", out.to_str().unwrap()],
    );
    assert_eq!(o.status.code(), Some(3), "stderr: {}", stderr(&o));
    let v = summary(&out);
    assert_eq!(v["diverged"], true);
    assert_eq!(v["mode"], "lockstep");
    assert!(out.join("trajectory.csv").is_file());
    // Child logs name agents by their 1-based ids, as the file names do.
    let log = std::fs::read_to_string(out.join("logs/agent-1.log")).expect("agent 1 logs");
    assert!(log.contains("fm-agent-1 starting"), "{log}");
    assert!(!log.contains("fm-agent-0"), "{log}");
    let log5 = std::fs::read_to_string(out.join("logs/agent-5.log")).expect("agent 5 logs");
    assert!(log5.contains("fm-agent-5 starting"), "{log5}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn sim_with_a_duration_shorter_than_one_step_exits_2_naming_the_duration() {
    let dir = temp_dir("zero-steps");
    let o = formation(
        &dir,
        &["sim", "--set", "simulation.duration_s=0.0004", "--out", "o"],
    );
    assert_eq!(o.status.code(), Some(2), "stderr: {}", stderr(&o));
    assert!(
        stderr(&o).contains("simulation.duration_s"),
        "{}",
        stderr(&o)
    );
    assert!(!dir.join("o/summary.json").exists());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn sim_with_a_negative_rbfnn_gain_exits_2_naming_the_field_and_eq_15() {
    let dir = temp_dir("negative-gain");
    let o = formation(
        &dir,
        &[
            "sim",
            "--set",
            "controller.position.nn_k_p=-5",
            "--out",
            "o",
        ],
    );
    assert_eq!(o.status.code(), Some(2), "stderr: {}", stderr(&o));
    assert!(
        stderr(&o).contains("controller.position.nn_k_p") && stderr(&o).contains("eq. (15)"),
        "{}",
        stderr(&o)
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// The time of every row of `trajectory.csv` holding a value that is not a finite number.
fn non_finite_rows(csv: &Path) -> Vec<f64> {
    let tr = Trajectory::read(csv).expect("trajectory.csv is written");
    tr.rows()
        .iter()
        .filter(|r| r.iter().any(|v| !v.is_finite()))
        .map(|r| tr.value(r, Column::T))
        .collect()
}

#[test]
fn a_non_finite_output_is_a_divergence_at_the_step_it_appears() {
    for set in [
        "controller.attitude.attitude_margin_rad=1e308", // C_i1² overflows: blf1 = NaN
        "controller.position.nn_k_v=1e308",              // the RBFNN weights overflow
    ] {
        let dir = temp_dir("non-finite");
        let out = dir.join("out");
        let o = formation(&dir, &["sim", "--set", set, "--out", out.to_str().unwrap()]);
        assert_eq!(o.status.code(), Some(3), "{set}: stderr: {}", stderr(&o));
        let v = summary(&out);
        assert_eq!(v["diverged"], true, "{set}");
        let cause = v["divergence"]["cause"].as_str().expect("a cause");
        assert!(cause.contains("not finite"), "{set}: {cause}");
        // Non-finite values appear only in the rows of the step the run diverged at (its last).
        let t = v["divergence"]["time_s"].as_f64().expect("a time");
        let rows = non_finite_rows(&out.join("trajectory.csv"));
        assert!(!rows.is_empty(), "{set}: the diverging step is written");
        // The same step: summary.json's time is the reference frame's t, the CSV's the plant state's,
        // which may differ in the last bit (26 * 0.001 against 0.026).
        for row_t in rows {
            assert!(
                (row_t - t).abs() < 1e-9,
                "{set}: non-finite value before the divergence at {t} s, at t = {row_t}"
            );
        }
        let _ = std::fs::remove_dir_all(&dir);
    }
}

#[test]
fn set_that_is_not_exactly_path_equals_value_exits_2_naming_it() {
    let dir = temp_dir("set-strict");
    for arg in [
        "agents[0.delay.base_s=0.1",
        "agents[0]]]].delay.base_s=0.1",
        "controller.position.k_p=1.5\nsimulation.duration_s=1",
    ] {
        let o = formation(&dir, &["check", "--set", arg]);
        assert_eq!(o.status.code(), Some(2), "{arg:?}: stderr: {}", stderr(&o));
        assert!(
            stderr(&o).contains(&format!("--set {arg:?}")),
            "{arg:?} is named: {}",
            stderr(&o)
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn set_for_every_agent_and_validation_errors_name_the_1_based_agent_id() {
    let dir = temp_dir("set-every");
    let o = formation(&dir, &["check", "--set", "agents[*].delay.base_s=0.046"]);
    assert_eq!(o.status.code(), Some(2), "stderr: {}", stderr(&o));
    let err = stderr(&o);
    // 0.046 + amplitude > tau_M = 0.05 for every agent (amplitudes 0.005 .. 0.015).
    for k in 0..5 {
        assert!(
            err.contains(&format!("agents[{k}].delay (agent {}):", k + 1)),
            "agents[{k}] named with its id: {err}"
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn negative_numbers_reach_validation_which_names_the_argument() {
    let dir = temp_dir("negative-args");
    let inject = [
        "inject",
        "fault",
        "--agent",
        "1",
        "--gamma",
        "0.5,0.5,0.5",
        "--delta",
    ];
    let cases: [(Vec<&str>, &str); 6] = [
        // Valid values: refused only because no run is running.
        (
            [&inject[..], &["-0.1,0,0", "--run", "nosuch"]].concat(),
            "nosuch",
        ),
        ([&inject[..], &["0,0,0", "--at", "-1"]].concat(), "--at -1"),
        (
            vec![
                "inject", "delay", "--agent", "1", "--tau", "0.01", "--at", "-0.5",
            ],
            "--at -0.5",
        ),
        (vec!["bench", "--seconds", "-1"], "--seconds"),
        (vec!["scenario", "--n", "-3"], "--n"),
        (vec!["bench", "--n", "-2"], "--n"),
    ];
    for (args, named) in cases {
        let o = formation(&dir, &args);
        let err = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
        assert!(!err.contains("unexpected argument"), "{args:?}: {err}");
        assert!(err.contains(named), "{args:?} names {named}: {err}");
        assert!(!err.contains("panicked"), "{args:?}: {err}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn run_and_sim_with_json_print_exactly_their_summary_json_on_stdout() {
    let dir = temp_dir("json-summary");
    for command in ["sim", "run"] {
        let out = dir.join(command);
        let o = formation(
            &dir,
            &[
                command,
                "--set",
                "simulation.duration_s=0.3",
                "--out",
                out.to_str().unwrap(),
                "--json",
            ],
        );
        assert!(o.status.success(), "{command}: {}", stderr(&o));
        let printed: serde_json::Value = serde_json::from_slice(&o.stdout)
            .unwrap_or_else(|e| panic!("{command} --json: stdout is not one JSON value: {e}"));
        assert_eq!(printed, summary(&out), "{command}: stdout == summary.json");
        assert_eq!(printed["steps"], 300);
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn scenario_with_json_prints_the_same_scenario_as_its_toml() {
    let dir = temp_dir("scenario-json");
    let args = ["scenario", "--n", "7", "--graph", "ring"];
    let toml = formation(&dir, &args);
    assert!(toml.status.success(), "{}", stderr(&toml));
    let json = formation(&dir, &[&args[..], &["--json"]].concat());
    assert!(json.status.success(), "{}", stderr(&json));
    let from_toml = Scenario::from_toml_str(&String::from_utf8_lossy(&toml.stdout))
        .expect("the TOML output parses");
    let printed: serde_json::Value =
        serde_json::from_slice(&json.stdout).expect("--json prints one JSON value");
    assert_eq!(printed["agents"].as_array().map(Vec::len), Some(7));
    // Compared as text: serde_json's float parser may be an ulp off, its printer is exact.
    let expected = serde_json::to_string_pretty(&from_toml).unwrap() + "\n";
    assert_eq!(String::from_utf8_lossy(&json.stdout), expected);
    let _ = std::fs::remove_dir_all(&dir);
}
