//! End to end with an outside client nobody here wrote the transport of: the Python SDK
//! (`clients/python`, on the PyPI `iceoryx2==0.10.0` binding) attaches to a live lockstep run as
//! an observer — telemetry of agent 2, a second subscriber on the states of agents 1 and 2, a
//! listener on agent 1's wake-up event, the run control — and
//! * every sample it reads equals, float for float, the same step's row of `trajectory.csv` and
//!   the sample `formation inspect --json` printed for that step;
//! * it sees the run end (the stop on `formation/run/control`) and exits by itself;
//! * the run stays byte-identical to `formation sim`, and `python -m formation_client inspect`
//!   prints what `formation inspect --json` prints.
//!
//! The interpreter is `$FORMATION_PYTHON` (`.ci/run` creates the venv `target/pyenv`); without it
//! the test is skipped with the reason, unless `FORMATION_REQUIRE_PYTHON=1` (CI).

use formation_config::protocol::wire::{AgentTelemetry, VehicleState};
use formation_runtime::record::csv::Column;
use formation_runtime::record::table::Trajectory;
use formation_tests::run::RunningRun;
use formation_tests::wire::{assert_state_is_row, from_raw, rows_by_agent_and_step};
use formation_tests::{formation_in, python_or_skip, temp_dir, workspace_root};
use serde_json::Value;
use std::collections::BTreeMap;
use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// Generous bound for anything to happen; reaching it means a hang.
const TIMEOUT: Duration = Duration::from_secs(180);

/// Simulated duration of the observed run, s.
const DURATION: &str = "simulation.duration_s=10";

fn python(py: &Path, runs: &Path) -> Command {
    let mut c = Command::new(py);
    c.env("PYTHONPATH", workspace_root().join("clients/python"))
        .env("FORMATION_RUNS_DIR", runs)
        .env_remove("CARGO");
    c
}

fn run_id(runs: &Path, run: &RunningRun) -> String {
    let start = Instant::now();
    loop {
        let o = formation_in(runs, &["ps", "--json"]);
        let v: Value = serde_json::from_slice(&o.stdout).unwrap_or(Value::Null);
        if let Some(id) = v["runs"][0]["id"].as_str() {
            return id.to_string();
        }
        assert!(start.elapsed() < TIMEOUT, "never listed: {}", run.stderr());
        std::thread::sleep(Duration::from_millis(20));
    }
}

fn f(v: &Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("a number: {v}"))
}

