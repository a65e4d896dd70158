//! End to end over the network: a lockstep run exports its telemetry with `--zenoh-listen` on a
//! loopback port, and a real Python process with the PyPI Zenoh binding (`eclipse-zenoh`, through
//! `formation_client.net`) reads it as a machine without iceoryx2 would:
//! * the info queryable names the run, N, dt and the wire type, size and field offsets of the
//!   states, equal to the Rust ones;
//! * every state it decodes equals, float for float, the same step's row of `trajectory.csv`,
//!   and a step record holds N quadrotors;
//! * the run exits 0, stays byte-identical to `formation sim`, and leaves nothing in /dev/shm.
//!
//! The interpreter is `$FORMATION_PYTHON` with `eclipse-zenoh` (`.ci/run` installs
//! `./clients/python[net]` into its venv); without it the test is skipped with the reason, unless
//! `FORMATION_REQUIRE_PYTHON=1` (CI): then it fails.

use formation_config::protocol::layout::WireLayout;
use formation_config::protocol::wire::VehicleState;
use formation_runtime::record::table::Trajectory;
use formation_tests::run::RunningRun;
use formation_tests::wire::{assert_state_is_row, from_raw, rows_by_agent_and_step};
use formation_tests::{formation, python_or_skip, stderr_of, temp_dir, workspace_root};
use serde_json::Value;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Duration;

/// Generous bound for anything to happen; reaching it means a hang.
const TIMEOUT: Duration = Duration::from_secs(180);

/// Simulated duration of the exported run, s.
const DURATION: &str = "simulation.duration_s=10";

/// States of every agent the reader checks (at steps `trajectory.csv` records).
const STATES_PER_AGENT: &str = "3";

/// `trajectory.csv` records every this many steps (100 Hz at dt = 1 ms).
const CSV_EVERY: &str = "10";

/// The Python with `formation_client` importable from this tree and the Zenoh binding, or
/// `None` when the test is skipped.
fn python_with_zenoh(test: &str) -> Option<PathBuf> {
    let py = python_or_skip(test)?;
    let o = python(&py)
        .args(["-c", "import zenoh, formation_client.net"])
        .output()
        .expect("python starts");
    if !o.status.success() {
        let why = format!(
            "{} cannot import the Zenoh binding (`pip install './clients/python[net]'`): {}",
            py.display(),
            String::from_utf8_lossy(&o.stderr).trim()
        );
        return formation_tests::skip_python_test(test, &why);
    }
    Some(py)
}

fn python(py: &Path) -> Command {
    let mut c = Command::new(py);
    c.env("PYTHONPATH", workspace_root().join("clients/python"))
        .env_remove("CARGO");
    c
}

/// A loopback port nothing listens on now.
fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .expect("a free loopback port")
        .port()
}

