//! End to end: a Rust outside node (this test process) observes a live lockstep run through the
//! observer slots of `formation run --observers K`: K extra subscribers on a state service (one
//! more is refused: the slots are exactly K), a listener on a wake-up event and the run control.
//! It sees the run end (the stop on `formation/run/control`), stays attached past the end without
//! the run failing or deleting its files (the run names it), and the run's trajectory is byte for
//! byte what `formation sim` writes.

use formation_config::node::ipc;
use formation_config::node::ports::{subscriber, Input, Wake};
use formation_config::protocol::messages::{RunControl, CONTROL_STOP};
use formation_config::protocol::services;
use formation_config::protocol::wire::VehicleState;
use formation_tests::run::RunningRun;
use formation_tests::{formation_in, temp_dir};
use std::time::{Duration, Instant};

/// Generous bound for anything to happen; reaching it means a hang.
const TIMEOUT: Duration = Duration::from_secs(180);

/// Simulated duration of the observed run, s: long enough to attach while it runs.
const DURATION: &str = "simulation.duration_s=20";

/// Retries `open` until the run has created its services.
fn opened<T, E: std::fmt::Debug>(mut open: impl FnMut() -> Result<T, E>) -> T {
    let start = Instant::now();
    loop {
        match open() {
            Ok(v) => return v,
            Err(e) if start.elapsed() > TIMEOUT => panic!("cannot attach: {e:?}"),
            Err(_) => std::thread::sleep(Duration::from_millis(2)),
        }
    }
}

#[test]
fn an_outside_node_fills_exactly_k_observer_slots_sees_the_end_and_changes_nothing() {
    let dir = temp_dir("observers");
    let mut run = RunningRun::start_with_env(
        &["--observers", "2", "--set", DURATION],
        &dir.join("run"),
        &[("FORMATION_RUNS_DIR", &dir.join("runs"))],
    );
    let prefix = run.prefix().expect("the run announces its prefix");
    // Attach once `ps` shows recorded steps: every role process has opened its ports by then (the
    // run starts after their hellos), so the third subscriber below is refused for the observer
    // slots, not accepted in the place of agent 1's own.
    let start = Instant::now();
    let listed = || {
        let o = formation_in(&dir.join("runs"), &["ps", "--json"]);
        serde_json::from_slice::<serde_json::Value>(&o.stdout)
            .is_ok_and(|v| v["runs"][0]["last_step"].as_u64().is_some_and(|k| k > 0))
    };
    while !listed() {
        assert!(start.elapsed() < TIMEOUT, "never listed: {}", run.stderr());
        std::thread::sleep(Duration::from_millis(5));
    }
    let node = ipc::node(&prefix, "fm-test-outside").expect("an outside node");
    let state = services::VEHICLE_STATE.at(0);
    let control: Input<RunControl> = opened(|| subscriber(&node, &services::CONTROL.named()));
    let first: Input<VehicleState> = opened(|| subscriber(&node, &state));
    let second: Input<VehicleState> = opened(|| subscriber(&node, &state));
    let third = subscriber::<VehicleState>(&node, &state);
    assert!(
        third.is_err(),
        "a third outside subscriber on {} exceeds --observers 2",
        state.name
    );
    let wake = opened(|| Wake::open(&node, &services::WAKE_AGENT.at(0)));

    let mut states = 0u64;
    let start = Instant::now();
    let stop = loop {
        if let Some(c) = control.receive().expect("control") {
            if c.kind == CONTROL_STOP {
                break *c;
            }
        }
        for sub in [&first, &second] {
            while sub.receive().expect("state").is_some() {
                states += 1;
            }
        }
        // The outside listener sleeps on agent 1's wake-up event like agent 1 does.
        wake.wait(Duration::from_millis(1))
            .expect("wake-up listener");
        assert!(start.elapsed() < TIMEOUT, "no stop: {}", run.stderr());
    };
    assert_eq!(stop.step, 20_000, "the stop carries the recorded steps");
    assert!(states > 0, "the outside subscribers read states");

    // Still attached: the run ends normally and leaves the files the outside node uses to it.
    let (status, _) = run.wait(TIMEOUT).expect("the run ends");
    assert!(status.success(), "run failed: {}", run.stderr());
    assert!(
        run.stderr().contains("outside node(s) still attached to")
            && run.stderr().contains("fm-test-outside"),
        "the run names the outside node: {}",
        run.stderr()
    );
    assert!(!ipc::residue(&prefix).expect("list").is_empty());
    drop((control, first, second, wake, node));
    ipc::remove_residue(&prefix).expect("remove");
    assert!(ipc::residue(&prefix).expect("list").is_empty());

    formation_tests::assert_trajectory_is_sims(&run.out, &["--set", DURATION], &dir.join("sim"));
    drop(run);
    let _ = std::fs::remove_dir_all(&dir);
}
