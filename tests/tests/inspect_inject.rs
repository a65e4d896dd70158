//! End to end: a live `formation run` is discoverable with `formation ps`, one agent's telemetry is
//! readable with `formation inspect`, faults and delays injected with `formation inject` reach the
//! plant and the agents at the step the orchestrator announces (and are recorded), and bad
//! injections are rejected with exit code 2 without changing anything.
//!
//! Every test uses its own runs directory (`FORMATION_RUNS_DIR`), so runs of other tests or other
//! users never interfere; `RunningRun` kills the whole run on drop, even when an assertion fails.

use formation_runtime::record::csv::Column;
use formation_runtime::record::table::Trajectory;
use formation_tests::run::RunningRun;
use formation_tests::{bin, stderr_of as stderr, temp_dir};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::{Duration, Instant};

/// Generous bound for anything to happen; reaching it means a hang.
const TIMEOUT: Duration = Duration::from_secs(180);

/// Runs `formation <args>` with the given runs directory.
fn formation(runs: &Path, args: &[&str]) -> Output {
    formation_tests::formation_in(runs, args)
}

fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

fn ps_json(runs: &Path) -> Value {
    let o = formation(runs, &["ps", "--json"]);
    assert!(o.status.success(), "ps failed: {}", stderr(&o));
    serde_json::from_str(&stdout(&o)).expect("ps --json prints JSON")
}

