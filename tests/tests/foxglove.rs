//! End to end: the Foxglove view of a run, read by Foxglove's own clients.
//!
//! * Live: `formation run --foxglove 127.0.0.1:0` (lockstep and realtime) prints the address it
//!   serves; the npm client `@foxglove/ws-protocol` (run with node: `tests/js/foxglove_client.mjs`)
//!   joins, subscribes to every advertised channel and decodes each message with the schema the
//!   server sent. Its scene and plot channels arrive, and every pose it received is the position
//!   of `trajectory.csv` at the same step.
//! * Recorded: the scene channels of `run.mcap` decode with Foxglove's schemas from PyPI
//!   (`foxglove-schemas-protobuf`, `tests/python/mcap_scene_check.py`); the events of the run are
//!   logged at their steps and marked from the first scene frame at or after them; links are
//!   coloured by state; a lockstep run and `formation sim` write the same bytes.
//!
//! Node: `$FORMATION_NODE` (default `node`) with `tests/js/node_modules` installed (`npm ci` in
//! tests/js). Python: `$FORMATION_PYTHON` with `mcap` and `foxglove-schemas-protobuf`. Without
//! them a test is skipped with the reason on stderr, unless `FORMATION_REQUIRE_NODE=1` /
//! `FORMATION_REQUIRE_PYTHON=1` (set by `.ci/run`): then it fails.

use formation_runtime::record::csv::Column;
use formation_tests::run::RunningRun;
use formation_tests::{sim, temp_dir, workspace_root};
use serde_json::Value;
use std::collections::HashMap;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Duration;

/// Long enough for any run here; a run that takes longer is a hang.
const RUN_TIMEOUT: Duration = Duration::from_secs(180);

/// Says on the process's stderr (the harness swallows `eprintln!` of passing tests) why a test
/// is skipped, or fails when `require` is set to 1.
fn skip_or_fail(test: &str, require: &str, why: &str) {
    if std::env::var(require).as_deref() == Ok("1") {
        panic!("{test}: {require}=1 but {why}");
    }
    let _ = writeln!(std::io::stderr(), "{test}: SKIPPED: {why}");
}

/// The node executable and the folder of the client script, with its packages installed.
fn node(test: &str) -> Option<(PathBuf, PathBuf)> {
    let js = workspace_root().join("tests/js");
    let node = std::env::var_os("FORMATION_NODE")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from("node"));
    let why = match Command::new(&node).arg("--version").output() {
        Err(e) => format!("cannot start {}: {e}", node.display()),
        Ok(_) if !js.join("node_modules/@foxglove/ws-protocol").is_dir() => {
            "tests/js/node_modules is not installed (`npm ci` in tests/js)".to_string()
        }
        Ok(_) => return Some((node, js)),
    };
    skip_or_fail(test, "FORMATION_REQUIRE_NODE", &why);
    None
}

/// A Python with `mcap` and `foxglove-schemas-protobuf`.
fn python(test: &str) -> Option<PathBuf> {
    let why = match std::env::var_os("FORMATION_PYTHON") {
        None => "FORMATION_PYTHON is not set".to_string(),
        Some(py) => {
            let o = Command::new(&py)
                .args(["-c", "import mcap.reader, foxglove_schemas_protobuf"])
                .output();
            match o {
                Ok(o) if o.status.success() => return Some(PathBuf::from(py)),
                Ok(o) => format!(
                    "it cannot import mcap and foxglove_schemas_protobuf: {}",
                    String::from_utf8_lossy(&o.stderr).trim()
                ),
                Err(e) => format!("cannot start it: {e}"),
            }
        }
    };
    skip_or_fail(test, "FORMATION_REQUIRE_PYTHON", &why);
    None
}

/// `trajectory.csv` as (step, agent) -> column -> value.
fn trajectory(dir: &Path) -> HashMap<(u64, u64), HashMap<Column, f64>> {
    let text = std::fs::read_to_string(dir.join("trajectory.csv")).expect("trajectory.csv");
    let mut lines = text.lines();
    let header: Vec<Column> = lines
        .next()
        .expect("a header")
        .split(',')
        .map(|name| Column::named(name).expect("a column of trajectory.csv"))
        .collect();
    let mut rows = HashMap::new();
    for line in lines {
        let row: HashMap<Column, f64> = header
            .iter()
            .zip(line.split(','))
            .map(|(&c, v)| (c, v.parse::<f64>().unwrap_or(f64::NAN)))
            .collect();
        rows.insert((row[&Column::Step] as u64, row[&Column::Agent] as u64), row);
    }
    rows
}

