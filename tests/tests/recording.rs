//! End to end: `--record mcap` writes `DIR/run.mcap`. A lockstep `formation run` and `formation
//! sim` of the same scenario write the same bytes (log times are simulation time), and the file,
//! read by the Python `mcap` package (PyPI; an outside reader nobody here wrote), holds every row of
//! `trajectory.csv` as the per-agent state (`tests/python/mcap_check.py`).
//!
//! The Python interpreter is `$FORMATION_PYTHON` (a venv with `mcap` installed: `.ci/run` makes
//! `target/pyenv`). Without it the Python part is skipped with a message on stderr, unless
//! `FORMATION_REQUIRE_PYTHON=1` (set by `.ci/run`): then it fails.

use formation_tests::run::RunningRun;
use formation_tests::{sim, temp_dir};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

/// Long enough for any run here; a run that takes longer is a hang.
const RUN_TIMEOUT: Duration = Duration::from_secs(120);

/// How `.ci/run` provides the reader.
const INSTALL: &str = "python3 -m venv target/pyenv && target/pyenv/bin/pip install mcap";

/// The Python interpreter with the `mcap` package, or why there is none.
fn find_python() -> Result<PathBuf, String> {
    let python = std::env::var_os("FORMATION_PYTHON")
        .map(PathBuf::from)
        .ok_or("FORMATION_PYTHON is not set")?;
    let probe = Command::new(&python)
        .args(["-c", "import mcap.reader"])
        .output()
        .map_err(|e| format!("cannot start {}: {e}", python.display()))?;
    if !probe.status.success() {
        return Err(format!(
            "{} cannot import mcap: {}",
            python.display(),
            String::from_utf8_lossy(&probe.stderr).trim()
        ));
    }
    Ok(python)
}

/// The interpreter; `None` (after saying so on stderr) when it is missing and not required.
fn python_or_skip() -> Option<PathBuf> {
    match find_python() {
        Ok(p) => Some(p),
        Err(why) if std::env::var("FORMATION_REQUIRE_PYTHON").as_deref() == Ok("1") => panic!(
            "FORMATION_REQUIRE_PYTHON=1 but no Python with `mcap`: {why}. Make one with \
             `{INSTALL}` and set FORMATION_PYTHON=target/pyenv/bin/python (.ci/run does both)"
        ),
        Err(why) => {
            // Straight to the process's stderr: the test harness would swallow `eprintln!`.
            let _ = writeln!(
                std::io::stderr(),
                "SKIPPED the Python mcap reader: {why}; `{INSTALL}` and set FORMATION_PYTHON; \
                 FORMATION_REQUIRE_PYTHON=1 makes this a failure"
            );
            None
        }
    }
}

#[test]
fn lockstep_run_mcap_equals_sim_mcap_byte_for_byte_and_its_states_equal_trajectory_csv() {
    let dir = temp_dir("mcap");
    let args = ["--set", "simulation.duration_s=2", "--record", "mcap"];
    let mut run = RunningRun::start(&args, &dir.join("lockstep"));
    let (st, _) = run.wait(RUN_TIMEOUT).expect("the run ends");
    assert!(st.success(), "formation run failed: {}", run.stderr());
    sim(&args, &dir.join("sim"));
    let a = std::fs::read(dir.join("lockstep/run.mcap")).expect("the run wrote run.mcap");
    let b = std::fs::read(dir.join("sim/run.mcap")).expect("sim wrote run.mcap");
    assert!(a.starts_with(b"\x89MCAP0\r\n"), "MCAP magic");
    assert!(
        a.len() > 100_000,
        "run.mcap is too short: {} bytes",
        a.len()
    );
    assert!(a == b, "run.mcap differs between run and sim");

    let Some(python) = python_or_skip() else {
        return;
    };
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("python/mcap_check.py");
    let out = Command::new(python)
        .arg(&script)
        .arg(dir.join("lockstep"))
        .output()
        .expect("python starts");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "mcap_check.py: {stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let report: serde_json::Value = serde_json::from_str(stdout.trim()).expect("one JSON line");
    // 2 s at 100 Hz: 200 rows per agent, steps 0, 10, ..., 1990.
    assert_eq!(report["rows"], 5 * 200, "{report}");
    assert_eq!(report["states_compared"], 5 * 200, "{report}");
    assert_eq!(report["problems"], 0, "{report}");
    // 5 agents x (state, command, telemetry, truth) + reference + events, and the 3D scene (the
    // orchestrator's default feature `foxglove`): /tf, /scene/{agents,mission,links,events}, /log
    // on Foxglove's protobuf schemas and 5 x /agent/{i}/plot (JSON).
    assert_eq!(report["scene_channels"], 6, "{report}");
    assert_eq!(report["channels"], 22 + 6 + 5, "{report}");
    assert_eq!(report["messages"]["/agent/3/telemetry"], 200, "{report}");
    assert_eq!(report["messages"]["/reference"], 200, "{report}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn without_record_mcap_no_run_mcap_is_written_and_a_stale_one_is_removed() {
    let dir = temp_dir("no-mcap");
    let out = dir.join("sim");
    std::fs::create_dir_all(&out).unwrap();
    std::fs::write(out.join("run.mcap"), b"stale").unwrap();
    sim(&["--set", "simulation.duration_s=0.2"], &out);
    assert!(out.join("trajectory.csv").is_file());
    assert!(!out.join("run.mcap").exists(), "a stale run.mcap stayed");
    let _ = std::fs::remove_dir_all(&dir);
}