/// Waits until `ps --json` lists exactly one run whose N agents are alive; returns that run.
fn wait_listed(runs: &Path, run: &RunningRun, n: usize) -> Value {
    let start = Instant::now();
    loop {
        let v = ps_json(runs);
        if let Some(r) = v["runs"].as_array().and_then(|a| a.first()) {
            let agents_alive = r["processes"].as_array().map_or(0, |p| {
                p.iter()
                    .filter(|p| p["role"] == "agent" && p["alive"] == true)
                    .count()
            });
            if agents_alive == n {
                return r.clone();
            }
        }
        assert!(
            start.elapsed() < TIMEOUT,
            "run never listed: {}",
            run.stderr()
        );
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// One telemetry sample of `agent` (1-based) as JSON, or `None` if the command failed.
fn inspect(runs: &Path, agent: usize) -> Option<Value> {
    let o = formation(runs, &["inspect", "--agent", &agent.to_string(), "--json"]);
    if !o.status.success() {
        return None;
    }
    serde_json::from_str(stdout(&o).lines().next()?).ok()
}

fn vec3(v: &Value, key: &str) -> [f64; 3] {
    let a = v[key]
        .as_array()
        .unwrap_or_else(|| panic!("{key} is an array: {v}"));
    assert_eq!(a.len(), 3, "{key} has 3 components");
    [0, 1, 2].map(|k| a[k].as_f64().expect("a number"))
}

/// The step an accepted injection applies at, from `formation inject`'s confirmation.
fn applies_at(o: &Output) -> u64 {
    assert!(o.status.success(), "inject failed: {}", stderr(o));
    let text = stdout(o);
    let rest = text
        .split("applies at step ")
        .nth(1)
        .unwrap_or_else(|| panic!("no step in: {text}"));
    rest.split(' ')
        .next()
        .and_then(|s| s.parse().ok())
        .expect("a step number")
}

/// The first telemetry sample of `agent` (1-based) at or after simulation time `t_min`.
fn sample_from(runs: &Path, run: &RunningRun, agent: usize, t_min: f64) -> Value {
    let start = Instant::now();
    loop {
        if let Some(s) = inspect(runs, agent).filter(|s| s["t"].as_f64().unwrap_or(0.0) >= t_min) {
            return s;
        }
        assert!(start.elapsed() < TIMEOUT, "no telemetry: {}", run.stderr());
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// Injects Gamma = 0.5 on every axis of agent 2 with the additive fault `delta`; the apply step.
fn inject_half_gamma_into_agent_2(runs: &Path, delta: &str) -> u64 {
    applies_at(&formation(
        runs,
        &[
            "inject",
            "fault",
            "--agent",
            "2",
            "--gamma",
            "0.5,0.5,0.5",
            "--delta",
            delta,
        ],
    ))
}

#[test]
fn ps_inspect_and_fault_injection_work_on_a_live_run() {
    let dir = temp_dir("inspect-live");
    let runs = dir.join("runs");
    let run = RunningRun::start_with_env(
        &["--set", "simulation.duration_s=40"],
        &dir.join("out"),
        &[("FORMATION_RUNS_DIR", &runs)],
    );
    let listed = wait_listed(&runs, &run, 5);
    let id = listed["id"]
        .as_str()
        .expect("the run has an id")
        .to_string();
    assert!(run.stderr().contains(&format!("formation run: id {id}")));
    let procs = listed["processes"].as_array().expect("processes");
    assert_eq!(
        procs.len(),
        5 + 3,
        "orchestrator, plant, leader and 5 agents"
    );
    assert!(procs.iter().all(|p| p["pid"].as_u64().is_some()));

    // Wait until agent 2's estimator has settled a little (t >= 4 s): the scenario's own additive
    // fault has then built up delta-hat, which the injection below removes.
    let before = sample_from(&runs, &run, 2, 4.0);
    assert_eq!(before["agent"], 2);
    for key in [
        "step",
        "t",
        "d_hat",
        "tau_s",
        "formation_error_m",
        "loop_latency_us",
    ] {
        assert!(before[key].is_number(), "{key} in {before}");
    }
    let gamma_before = vec3(&before, "gamma_hat");
    let delta_before = vec3(&before, "delta_hat");

    let fault_step = inject_half_gamma_into_agent_2(&runs, "0.15,0.1,0.5");
    let delay_step = applies_at(&formation(
        &runs,
        &["inject", "delay", "--agent", "3", "--tau", "0.03"],
    ));
    assert!(fault_step > before["step"].as_u64().unwrap());

    // While the run flies on, inspect keeps answering and Gamma-hat stays inside its projection bounds
    // (Assumption 5); the effect of the injection on Gamma-hat is checked at the end against a baseline.
    let start = Instant::now();
    let mut samples = 0;
    while run.role_processes().len() == 7 && start.elapsed() < TIMEOUT {
        if let Some(s) = inspect(&runs, 2) {
            let g = vec3(&s, "gamma_hat");
            assert!(
                g.iter().all(|x| (0.3..=1.05).contains(x)),
                "Gamma-hat within its projection bounds: {s}"
            );
            samples += 1;
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    assert!(samples > 0, "inspect answered during the run");
    let _ = (gamma_before, delta_before);

    let mut run = run;
    let (status, _) = run.wait(TIMEOUT).expect("the run finishes");
    assert!(status.success(), "run failed: {}", run.stderr());
    let out = &run.out;

    let summary: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    for a in summary["agents"].as_array().expect("agents") {
        assert_eq!(a["attitude_constraint_violations"], 0, "{a}");
        assert_eq!(a["rate_constraint_violations"], 0, "{a}");
    }
    assert_eq!(summary["diverged"], false);

    // Gamma-hat moves towards the injected 0.5: compared with the same scenario flown without the
    // injection (in-process, deterministic), agent 2's pitch Gamma-hat over the last 10 s is lower.
    let baseline_dir = dir.join("baseline");
    let status = std::process::Command::new(formation_tests::bin("formation"))
        .args([
            "sim",
            "--set",
            "simulation.duration_s=40",
            "--quiet",
            "--out",
        ])
        .arg(&baseline_dir)
        .output()
        .expect("formation sim runs");
    assert!(status.status.success());
    let late_mean = |csv: &std::path::Path| -> f64 {
        let tr = Trajectory::read(csv).unwrap();
        let vals: Vec<f64> = tr
            .agent(2)
            .filter(|r| tr.value(r, Column::T) >= 30.0)
            .map(|r| tr.value(r, Column::GammaHatY))
            .collect();
        vals.iter().sum::<f64>() / vals.len() as f64
    };
    // The estimates identify the injected fault itself (D16): from 15 s after the injection on, every
    // channel's mean Gamma-hat is within 10 % of 0.5 and delta-hat within 0.05 N m of the injected delta.
    let tr = Trajectory::read(&out.join("trajectory.csv")).unwrap();
    let rows: Vec<&[f64]> = tr
        .agent(2)
        .filter(|r| tr.value(r, Column::Step) >= (fault_step + 15_000) as f64)
        .collect();
    assert!(!rows.is_empty(), "the run lasts 15 s past the injection");
    let gamma_hat = [Column::GammaHatX, Column::GammaHatY, Column::GammaHatZ];
    let delta_hat = [Column::DeltaHatX, Column::DeltaHatY, Column::DeltaHatZ];
    for (k, axis) in ["x", "y", "z"].iter().enumerate() {
        let mean = |c: Column| rows.iter().map(|r| tr.value(r, c)).sum::<f64>() / rows.len() as f64;
        let g = mean(gamma_hat[k]);
        let d = mean(delta_hat[k]);
        let injected_delta = [0.15, 0.1, 0.5][k];
        assert!(
            (g - 0.5).abs() < 0.05,
            "Gamma-hat_{axis} of agent 2: {g} for 0.5 injected"
        );
        assert!(
            (d - injected_delta).abs() < 0.05,
            "delta-hat_{axis} of agent 2: {d} for {injected_delta} injected"
        );
    }
    let injected = late_mean(&out.join("trajectory.csv"));
    let baseline = late_mean(&baseline_dir.join("trajectory.csv"));
    assert!(
        injected < baseline - 0.02,
        "pitch Gamma-hat of agent 2 over 30-40 s: {injected} with Gamma = 0.5 injected vs {baseline} without"
    );

    let events = std::fs::read_to_string(out.join("events.jsonl")).expect("events.jsonl");
    let events: Vec<Value> = events
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(events.len(), 2, "{events:?}");
    assert_eq!(events[0]["event"], "fault");
    assert_eq!(events[0]["agent"], 2);
    assert_eq!(events[0]["step"], fault_step);
    assert_eq!(vec3(&events[0], "gamma"), [0.5; 3]);
    assert!(events[0]["wall_time_unix_s"].is_number() && events[0]["t"].is_number());
    assert_eq!(events[1]["event"], "delay");
    assert_eq!(events[1]["agent"], 3);
    assert_eq!(events[1]["step"], delay_step);

    // The plant's truth (gamma columns) and the agent's delay (tau column) change exactly at the
    // announced steps.
    let (mut after_fault, mut after_delay) = (0, 0);
    for r in tr.rows() {
        let step = tr.value(r, Column::Step) as u64;
        let agent = tr.value(r, Column::Agent) as usize;
        let gx = tr.value(r, Column::GammaX);
        let tau = tr.value(r, Column::Tau);
        if agent == 2 {
            if step >= fault_step {
                assert_eq!(gx, 0.5, "gamma_x of agent 2 at step {step}");
                after_fault += 1;
            } else {
                assert!(
                    gx > 0.5,
                    "gamma_x of agent 2 before the injection at step {step}"
                );
            }
        }
        if agent == 3 && step >= delay_step {
            assert!(
                (tau - 0.03).abs() < 1e-12,
                "tau of agent 3 at step {step}: {tau}"
            );
            after_delay += 1;
        }
    }
    assert!(after_fault > 0 && after_delay > 0);

    // The run is gone from the registry once it has ended.
    assert_eq!(ps_json(&runs)["runs"], serde_json::json!([]));
}

/// Starts a run of 600 s (killed when the test ends) with its own runs directory, and waits until
/// `ps` lists its 5 agents; returns the test's directory, the runs directory and the run.
fn start_long_run(tag: &str) -> (formation_tests::TempDir, PathBuf, RunningRun) {
    let dir = temp_dir(tag);
    let runs = dir.join("runs");
    let run = RunningRun::start_with_env(
        &["--set", "simulation.duration_s=600"],
        &dir.join("out"),
        &[("FORMATION_RUNS_DIR", &runs)],
    );
    wait_listed(&runs, &run, 5);
    (dir, runs, run)
}

#[test]
fn rejected_injections_exit_2_and_change_nothing() {
    let (dir, runs, run) = start_long_run("inspect-reject");
    let cases: [(&[&str], &str); 6] = [
        (
            &[
                "inject",
                "fault",
                "--agent",
                "6",
                "--gamma",
                "0.5,0.5,0.5",
                "--delta",
                "0,0,0",
            ],
            "--agent",
        ),
        (
            &[
                "inject",
                "fault",
                "--agent",
                "0",
                "--gamma",
                "0.5,0.5,0.5",
                "--delta",
                "0,0,0",
            ],
            "--agent",
        ),
        (
            &[
                "inject",
                "fault",
                "--agent",
                "2",
                "--gamma",
                "1.5,0.5,0.5",
                "--delta",
                "0,0,0",
            ],
            "--gamma",
        ),
        (
            &[
                "inject",
                "fault",
                "--agent",
                "2",
                "--gamma",
                "0.5,0.5,0.5",
                "--delta",
                "100,0,0",
            ],
            "--delta",
        ),
        (
            &["inject", "delay", "--agent", "2", "--tau", "0.2"],
            "tau_M",
        ),
        (
            &[
                "inject",
                "delay",
                "--agent",
                "2",
                "--tau",
                "0.02+0.01*cos(t)",
            ],
            "--tau",
        ),
    ];
    for (args, field) in cases {
        let o = formation(&runs, args);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {}", stderr(&o));
        assert!(
            stderr(&o).contains(field),
            "{args:?} names {field}: {}",
            stderr(&o)
        );
    }
    assert_eq!(
        formation(&runs, &["inspect", "--agent", "6", "--json"])
            .status
            .code(),
        Some(2)
    );
    // Nothing reached the run: no event was recorded.
    let events = std::fs::read_to_string(run.out.join("events.jsonl")).unwrap_or_default();
    assert!(events.trim().is_empty(), "events.jsonl: {events}");
    drop(run);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn ps_json_lists_no_runs_and_forgets_dead_ones() {
    let dir = temp_dir("inspect-none");
    let runs = dir.join("runs");
    assert_eq!(ps_json(&runs), serde_json::json!({ "runs": [] }));
    // A record left behind by an orchestrator that no longer exists is ignored and deleted.
    std::fs::create_dir_all(&runs).unwrap();
    let stale = runs.join("dead.json");
    std::fs::write(
        &stale,
        r#"{"format":"formation-run-record/1","id":"dead","prefix":"fmdead_","out_dir":"/nonexistent","scenario":"paper",
            "variant":"proposed","n_agents":1,"steps":1,"dt_s":0.001,
            "orchestrator_start_ticks":1,"started_unix_s":0.0,
            "processes":[{"role":"orchestrator","agent":null,"pid":4194300}],
            "last_step":0,"steps_per_s":0.0}"#,
    )
    .unwrap();
    assert_eq!(ps_json(&runs), serde_json::json!({ "runs": [] }));
    assert!(!stale.exists());
    for args in [
        &["inspect", "--agent", "1"][..],
        &["inject", "delay", "--agent", "1", "--tau", "0.01"][..],
    ] {
        let o = formation(&runs, args);
        assert_eq!(o.status.code(), Some(2), "{args:?}");
        assert!(stderr(&o).contains("no run is running"), "{}", stderr(&o));
    }
}

#[test]
fn inspect_follow_into_a_pipe_prints_samples_without_escape_sequences() {
    let (dir, runs, run) = start_long_run("inspect-follow-pipe");
    let mut follow = Command::new(bin("formation"))
        .env("FORMATION_RUNS_DIR", &runs)
        .env_remove("CARGO")
        .env_remove("NO_COLOR")
        .args(["inspect", "--agent", "1", "--follow"])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("formation inspect starts");
    let mut stdout = follow.stdout.take().expect("stdout is piped");
    let bytes = std::sync::Arc::new(std::sync::Mutex::new(Vec::new()));
    let sink = bytes.clone();
    let reader = std::thread::spawn(move || {
        let mut buf = [0u8; 4096];
        while let Ok(n) = std::io::Read::read(&mut stdout, &mut buf) {
            if n == 0 {
                break;
            }
            sink.lock().unwrap().extend_from_slice(&buf[..n]);
        }
    });
    let samples = |b: &[u8]| {
        String::from_utf8_lossy(b)
            .matches("controller step")
            .count()
    };
    let start = Instant::now();
    while samples(&bytes.lock().unwrap()) < 2 {
        if start.elapsed() > TIMEOUT {
            let _ = follow.kill();
            panic!("fewer than two samples from inspect --follow");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    // Ctrl-C ends --follow normally.
    // SAFETY: signal to our own child.
    unsafe {
        libc::kill(follow.id() as i32, libc::SIGINT);
    }
    let status = follow.wait().expect("inspect exits");
    reader.join().expect("reader thread");
    let bytes = bytes.lock().unwrap();
    assert!(status.success(), "inspect --follow: {status:?}");
    assert!(
        !bytes.contains(&0x1b),
        "an escape sequence went into the pipe: {:?}",
        String::from_utf8_lossy(&bytes)
    );
    // One block per sample, separated by a blank line.
    assert!(String::from_utf8_lossy(&bytes).contains("\n\nrun "));
    drop(run);
    let _ = std::fs::remove_dir_all(&dir);
}

/// Mean of the three components.
fn mean3(v: [f64; 3]) -> f64 {
    (v[0] + v[1] + v[2]) / 3.0
}

#[test]
fn inspect_answers_on_a_realtime_run_and_shows_an_injected_fault_in_gamma_hat() {
    let dir = temp_dir("inspect-realtime");
    let runs = dir.join("runs");
    let run = RunningRun::start_with_env(
        &["--realtime", "--set", "simulation.duration_s=40"],
        &dir.join("out"),
        &[("FORMATION_RUNS_DIR", &runs)],
    );
    wait_listed(&runs, &run, 5);
    // The first sample: the service keeps the latest one for a late subscriber, so `inspect`
    // answers at once (the time it took is printed; no timing assertion on a shared machine).
    let start = Instant::now();
    let first = sample_from(&runs, &run, 2, 0.0);
    eprintln!(
        "first realtime sample of agent 2 after {:.3} s: step {}",
        start.elapsed().as_secs_f64(),
        first["step"]
    );
    assert_eq!(first["agent"], 2);
    let timed = Instant::now();
    let again = inspect(&runs, 2).expect("a second inspect answers");
    eprintln!(
        "inspect --agent 2 --json on a realtime run: {:.3} s",
        timed.elapsed().as_secs_f64()
    );
    assert!(again["step"].as_u64() >= first["step"].as_u64());

    // Let the estimator settle (t >= 4 s), then inject Gamma = 0.5 on every axis of agent 2.
    let before = sample_from(&runs, &run, 2, 4.0);
    let gamma_before = mean3(vec3(&before, "gamma_hat"));
    let fault_step = inject_half_gamma_into_agent_2(&runs, "0,0,0");
    assert!(fault_step > before["step"].as_u64().unwrap());
    // Gamma-hat moves towards 0.5 while the run flies on: a later sample is well below the value
    // before the injection.
    let mut lowest = gamma_before;
    while run.role_processes().len() == 7 && lowest > gamma_before - 0.1 {
        if let Some(s) = inspect(&runs, 2) {
            if s["step"].as_u64().unwrap() > fault_step {
                lowest = lowest.min(mean3(vec3(&s, "gamma_hat")));
            }
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    assert!(
        lowest < gamma_before - 0.1,
        "mean Gamma-hat of agent 2: {gamma_before} before the injection of 0.5, lowest after {lowest}"
    );
    // A crash is not scheduled on the wall clock: the run rejects it with its reason (exit 2),
    // and no process is killed.
    let o = formation(&runs, &["inject", "crash", "--agent", "3", "--down", "1"]);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains("needs a lockstep run"), "{err}");
    assert_eq!(run.role_processes().len(), 7, "nothing was killed");
    drop(run);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn an_injection_into_a_recording_run_is_an_event_of_run_mcap_and_inject_json_prints_its_step() {
    let dir = temp_dir("inject-mcap");
    let runs = dir.join("runs");
    let mut run = RunningRun::start_with_env(
        &["--set", "simulation.duration_s=600", "--record", "mcap"],
        &dir.join("out"),
        &[("FORMATION_RUNS_DIR", &runs)],
    );
    let listed = wait_listed(&runs, &run, 5);
    let o = formation(
        &runs,
        &[
            "inject",
            "fault",
            "--agent",
            "2",
            "--gamma",
            "0.5,0.6,0.7",
            "--delta",
            "0.1,0,0",
            "--json",
        ],
    );
    assert!(o.status.success(), "inject failed: {}", stderr(&o));
    let applied: Value =
        serde_json::from_str(stdout(&o).trim()).expect("inject --json prints one JSON object");
    assert_eq!(applied["event"], "fault", "{applied}");
    assert_eq!(applied["agent"], 2, "{applied}");
    assert_eq!(applied["run"], listed["id"], "{applied}");
    assert_eq!(applied["gamma"], serde_json::json!([0.5, 0.6, 0.7]));
    let step = applied["step"].as_u64().expect("the step it applies at");
    assert_eq!(applied["t"].as_f64(), Some(step as f64 * 0.001));

    // Let the run pass that step, then stop it (Ctrl-C finishes the outputs, run.mcap included).
    let start = Instant::now();
    while inspect(&runs, 1)
        .and_then(|s| s["step"].as_u64())
        .unwrap_or(0)
        <= step + 100
    {
        assert!(
            start.elapsed() < TIMEOUT,
            "the run stalled: {}",
            run.stderr()
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    run.signal(libc::SIGINT);
    let (st, _) = run.wait(TIMEOUT).expect("the run stops on Ctrl-C");
    assert_eq!(st.code(), Some(130), "{}", run.stderr());

    let bytes = std::fs::read(dir.join("out/run.mcap")).expect("run.mcap is written");
    let mut events = Vec::new();
    // Gamma of agent 2 at the first output step from the applied step on, and just before it.
    let (mut after, mut before) = (None::<(u64, Value)>, None::<(u64, Value)>);
    for m in mcap::MessageStream::new(&bytes).expect("run.mcap parses") {
        let m = m.expect("every message parses");
        if m.channel.message_encoding != "json" {
            continue; // the 3D scene's channels (Foxglove's protobuf schemas, docs/foxglove.md)
        }
        let v: Value = serde_json::from_slice(&m.data).expect("JSON messages");
        match m.channel.topic.as_str() {
            "/events" => events.push((m.log_time, v)),
            "/agent/2/truth" => {
                let k = v["step"].as_u64().expect("a step");
                let slot = if k >= step { &mut after } else { &mut before };
                let closer = slot
                    .as_ref()
                    .is_none_or(|(s, _)| if k >= step { k < *s } else { k > *s });
                if closer {
                    *slot = Some((k, v["gamma"].clone()));
                }
            }
            _ => {}
        }
    }
    assert_eq!(events.len(), 1, "{events:?}");
    let (log_time, event) = &events[0];
    assert_eq!(
        *log_time,
        step * 1_000_000,
        "logged at the step it applies, in ns"
    );
    assert_eq!(event["kind"], "fault");
    assert_eq!(event["agent"], 2);
    assert_eq!(event["step"], step);
    assert_eq!(event["gamma"], serde_json::json!([0.5, 0.6, 0.7]));
    assert!(event.get("nonce").is_none() && event.get("wall_time_unix_s").is_none());
    // The plant's truth in run.mcap shows the fault from that step on, and not before.
    let injected = serde_json::json!([0.5, 0.6, 0.7]);
    assert_eq!(after.expect("an output step after it").1, injected);
    assert_ne!(before.expect("an output step before it").1, injected);
    let _ = std::fs::remove_dir_all(&dir);
}