/// Starts `formation run ARGS --foxglove 127.0.0.1:0`, joins it with the node client and returns
/// the client's report and the run directory once both ended.
fn live_run_seen_by_node(test: &str, args: &[&str], dir: &Path) -> Option<(Value, PathBuf)> {
    let (node, js) = node(test)?;
    let out = dir.join("run");
    // The run waits for the client before it starts (a lockstep run lasts a few seconds).
    let mut all = vec!["--foxglove", "127.0.0.1:0", "--foxglove-wait", "60"];
    all.extend_from_slice(args);
    let mut run = RunningRun::start(&all, &out);
    let line = run
        .wait_for_line("foxglove: live view on ws://", Duration::from_secs(60))
        .unwrap_or_else(|| panic!("no address printed: {}", run.stderr()));
    let url = line
        .split_whitespace()
        .find(|w| w.starts_with("ws://"))
        .expect("a ws:// address")
        .to_string();
    assert!(!url.ends_with(":0"), "the bound port is printed: {url}");
    let client = Command::new(node)
        .arg(js.join("foxglove_client.mjs"))
        .arg(&url)
        .arg("150")
        .current_dir(&js)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("node starts");
    let (st, _) = run.wait(RUN_TIMEOUT).expect("the run ends");
    assert!(st.success(), "formation run failed: {}", run.stderr());
    let o = client.wait_with_output().expect("the client ends");
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "client: {stdout}\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let report: Value = serde_json::from_str(stdout.trim()).expect("one JSON object");
    Some((report, out))
}

/// The assertions both live tests share: channels, their schemas, entities, and every pose and
/// plot equal to `trajectory.csv` at the same step.
fn check_live_report(report: &Value, out: &Path) {
    assert_eq!(
        report["errors"],
        serde_json::json!([]),
        "{}",
        report["errors"]
    );
    assert!(
        report["subprotocol"]
            .as_str()
            .is_some_and(|p| p.starts_with("foxglove.")),
        "{}",
        report["subprotocol"]
    );
    let channels: HashMap<&str, (&str, &str)> = report["channels"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| {
            (
                c["topic"].as_str().unwrap(),
                (
                    c["schemaName"].as_str().unwrap(),
                    c["encoding"].as_str().unwrap(),
                ),
            )
        })
        .collect();
    assert_eq!(channels["/tf"], ("foxglove.FrameTransforms", "protobuf"));
    for t in [
        "/scene/agents",
        "/scene/mission",
        "/scene/links",
        "/scene/events",
    ] {
        assert_eq!(channels[t], ("foxglove.SceneUpdate", "protobuf"), "{t}");
    }
    assert_eq!(channels["/log"], ("foxglove.Log", "protobuf"));
    for i in 1..=5 {
        assert_eq!(
            channels[format!("/agent/{i}/plot").as_str()],
            ("formation.AgentPlot", "json")
        );
    }
    let counts = &report["counts"];
    for t in [
        "/tf",
        "/scene/agents",
        "/scene/mission",
        "/scene/links",
        "/agent/3/plot",
    ] {
        assert!(counts[t].as_u64().unwrap_or(0) >= 5, "{t}: {counts}");
    }
    let ids = |t: &str| -> Vec<String> {
        report["entities"][t]
            .as_array()
            .unwrap_or_else(|| panic!("no entities on {t}"))
            .iter()
            .map(|v| v.as_str().unwrap().to_string())
            .collect()
    };
    let agents = ids("/scene/agents");
    for want in ["quad/1", "quad/5", "trail/3", "footprint/2", "error/4"] {
        assert!(agents.iter().any(|i| i == want), "{want} in {agents:?}");
    }
    let mission = ids("/scene/mission");
    for want in ["target", "leader", "slots"] {
        assert!(mission.iter().any(|i| i == want), "{want} in {mission:?}");
    }
    assert!(ids("/scene/links").iter().any(|i| i == "graph"));

    let rows = trajectory(out);
    let dt_ns = 1_000_000u64;
    let mut compared = 0;
    for tf in report["tf"].as_array().unwrap() {
        let stamp = tf["stamp_ns"].as_u64().unwrap();
        assert_eq!(stamp, tf["log_time_ns"].as_u64().unwrap());
        assert_eq!(stamp % dt_ns, 0);
        let step = stamp / dt_ns;
        assert_eq!(step % 40, 0, "scene frames every 40 steps");
        assert_eq!(tf["parent"], "world");
        let agent: u64 = tf["child"].as_str().unwrap()["agent/".len()..]
            .parse()
            .unwrap();
        let row = &rows[&(step, agent)];
        let got: Vec<f64> = serde_json::from_value(tf["translation"].clone()).unwrap();
        assert_eq!(
            got,
            vec![row[&Column::Px], row[&Column::Py], row[&Column::Pz]],
            "step {step} agent {agent}"
        );
        compared += 1;
    }
    assert!(compared >= 25, "{compared} poses compared");
    for p in report["plots"].as_array().unwrap() {
        let (step, agent) = (p["step"].as_u64().unwrap(), p["agent"].as_u64().unwrap());
        let row = &rows[&(step, agent)];
        let pos: Vec<f64> = serde_json::from_value(p["position"].clone()).unwrap();
        assert_eq!(
            pos,
            vec![row[&Column::Px], row[&Column::Py], row[&Column::Pz]]
        );
        assert_eq!(
            p["formation_error_m"].as_f64().unwrap(),
            row[&Column::ENorm]
        );
        assert_eq!(p["gamma_hat"][0].as_f64().unwrap(), row[&Column::GammaHatX]);
        assert_eq!(p["log_time_ns"].as_u64().unwrap(), step * dt_ns);
    }
}