#[test]
fn a_python_observer_reads_exactly_the_recorded_values_and_the_run_stays_byte_identical() {
    let Some(py) = python_or_skip("python_client") else {
        return;
    };
    let dir = temp_dir("python-client");
    let runs = dir.join("runs");
    let mut run = RunningRun::start_with_env(
        &["--set", DURATION],
        &dir.join("out"),
        &[("FORMATION_RUNS_DIR", &runs)],
    );
    let id = run_id(&runs, &run);
    let mut observer = python(&py, &runs)
        .arg(workspace_root().join("tests/python/observer.py"))
        .arg(&id)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("the Python observer starts");
    let lines = BufReader::new(observer.stdout.take().expect("piped"));
    let reader = std::thread::spawn(move || {
        lines
            .lines()
            .map_while(Result::ok)
            .map(|l| serde_json::from_str::<Value>(&l).expect("the observer prints JSON"))
            .collect::<Vec<Value>>()
    });
    // Meanwhile, `formation inspect --json` and the SDK's own inspect, for comparison by step.
    let mut inspected: BTreeMap<u64, Value> = BTreeMap::new();
    let mut sdk_inspected: BTreeMap<u64, Value> = BTreeMap::new();
    let start = Instant::now();
    while run.role_processes().len() == 7 && start.elapsed() < TIMEOUT {
        let o = formation_in(&runs, &["inspect", "--agent", "2", "--json"]);
        if let Ok(v) = serde_json::from_slice::<Value>(&o.stdout) {
            inspected.insert(v["step"].as_u64().unwrap(), v);
        }
        let o = python(&py, &runs)
            .args([
                "-m",
                "formation_client",
                "inspect",
                "--agent",
                "2",
                "--json",
            ])
            .output()
            .expect("python -m formation_client starts");
        if let Ok(v) = serde_json::from_slice::<Value>(&o.stdout) {
            sdk_inspected.insert(v["step"].as_u64().unwrap(), v);
        }
    }
    let (status, _) = run.wait(TIMEOUT).expect("the run finishes");
    assert!(status.success(), "run failed: {}", run.stderr());
    let observed = reader.join().expect("reader");
    let ended = observer.wait().expect("the observer exits");
    let mut err = String::new();
    if let Some(mut e) = observer.stderr.take() {
        let _ = std::io::Read::read_to_string(&mut e, &mut err);
    }
    assert!(ended.success(), "the observer failed: {err}");

    // It saw the end of the run: the stop, with the number of recorded steps.
    let end = &observed.last().expect("the observer printed")["end"];
    assert_eq!(end["stop_step"], 10_000, "{end}");
    assert!(f(&end["wakeups"]) > 0.0, "the wake-up listener was woken");

    // Every sample equals the recorded row of its step, float for float (trajectory.csv has every
    // 10th step at the default 100 Hz; telemetry comes every 20th).
    let tr = Trajectory::read(&run.out.join("trajectory.csv")).unwrap();
    let rows = rows_by_agent_and_step(&tr);
    let row = |agent: usize, step: u64| {
        *rows
            .get(&(agent, step))
            .unwrap_or_else(|| panic!("row of agent {agent} at step {step}"))
    };
    let (mut states, mut samples) = (0, 0);
    for v in &observed {
        if v.get("state").is_some() {
            let s: VehicleState = from_raw(v);
            let agent = s.agent as usize + 1;
            let Some(&r) = rows.get(&(agent, s.step)) else {
                continue; // a step between two rows
            };
            assert_state_is_row(&tr, r, &s);
            states += 1;
        }
        if v.get("telemetry").is_some() {
            let s: AgentTelemetry = from_raw(v);
            assert_eq!(s.agent, 1, "agent 2's telemetry");
            let r = row(2, s.step);
            let c = &s.controller;
            let gamma_hat = [Column::GammaHatX, Column::GammaHatY, Column::GammaHatZ];
            let delta_hat = [Column::DeltaHatX, Column::DeltaHatY, Column::DeltaHatZ];
            let f_hat = [Column::FHatX, Column::FHatY, Column::FHatZ];
            for k in 0..3 {
                assert_eq!(c.gamma_hat[k], tr.value(r, gamma_hat[k]));
                assert_eq!(c.delta_hat[k], tr.value(r, delta_hat[k]));
                assert_eq!(c.f_hat[k], tr.value(r, f_hat[k]));
            }
            assert_eq!(c.tau_s, tr.value(r, Column::Tau));
            assert_eq!(c.d_hat, tr.value(r, Column::DHat));
            assert_eq!(s.attitude[0], tr.value(r, Column::Phi));
            samples += 1;
        }
    }
    eprintln!(
        "observer: {states} states, {samples} telemetry samples, {} wake-ups; inspect: {} \
         samples, SDK inspect: {}",
        end["wakeups"],
        inspected.len(),
        sdk_inspected.len()
    );
    assert!(
        states > 0 && samples > 0,
        "the observer read states and telemetry"
    );

    // The same step read by `formation inspect --json` and by the observer: equal values.
    let by_step: BTreeMap<u64, &Value> = observed
        .iter()
        .filter_map(|v| v.get("telemetry"))
        .map(|s| (s["step"].as_u64().unwrap(), s))
        .collect();
    let mut common = 0;
    for (step, i) in &inspected {
        if let Some(s) = by_step.get(step) {
            assert_eq!(i["formation_error_m"], s["formation_error_m"]);
            assert_eq!(i["gamma_hat"], s["controller"]["gamma_hat"]);
            assert_eq!(i["e_p"], s["controller"]["e_p"]);
            assert_eq!(i["attitude"], s["attitude"]);
            common += 1;
        }
    }
    // And the SDK's inspect prints the keys and values of `formation inspect --json`.
    for (step, i) in &inspected {
        if let Some(p) = sdk_inspected.get(step) {
            for (key, value) in i.as_object().unwrap() {
                assert_eq!(&p[key], value, "{key} at step {step}");
            }
        }
    }
    eprintln!("steps read by both inspect and the observer: {common}");
    assert!(common > 0, "no step read by both inspect and the observer");
    assert!(
        !sdk_inspected.is_empty(),
        "python -m formation_client inspect answered"
    );

    // Observers never disturb a lockstep run: byte for byte what `formation sim` writes.
    formation_tests::assert_trajectory_is_sims(&run.out, &["--set", DURATION], &dir.join("sim"));
    drop(run);
    let _ = std::fs::remove_dir_all(&dir);
}
