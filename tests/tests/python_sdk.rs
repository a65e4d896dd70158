//! End to end: the Python client SDK installed with `pip install ./clients/python` (no
//! PYTHONPATH: the package as a user gets it) drives a live run.
//!
//! * `python -m formation_client --help` exits 0 and lists its commands; the installed module is
//!   the venv's, and its request kinds are the Rust constants.
//! * Against a live lockstep run: a fault injected with the library (`Run.inject_fault`), a
//!   delay with the command line (`python -m formation_client inject delay`) and a link cut
//!   (`Run.inject_link`) are confirmed by the run, logged in `events.jsonl` like `formation
//!   inject`'s, and act at their steps (the plant's Gamma of agent 2, agent 3's tau in
//!   `trajectory.csv`); the loader reads the run's outputs back as plain Python data.
//!
//! The interpreter is `$FORMATION_PYTHON` (`.ci/run` makes the venv `target/pyenv` and installs
//! `./clients/python` into it). Without it the test is skipped with the reason, unless
//! `FORMATION_REQUIRE_PYTHON=1` (CI): then it fails.

use formation_config::protocol::messages::{
    INJECT_CRASH, INJECT_DELAY, INJECT_FAULT, INJECT_HANG, INJECT_LINK_DOWN, INJECT_LINK_UP,
};
use formation_tests::run::RunningRun;
use formation_tests::{python_or_skip, temp_dir, workspace_root};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

const TIMEOUT: Duration = Duration::from_secs(240);

/// The venv's Python with the SDK installed (not from the source tree), or None when skipped.
fn sdk_python(test: &str) -> Option<PathBuf> {
    let py = python_or_skip(test)?;
    let o = sdk(&py, std::env::temp_dir().as_path())
        .args(["-c", "import formation_client as fc; print(fc.__file__)"])
        .output()
        .expect("python starts");
    let file = String::from_utf8_lossy(&o.stdout).trim().to_string();
    let source = workspace_root().join("clients/python");
    if !o.status.success() || Path::new(&file).starts_with(&source) {
        let why = format!(
            "formation_client is not installed in {} (`pip install ./clients/python`): {}",
            py.display(),
            String::from_utf8_lossy(&o.stderr).trim()
        );
        return formation_tests::skip_python_test(test, &why);
    }
    Some(py)
}

/// `python` run from a neutral folder without PYTHONPATH, with the runs folder `runs`.
fn sdk(py: &Path, runs: &Path) -> Command {
    let mut c = Command::new(py);
    c.env_remove("PYTHONPATH")
        .env("FORMATION_RUNS_DIR", runs)
        .current_dir(std::env::temp_dir());
    c
}

fn json_line(o: &std::process::Output, what: &str) -> Value {
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "{what}: {out}\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    serde_json::from_str(out.trim().lines().last().unwrap_or_default())
        .unwrap_or_else(|e| panic!("{what}: not JSON ({e}): {out}"))
}

#[test]
fn the_installed_sdk_lists_its_commands_and_speaks_the_runs_request_kinds() {
    let Some(py) = sdk_python("the_installed_sdk_lists_its_commands") else {
        return;
    };
    let tmp = std::env::temp_dir();
    let o = sdk(&py, &tmp)
        .args(["-m", "formation_client", "--help"])
        .output()
        .expect("python starts");
    assert!(o.status.success(), "--help exits 0");
    let help = String::from_utf8_lossy(&o.stdout);
    for cmd in ["ps", "inspect", "inject", "summary"] {
        assert!(help.contains(&format!("    {cmd}")), "{cmd} in\n{help}");
    }
    let o = sdk(&py, &tmp)
        .args(["-m", "formation_client", "inject", "--help"])
        .output()
        .expect("python starts");
    let help = String::from_utf8_lossy(&o.stdout);
    for kind in ["fault", "delay", "crash", "hang", "link"] {
        assert!(help.contains(kind), "{kind} in\n{help}");
    }
    let o = sdk(&py, &tmp)
        .args([
            "-c",
            "import json, formation_client.inject as i; print(json.dumps([i.INJECT_FAULT, \
             i.INJECT_DELAY, i.INJECT_CRASH, i.INJECT_HANG, i.INJECT_LINK_DOWN, i.INJECT_LINK_UP, \
             i.INJECT_ASAP]))",
        ])
        .output()
        .expect("python starts");
    let kinds = json_line(&o, "constants");
    assert_eq!(
        kinds,
        serde_json::json!([
            INJECT_FAULT,
            INJECT_DELAY,
            INJECT_CRASH,
            INJECT_HANG,
            INJECT_LINK_DOWN,
            INJECT_LINK_UP,
            formation_config::protocol::messages::INJECT_ASAP
        ])
    );
    // A bad agent is refused before anything is sent (exit 2), without a run.
    let o = sdk(&py, &tmp.join("formation-no-runs-here"))
        .args([
            "-m",
            "formation_client",
            "inject",
            "crash",
            "--agent",
            "1",
            "--down",
            "1",
        ])
        .output()
        .expect("python starts");
    assert_eq!(o.status.code(), Some(2), "no run: exit 2");
}