#[test]
fn a_foxglove_ws_protocol_client_joins_a_lockstep_run_and_its_poses_are_trajectory_csv() {
    let test = "a_foxglove_ws_protocol_client_joins_a_lockstep_run";
    let dir = temp_dir("foxglove-lockstep");
    let args = ["--set", "simulation.duration_s=10"];
    let Some((report, out)) = live_run_seen_by_node(test, &args, &dir) else {
        return;
    };
    check_live_report(&report, &out);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_foxglove_ws_protocol_client_joins_a_realtime_run_and_its_poses_are_trajectory_csv() {
    let test = "a_foxglove_ws_protocol_client_joins_a_realtime_run";
    let dir = temp_dir("foxglove-realtime");
    let args = ["--realtime", "--set", "simulation.duration_s=4"];
    let Some((report, out)) = live_run_seen_by_node(test, &args, &dir) else {
        return;
    };
    check_live_report(&report, &out);
    let _ = std::fs::remove_dir_all(&dir);
}

/// The events of the recorded runs: a link cut and restored, a crash, an actuator fault.
const EVENTS: &str = r#"
[[events]]
at_s = 0.5
kind = "link_down"
agents = [1, 2]

[[events]]
at_s = 1.0
kind = "crash"
agent = 3
down_s = 0.3

[[events]]
at_s = 1.2
kind = "link_up"
agents = [1, 2]

[[events]]
at_s = 1.5
kind = "fault"
agent = 2
gamma = [0.6, 0.6, 0.6]
delta = [0.0, 0.0, 0.05]
"#;

#[test]
fn run_mcap_scene_channels_decode_with_foxglove_schemas_and_mark_events_at_their_steps() {
    let dir = temp_dir("foxglove-mcap");
    let events = dir.join("events.toml");
    std::fs::write(&events, EVENTS).unwrap();
    let events = events.to_str().unwrap();
    let args = [
        "--set",
        "simulation.duration_s=2.5",
        "--events",
        events,
        "--record",
        "mcap",
    ];
    let mut run = RunningRun::start(&args, &dir.join("lockstep"));
    let (st, _) = run.wait(RUN_TIMEOUT).expect("the run ends");
    assert!(st.success(), "formation run failed: {}", run.stderr());
    sim(&args, &dir.join("sim"));
    let a = std::fs::read(dir.join("lockstep/run.mcap")).expect("the run wrote run.mcap");
    let b = std::fs::read(dir.join("sim/run.mcap")).expect("sim wrote run.mcap");
    assert!(a == b, "run.mcap of the run and of sim differ");

    let Some(py) = python("run_mcap_scene_channels_decode_with_foxglove_schemas") else {
        return;
    };
    let script = workspace_root().join("tests/python/mcap_scene_check.py");
    let o = Command::new(py)
        .arg(script)
        .arg(dir.join("lockstep"))
        .output()
        .expect("python starts");
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "mcap_scene_check.py: {stdout}\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let r: Value = serde_json::from_str(stdout.trim()).expect("one JSON object");
    assert_eq!(r["decode_failures"], 0, "{r}");
    assert_eq!(r["schema_mismatches"], serde_json::json!([]), "{r}");
    assert_eq!(r["tf_mismatches"], serde_json::json!([]), "{r}");
    // 2.5 s at 25 Hz: frames at steps 0, 40, ..., 2480; 5 transforms each.
    let frames = 63;
    assert_eq!(r["tf_compared"], 5 * frames, "{r}");
    assert_eq!(r["plots_compared"], 5 * frames, "{r}");
    for t in [
        "/tf",
        "/scene/agents",
        "/scene/mission",
        "/scene/links",
        "/scene/events",
    ] {
        assert_eq!(r["counts"][t], frames, "{t}: {}", r["counts"]);
    }
    assert_eq!(r["channels"]["/scene/agents"][0], "foxglove.SceneUpdate");

    // /log: each event once, at its own step (t = step x 1 ms).
    let logs: Vec<(u64, String)> = r["logs"]
        .as_array()
        .unwrap()
        .iter()
        .map(|l| (l[0].as_u64().unwrap(), l[2].as_str().unwrap().to_string()))
        .collect();
    let want = [
        (500, "link 1-2 down"),
        (1000, "crash of agent 3"),
        (1200, "link 1-2 up"),
        (1500, "actuator fault of agent 2"),
    ];
    assert_eq!(logs.len(), want.len(), "{logs:?}");
    for ((time, text), (step, what)) in logs.iter().zip(want) {
        assert_eq!(*time, step * 1_000_000, "{text}");
        assert!(text.contains(what), "{text} should say {what}");
    }
    // /scene/events: a marker from the first scene frame at or after the event's step.
    let first_marked = |label: &str| -> Option<u64> {
        r["events"].as_array().unwrap().iter().find_map(|e| {
            let texts = e[1].as_array().unwrap();
            texts
                .iter()
                .any(|t| t.as_str() == Some(label))
                .then(|| e[0].as_u64().unwrap() / 1_000_000)
        })
    };
    assert_eq!(first_marked("link_down 1-2"), Some(520));
    assert_eq!(first_marked("crash 3"), Some(1000));
    assert_eq!(first_marked("link_up 1-2"), Some(1200));
    assert_eq!(first_marked("fault 2"), Some(1520));
    // /scene/links: edge 1-2 (the first edge) red while cut, amber edges 2-3 and 3-4 while agent
    // 3 is down, all green before.
    let colors_at = |step: u64| -> Vec<Vec<f64>> {
        let l = r["links"]
            .as_array()
            .unwrap()
            .iter()
            .find(|l| l[0].as_u64() == Some(step * 1_000_000))
            .unwrap_or_else(|| panic!("no /scene/links at step {step}"));
        serde_json::from_value(l[1].clone()).unwrap()
    };
    let red = |c: &[f64]| c[0] > 0.8 && c[1] < 0.2;
    let amber = |c: &[f64]| c[0] > 0.8 && c[1] > 0.5 && c[2] < 0.2;
    let green = |c: &[f64]| c[1] > 0.5 && c[0] < 0.3;
    let before = colors_at(400);
    assert!(before.iter().all(|c| green(c)), "{before:?}");
    let cut = colors_at(800);
    assert!(red(&cut[0]) && green(&cut[2]), "{cut:?}");
    let crashed = colors_at(1120);
    assert!(red(&crashed[0]), "{crashed:?}");
    assert!(
        amber(&crashed[2]) && amber(&crashed[4]),
        "edges 2-3, 3-4: {crashed:?}"
    );
    assert!(green(&crashed[6]), "edge 4-5: {crashed:?}");
    let after = colors_at(1400);
    assert!(after.iter().all(|c| green(c)), "{after:?}");
    let _ = std::fs::remove_dir_all(&dir);
}
