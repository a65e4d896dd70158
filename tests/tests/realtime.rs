//! End to end: `formation run --realtime` with the real binaries reports its timing in
//! `summary.json`, keeps the constraints, and leaves nothing in /dev/shm or /tmp/iceoryx2. No
//! latency thresholds here: the machine is shared and noisy; the speed goals are measured and
//! reported in README.md.

use formation_tests::run::RunningRun;
use formation_tests::temp_dir;
use serde_json::Value;
use std::time::Duration;

/// Long enough for a 5 s realtime run, start-up and stop included.
const RUN_TIMEOUT: Duration = Duration::from_secs(120);

fn t_rt_priority(s: &Value) -> u64 {
    s["timing"]["rt_priority"]
        .as_u64()
        .expect("timing.rt_priority")
}

fn quantiles_are_ordered(t: &Value, key: &str) {
    let q = &t[key];
    let get = |k: &str| {
        q[k].as_f64()
            .unwrap_or_else(|| panic!("timing.{key}.{k} is missing: {q}"))
    };
    let (p50, p99, p999, max) = (get("p50"), get("p99"), get("p999"), get("max"));
    assert!(p50 >= 0.0, "timing.{key}: p50 {p50} < 0");
    assert!(
        p50 <= p99 && p99 <= p999 && p999 <= max,
        "timing.{key} not ordered: {q}"
    );
}

#[test]
fn realtime_run_reports_timing_and_keeps_the_constraints() {
    let dir = temp_dir("realtime");
    let mut run = RunningRun::start(
        &["--realtime", "--set", "simulation.duration_s=5"],
        &dir.join("rt"),
    );
    let prefix = run.prefix().expect("the run announces its prefix");
    let (st, _) = run.wait(RUN_TIMEOUT).expect("the run ends");
    assert!(
        st.success(),
        "formation run --realtime failed: {}",
        run.stderr()
    );
    let text = std::fs::read_to_string(dir.join("rt/summary.json")).expect("summary.json exists");
    let s: Value = serde_json::from_str(&text).expect("summary.json parses");
    assert_eq!(s["mode"], "realtime");
    assert_eq!(s["steps"], 5000);
    let t = &s["timing"];
    // The scheduling is decided, said and recorded: SCHED_FIFO 10 where this process may use it
    // (root here), the normal policy otherwise.
    let stderr = run.stderr();
    let said = stderr
        .lines()
        .find(|l| l.starts_with("formation run: plant and agents under "))
        .unwrap_or_else(|| panic!("the scheduling is said: {stderr}"));
    let fifo = said.contains("SCHED_FIFO 10");
    assert!(fifo || said.contains("normal policy ("), "{said}");
    assert_eq!(t_rt_priority(&s), if fifo { 10 } else { 0 }, "{said}");
    // The host's own timer noise around the run: 2 s before, 2 s after, 1000 periods a second.
    let hp = &s["timing"]["host_probe"];
    assert_eq!(hp["before"]["periods"], 2000, "{hp}");
    assert_eq!(hp["after"]["periods"], 2000, "{hp}");
    assert_eq!(hp["pooled"]["periods"], 4000, "{hp}");
    assert_eq!(hp["late_over_us"], 500, "{hp}");
    assert!(hp["pooled"]["late_fraction"].as_f64().is_some(), "{hp}");
    for key in [
        "state_to_command_latency_us",
        "ipc_hop_latency_us",
        "plant_period_jitter_us",
        "controller_step_us",
    ] {
        quantiles_are_ordered(t, key);
    }
    let per_agent = t["state_to_command_latency_us"]["per_agent"]
        .as_array()
        .expect("per_agent latencies");
    assert_eq!(per_agent.len(), 5);
    let misses = t["deadline_misses"].as_u64().expect("deadline_misses");
    let fraction = t["deadline_miss_fraction"]
        .as_f64()
        .expect("deadline_miss_fraction");
    assert!((0.0..=1.0).contains(&fraction), "fraction {fraction}");
    assert_eq!(misses == 0, fraction == 0.0);
    let agents = s["agents"].as_array().expect("agents");
    assert_eq!(agents.len(), 5);
    for a in agents {
        assert_eq!(a["attitude_constraint_violations"], 0, "{a}");
        assert_eq!(a["rate_constraint_violations"], 0, "{a}");
    }
    assert_eq!(s["diverged"], false);
    // The run itself cleaned up (checked before the guard's own clean-up runs).
    let left = formation_config::node::ipc::residue(&prefix).expect("can list the iceoryx2 files");
    assert!(left.is_empty(), "residue: {left:?}");
    assert!(run.role_processes().is_empty(), "role processes left");
    drop(run);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn rt_priority_0_is_the_normal_policy_and_a_busy_loop_at_a_realtime_priority_is_refused() {
    let dir = temp_dir("realtime-rt0");
    let o = formation_tests::formation(&[
        "run",
        "--realtime",
        "--wait",
        "spin-block",
        "--rt-priority",
        "5",
        "--out",
        dir.join("spin").to_str().unwrap(),
    ]);
    let err = formation_tests::stderr_of(&o);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(
        err.contains("--rt-priority 5") && err.contains("spin-block"),
        "{err}"
    );
    let mut run = RunningRun::start(
        &[
            "--realtime",
            "--rt-priority",
            "0",
            "--set",
            "simulation.duration_s=1",
        ],
        &dir.join("rt0"),
    );
    let (st, _) = run.wait(RUN_TIMEOUT).expect("the run ends");
    let stderr = run.stderr();
    assert!(st.success(), "{stderr}");
    assert!(
        stderr.contains("plant and agents under normal policy (--rt-priority 0)"),
        "{stderr}"
    );
    let s: Value =
        serde_json::from_slice(&std::fs::read(dir.join("rt0/summary.json")).unwrap()).unwrap();
    assert_eq!(t_rt_priority(&s), 0);
    drop(run);
    let _ = std::fs::remove_dir_all(&dir);
}