/// What the SDK does on the live run (library and command line), printed as JSON lines.
const DRIVE: &str = r#"
import json, subprocess, sys
import formation_client as fc
run_dir = sys.argv[1]
with fc.connect(run_dir) as run:
    tel = run.telemetry(2)
    print(json.dumps({"fault": run.inject_fault(2, [0.5, 0.5, 0.5], [0.0, 0.0, 0.1])}), flush=True)
    cli = subprocess.run([sys.executable, "-m", "formation_client", "inject", "delay", "--agent",
                          "3", "--tau", "0.03", "--run", run_dir, "--json"],
                         capture_output=True, text=True)
    print(json.dumps({"delay": json.loads(cli.stdout), "rc": cli.returncode}), flush=True)
    print(json.dumps({"link": run.inject_link(1, 2, up=False)}), flush=True)
    try:
        run.inject_fault(2, [1.5, 0.5, 0.5], [0.0, 0.0, 0.0])
        print(json.dumps({"rejected": False}))
    except fc.InjectRejected as e:
        print(json.dumps({"rejected": True, "why": str(e)}))
"#;

#[test]
fn the_installed_sdk_injects_into_a_live_run_as_formation_inject_does() {
    let Some(py) = sdk_python("the_installed_sdk_injects_into_a_live_run") else {
        return;
    };
    let dir = temp_dir("python-sdk");
    let runs = dir.join("runs");
    let out = dir.join("out");
    let mut run = RunningRun::start_with_env(
        &["--set", "simulation.duration_s=40"],
        &out,
        &[("FORMATION_RUNS_DIR", &runs)],
    );
    run.wait_for_line("run registered", Duration::from_secs(60))
        .unwrap_or_else(|| panic!("the run did not start: {}", run.stderr()));
    let o = sdk(&py, &runs)
        .args(["-c", DRIVE])
        .arg(&out)
        .output()
        .expect("python starts");
    let stdout = String::from_utf8_lossy(&o.stdout).to_string();
    assert!(
        o.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let lines: Vec<Value> = stdout
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let (st, _) = run.wait(TIMEOUT).expect("the run ends");
    assert!(st.success(), "{}", run.stderr());

    let fault = &lines[0]["fault"];
    assert_eq!(fault["event"], "fault");
    assert_eq!(fault["agent"], 2);
    assert_eq!(fault["gamma"], serde_json::json!([0.5, 0.5, 0.5]));
    assert_eq!(lines[1]["rc"], 0, "{}", lines[1]);
    let delay = &lines[1]["delay"];
    assert_eq!(delay["event"], "delay");
    assert_eq!(delay["agent"], 3);
    assert_eq!(delay["base_s"], 0.03);
    assert!(delay["run"].is_string());
    let link = &lines[2]["link"];
    assert_eq!(link["event"], "link_down");
    assert_eq!(link["scenario_event"]["agents"], serde_json::json!([1, 2]));
    assert_eq!(
        lines[3]["rejected"], true,
        "Gamma = 1.5 is refused: {}",
        lines[3]
    );
    assert!(
        lines[3]["why"].as_str().unwrap().contains("gamma"),
        "{}",
        lines[3]
    );

    // The run's log: the same lines it wrote for the SDK's requests.
    let events: Vec<Value> = std::fs::read_to_string(out.join("events.jsonl"))
        .expect("events.jsonl")
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(events.len(), 4, "{events:?}");
    assert_eq!(&events[0], fault);
    assert_eq!(events[3]["event"], "rejected");

    // They act at their steps: Gamma of agent 2 (the plant's truth), tau of agent 3.
    let (fault_step, delay_step) = (
        fault["step"].as_u64().unwrap(),
        delay["step"].as_u64().unwrap(),
    );
    let loaded = sdk(&py, &runs)
        .args([
            "-c",
            "import json, sys, formation_client as fc\n\
             tr = fc.load_trajectory(sys.argv[1]); s = fc.load_summary(sys.argv[1])\n\
             a2, a3 = tr.agent(2), tr.agent(3)\n\
             print(json.dumps({'rows': len(tr), 'agents': tr.agents(), 'step2': a2['step'], \
             'gamma_x2': a2['gamma_x'], 'step3': a3['step'], 'tau3': a3['tau'], \
             'scenario': s['scenario']}))",
        ])
        .arg(&out)
        .output()
        .expect("python starts");
    let t = json_line(&loaded, "loader");
    assert_eq!(t["rows"], 5 * 4000);
    assert_eq!(t["agents"], serde_json::json!([1, 2, 3, 4, 5]));
    assert_eq!(t["scenario"], "paper");
    let (mut after_fault, mut after_delay) = (0, 0);
    for (step, g) in t["step2"]
        .as_array()
        .unwrap()
        .iter()
        .zip(t["gamma_x2"].as_array().unwrap())
    {
        let (step, g) = (step.as_u64().unwrap(), g.as_f64().unwrap());
        if step >= fault_step {
            assert_eq!(g, 0.5, "gamma_x of agent 2 at step {step}");
            after_fault += 1;
        } else {
            assert!(g > 0.5, "gamma_x of agent 2 before the fault, step {step}");
        }
    }
    for (step, tau) in t["step3"]
        .as_array()
        .unwrap()
        .iter()
        .zip(t["tau3"].as_array().unwrap())
    {
        if step.as_u64().unwrap() >= delay_step {
            assert!((tau.as_f64().unwrap() - 0.03).abs() < 1e-12);
            after_delay += 1;
        }
    }
    assert!(after_fault > 0 && after_delay > 0);
    let _ = std::fs::remove_dir_all(&dir);
}