#[test]
fn a_python_reader_over_zenoh_gets_the_info_and_exactly_the_recorded_states() {
    let Some(py) = python_with_zenoh("python_zenoh") else {
        return;
    };
    let dir = temp_dir("python-zenoh");
    let runs = dir.join("runs");
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    // The reader first: it retries until the run listens, so it is there from the first steps.
    let mut reader = python(&py)
        .arg(workspace_root().join("tests/python/net_reader.py"))
        .args([&endpoint, STATES_PER_AGENT, CSV_EVERY])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("the Python reader starts");
    let lines = BufReader::new(reader.stdout.take().expect("piped"));
    let collect = std::thread::spawn(move || {
        lines
            .lines()
            .map_while(Result::ok)
            .map(|l| serde_json::from_str::<Value>(&l).expect("the reader prints JSON"))
            .collect::<Vec<Value>>()
    });
    let mut run = RunningRun::start_with_env(
        &["--set", DURATION, "--zenoh-listen", &endpoint],
        &dir.join("out"),
        &[("FORMATION_RUNS_DIR", &runs)],
    );
    let id = run.id().expect("the run starts");
    let prefix = run.prefix().expect("the run names its prefix");
    let (status, _) = run.wait(TIMEOUT).expect("the run finishes");
    assert!(status.success(), "run failed: {}", run.stderr());
    let ended = reader.wait().expect("the reader exits");
    let mut err = String::new();
    if let Some(mut e) = reader.stderr.take() {
        let _ = std::io::Read::read_to_string(&mut e, &mut err);
    }
    let read = collect.join().expect("reader lines");
    assert!(ended.success(), "the reader failed: {err}\n{read:?}");

    // The info: this run, its N and dt, the state's wire type with the Rust size and offsets.
    let info = &read.first().expect("the reader printed")["info"];
    assert_eq!(info["run_id"], id.as_str(), "{info}");
    assert_eq!(
        (info["n_agents"].as_u64(), info["dt_s"].as_f64()),
        (Some(5), Some(0.001))
    );
    let keys = info["keys"].as_array().expect("keys");
    let state = keys
        .iter()
        .find(|k| k["topic"] == "state")
        .expect("state key");
    assert_eq!(state["key"], format!("formation/{id}/state/<agent>"));
    assert_eq!(state["type_name"], "formation.v3.VehicleState");
    assert_eq!(state["size"], size_of::<VehicleState>());
    let layout = info["types"]
        .as_array()
        .unwrap()
        .iter()
        .find(|t| t["type"] == "VehicleState")
        .expect("VehicleState's layout");
    for (f, rust) in layout["fields"]
        .as_array()
        .unwrap()
        .iter()
        .zip(VehicleState::FIELDS)
    {
        assert_eq!(
            (f["name"].as_str(), f["offset"].as_u64()),
            (Some(rust.name), Some(rust.offset as u64))
        );
    }

    // Every state read over Zenoh equals the recorded row of its step, float for float.
    let tr = Trajectory::read(&run.out.join("trajectory.csv")).unwrap();
    let rows = rows_by_agent_and_step(&tr);
    let mut per_agent = [0usize; 5];
    for v in read.iter().filter(|v| v.get("state").is_some()) {
        let s: VehicleState = from_raw(v);
        let agent = s.agent as usize + 1;
        let r = rows
            .get(&(agent, s.step))
            .unwrap_or_else(|| panic!("row of agent {agent} at step {}", s.step));
        assert_state_is_row(&tr, r, &s);
        per_agent[agent - 1] += 1;
    }
    assert!(
        per_agent.iter().all(|&k| k == 3),
        "states per agent: {per_agent:?}"
    );
    // A step record holds every quadrotor, at finite positions.
    let record = read
        .iter()
        .find(|v| v.get("steps").is_some())
        .expect("a step record");
    assert_eq!(record["n"], 5);
    for p in record["positions"].as_array().unwrap() {
        assert!(p
            .as_array()
            .unwrap()
            .iter()
            .all(|x| x.as_f64().is_some_and(f64::is_finite)));
    }
    let end = &read.last().unwrap()["end"];
    eprintln!("reader over Zenoh: {end}");

    // Nothing of the run is left in shared memory, and the export did not disturb the lockstep.
    let left: Vec<String> = std::fs::read_dir("/dev/shm")
        .map(|d| {
            d.flatten()
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .filter(|n| n.starts_with(&prefix))
                .collect()
        })
        .unwrap_or_default();
    assert!(left.is_empty(), "left in /dev/shm: {left:?}");
    formation_tests::assert_trajectory_is_sims(&run.out, &["--set", DURATION], &dir.join("sim"));
    drop(run);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn an_export_beyond_loopback_without_auth_is_refused_before_the_run_starts() {
    let dir = temp_dir("zenoh-wide");
    let o = formation(&[
        "run",
        "--zenoh-listen",
        "tcp/0.0.0.0:7448",
        "--out",
        dir.join("out").to_str().unwrap(),
    ]);
    let err = stderr_of(&o);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(
        err.contains("--zenoh-listen") && err.contains("requires authentication"),
        "{err}"
    );
    assert!(
        !dir.join("out").join("trajectory.csv").exists(),
        "nothing ran"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// Starts `tests/python/net_last_step.py` against `endpoint`: its one JSON line, once it exits.
fn last_step_reader(py: &Path, endpoint: &str) -> std::thread::JoinHandle<(bool, String, String)> {
    let child = python(py)
        .arg(workspace_root().join("tests/python/net_last_step.py"))
        .arg(endpoint)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("the Python reader starts");
    std::thread::spawn(move || {
        let o = child.wait_with_output().expect("the reader exits");
        (
            o.status.success(),
            String::from_utf8_lossy(&o.stdout).into_owned(),
            String::from_utf8_lossy(&o.stderr).into_owned(),
        )
    })
}

#[test]
fn a_reader_that_keeps_up_gets_every_quadrotors_last_step_and_the_end_marker() {
    let Some(py) = python_with_zenoh("python_zenoh_last_step") else {
        return;
    };
    let dir = temp_dir("python-zenoh-last");
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let reader = last_step_reader(&py, &endpoint);
    let mut run = RunningRun::start_with_env(
        &["--set", DURATION, "--zenoh-listen", &endpoint],
        &dir.join("out"),
        &[("FORMATION_RUNS_DIR", &dir.join("runs"))],
    );
    let (status, _) = run.wait(TIMEOUT).expect("the run finishes");
    let stderr = run.stderr();
    assert!(status.success(), "run failed: {stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    let (ok, out, err) = reader.join().expect("reader thread");
    assert!(ok, "the reader failed: {err}\n{out}");
    let v: Value = serde_json::from_str(out.trim()).expect("the reader prints JSON");
    eprintln!("reader of every state: {v}");
    let steps = v["info"]["steps"].as_u64().expect("steps");
    for a in 1..=5 {
        assert_eq!(
            v["last"][a.to_string()].as_u64(),
            Some(steps - 1),
            "agent {a}'s last step: {v}"
        );
    }
    // The end marker and summary.json tell the same end: every step put, none missed.
    assert_eq!(v["end"]["recorded"].as_u64(), Some(steps), "{v}");
    assert_eq!(v["end"]["caught_up"], true, "{v}");
    let s: Value =
        serde_json::from_slice(&std::fs::read(run.out.join("summary.json")).expect("summary.json"))
            .unwrap();
    assert_eq!(
        s["export"]["recorded"].as_u64(),
        Some(steps),
        "{}",
        s["export"]
    );
    assert_eq!(
        s["export"]["steps_exported"].as_u64().unwrap()
            + s["export"]["steps_missed"].as_u64().unwrap(),
        steps,
        "{}",
        s["export"]
    );
    assert!(stderr.contains("export: "), "{stderr}");
    drop(run);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_run_that_fails_with_the_export_on_ends_with_its_own_exit_code_and_no_panic() {
    // With a reader when the Zenoh binding is here (its session is torn down with the run's),
    // without one otherwise.
    let py = python_with_zenoh("python_zenoh_failed_run");
    let dir = temp_dir("python-zenoh-failed");
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let reader = py.as_ref().map(|py| last_step_reader(py, &endpoint));
    let mut run = RunningRun::start_with_env(
        &[
            "--set",
            "simulation.duration_s=30",
            "--zenoh-listen",
            &endpoint,
        ],
        &dir.join("out"),
        &[("FORMATION_RUNS_DIR", &dir.join("runs"))],
    );
    run.wait_for_line("formation run: id", Duration::from_secs(60))
        .expect("the run starts");
    let start = std::time::Instant::now();
    let pid = loop {
        match run.agent_pid(1) {
            Some(p) if start.elapsed() > Duration::from_millis(1500) => break p,
            _ if start.elapsed() > Duration::from_secs(60) => panic!("agent 2 never ran"),
            _ => std::thread::sleep(Duration::from_millis(50)),
        }
    };
    // SAFETY: a pid of this run's agent 2, just read.
    unsafe { libc::kill(pid as i32, libc::SIGKILL) };
    let (status, _) = run.wait(TIMEOUT).expect("the run ends");
    let stderr = run.stderr();
    // The default policy stops the run: exit 1, the death named, no thread of it panicked.
    assert_eq!(status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("was killed (SIGKILL)"), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert!(stderr.contains("export: "), "{stderr}");
    if let Some(r) = reader {
        let (_, out, err) = r.join().expect("reader thread");
        assert!(!err.contains("panicked"), "the reader: {err}");
        eprintln!("reader of a failed run: {}", out.trim());
    }
    drop(run);
    let _ = std::fs::remove_dir_all(&dir);
}
