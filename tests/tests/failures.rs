//! End to end: the resilient runtime (docs/failures.md). Timeline crashes, hangs, link faults and
//! message loss are steps, so a lockstep `formation run` that really kills, stops and respawns
//! agent processes writes the same trajectory as `formation sim`; agents that die or hang outside
//! the timeline are detected, named and replaced under `--restart on-failure`; a dead plant or
//! leader ends the run, named; nothing is left in /dev/shm.

use formation_runtime::record::csv::Column;
use formation_tests::run::RunningRun;
use formation_tests::{bin, formation, sim, summary, temp_dir, workspace_root};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

const RUN_TIMEOUT: Duration = Duration::from_secs(240);

/// The tests that kill or stop a process on the wall clock and time its detection and take-over
/// run one at a time: on a 2-core machine two 20 s realtime runs beside them would measure the
/// host, not the supervisor.
fn one_at_a_time() -> std::sync::MutexGuard<'static, ()> {
    static LOCK: std::sync::Mutex<()> = std::sync::Mutex::new(());
    LOCK.lock().unwrap_or_else(|e| e.into_inner())
}

/// The paper scenario of `duration_s` with `events` (TOML `[[events]]` tables) appended.
fn scenario_with(dir: &Path, name: &str, duration_s: f64, events: &str) -> PathBuf {
    let mut text = formation_config::scenario::PAPER_TOML
        .replace("duration_s = 60.0", &format!("duration_s = {duration_s}"));
    assert!(text.contains(&format!("duration_s = {duration_s}")));
    text.push('\n');
    text.push_str(events);
    let path = dir.join(format!("{name}.toml"));
    std::fs::write(&path, text).unwrap();
    path
}

fn same_file(a: &Path, b: &Path) -> bool {
    std::fs::read(a).unwrap() == std::fs::read(b).unwrap()
}

fn residue_of(run: &RunningRun) -> Vec<PathBuf> {
    run.prefix()
        .map(|p| formation_config::node::ipc::residue(&p).unwrap())
        .unwrap_or_default()
}

/// The worst `e_norm` of the rows of `csv` (a `trajectory.csv`) with t in [from, to] s.
fn worst_error_between(csv: &Path, from: f64, to: f64) -> f64 {
    let tr = formation_runtime::record::table::Trajectory::read(csv).unwrap();
    tr.rows()
        .iter()
        .filter(|r| (from..=to + 1e-9).contains(&tr.value(r, Column::T)))
        .map(|r| tr.value(r, Column::ENorm))
        .fold(0.0, f64::max)
}

/// Runs `formation run` to its end; returns (exit code, stderr).
fn run_to_end(args: &[&str], out: &Path) -> (i32, String, RunningRun) {
    let mut run = RunningRun::start(args, out);
    let (st, _) = run.wait(RUN_TIMEOUT).expect("the run ends");
    (st.code().unwrap_or(-1), run.stderr(), run)
}

fn wait_stepping(run: &RunningRun) {
    let csv = run.out.join("trajectory.csv");
    let start = Instant::now();
    while std::fs::metadata(&csv).map_or(0, |m| m.len()) < 64 * 1024 {
        assert!(
            start.elapsed() < RUN_TIMEOUT,
            "no progress: {}",
            run.stderr()
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// A warm restart is no worse than a cold one: with the slot failsafe both can stay under the
/// formation's own error in that phase, so the comparison is `<=`, and a warm restart whose peak
/// stays under the worst error the formation has without the crash over the same span (the crash
/// to the return and SETTLE_S after it) adds nothing to compare: the peak is then the mission's
/// own error at the span's end, which a 0.5 s outage moves by tens of micrometres either way.
#[test]
fn a_timeline_crash_restarted_warm_is_byte_identical_to_sim_recovers_and_is_no_worse_than_a_cold_restart(
) {
    let dir = temp_dir("crash-warm");
    let s = scenario_with(
        &dir,
        "crash",
        24.0,
        "[[events]]\nat_s = 20.0\nkind = \"crash\"\nagent = 3\ndown_s = 0.5\n",
    );
    let s = s.to_str().unwrap();
    let sim = dir.join("sim");
    let out = formation(&["sim", s, "--out", sim.to_str().unwrap()]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let (code, stderr, run) = run_to_end(&[s], &dir.join("run"));
    assert_eq!(code, 0, "{stderr}");
    assert!(
        stderr.contains("agent 3 taken over at step 20500") && stderr.contains("warm"),
        "the crash really replaced the process: {stderr}"
    );
    assert!(
        same_file(&sim.join("trajectory.csv"), &dir.join("run/trajectory.csv")),
        "lockstep run with a crash differs from sim"
    );
    let log = std::fs::read_to_string(dir.join("run/logs/agent-3.log")).unwrap();
    assert!(
        log.contains("replayed=500") || log.contains("mismatches=0"),
        "{log}"
    );
    assert!(
        log.contains("mismatches=0"),
        "the replay reproduced every command: {log}"
    );
    let warm = &summary(&dir.join("run"))["events"][0];
    assert_eq!(warm["kind"], "crash");
    let warm_recovery = warm["recovered_after_s"].as_f64().expect("recovered");
    assert!(warm_recovery <= 5.0, "{warm}");
    assert!(warm["restarted_after_ms"].as_f64().is_some(), "{warm}");
    let cold_dir = dir.join("cold");
    let out = formation(&[
        "sim",
        s,
        "--restart-state",
        "cold",
        "--out",
        cold_dir.to_str().unwrap(),
    ]);
    assert!(out.status.success());
    let cold = &summary(&cold_dir)["events"][0];
    let peak = |e: &serde_json::Value| e["peak_error_m"].as_f64().unwrap();
    // The same 24 s without the crash: its worst formation error over the event's span
    // [20 s, 20.5 s + SETTLE_S], from the rows of trajectory.csv (every 10 ms, the span's ends
    // included).
    let quiet = scenario_with(&dir, "quiet", 24.0, "");
    let quiet_dir = dir.join("quiet");
    let out = formation(&[
        "sim",
        quiet.to_str().unwrap(),
        "--out",
        quiet_dir.to_str().unwrap(),
    ]);
    assert!(out.status.success());
    let own = worst_error_between(&quiet_dir.join("trajectory.csv"), 20.0, 22.5);
    assert!(
        warm_recovery <= cold["recovered_after_s"].as_f64().unwrap_or(f64::INFINITY)
            && (peak(warm) <= peak(cold) || peak(warm) <= own),
        "warm {warm} vs cold {cold}; without the crash {own} m"
    );
    assert!(residue_of(&run).is_empty());
}

/// Issue 20's bounds on the two outages of the descent and spin of the enclosing phase where a
/// returning controller meets the largest re-entry error (docs/failures.md, crash-time sweeps):
/// agent 4 down from 44 s for 2 s peaks under 1 m, agent 5 down from 43 s for 0.5 s recovers
/// within 2 s; neither brings two quadrotors closer than the safety distance nor breaks a
/// constraint once its controller is back (the failsafe's disturbance observer holds the slot).
#[test]
fn outages_in_the_descent_and_spin_stay_within_issue_20s_peak_and_recovery_bounds() {
    let dir = temp_dir("rejoin-enclosing");
    let scenario = workspace_root().join("config/scenarios/crash-warm.toml");
    let run = |agent: u32, at_s: u32, down_s: f64| {
        let out = dir.join(format!("{agent}-{at_s}-{down_s}"));
        let (a, t, d) = (
            format!("events[0].agent={agent}"),
            format!("events[0].at_s={at_s}"),
            format!("events[0].down_s={down_s}"),
        );
        let args = [
            scenario.to_str().unwrap(),
            "--set",
            &a,
            "--set",
            &t,
            "--set",
            &d,
        ];
        sim(&args, &out);
        summary(&out)["events"][0].clone()
    };
    let long = run(4, 44, 2.0);
    let short = run(5, 43, 0.5);
    let peak = |e: &serde_json::Value| e["peak_error_m"].as_f64().expect("peak");
    assert!(peak(&long) <= 1.0, "agent 4 down 2 s: {long}");
    let recovered = short["recovered_after_s"].as_f64();
    assert!(
        recovered.is_some_and(|r| r <= 2.0),
        "agent 5 down 0.5 s: {short}"
    );
    for e in [&long, &short] {
        assert_eq!(e["steps_below_safety_during"], 0, "{e}");
        assert_eq!(e["violations_once_back"], 0, "{e}");
    }
}

/// Agent 3 crashes for 2 s and agent 1 hangs for 1 s: the failsafe flies their slots (`slot`,
/// the default) or holds their points (`hold`), with no step below the safety distance and no
/// violation once the controllers are back; the lockstep run writes sim's trajectory byte for byte
/// in both modes; `slot` stays within 1 m and the level hover of the same timeline is far worse.
#[test]
fn the_failsafe_flies_the_slot_or_holds_identically_in_run_and_sim_and_beats_the_level_hover() {
    let dir = temp_dir("failsafe");
    let s = scenario_with(
        &dir,
        "failsafe",
        9.0,
        "[[events]]\nat_s = 4.0\nkind = \"crash\"\nagent = 3\ndown_s = 2.0\n\n[[events]]\nat_s = 6.5\nkind = \"hang\"\nagent = 1\ndown_s = 1.0\n",
    );
    let s = s.to_str().unwrap();
    let mut peaks = Vec::new();
    for mode in ["slot", "hold", "hover"] {
        let set = format!("runtime.fallback=\"{mode}\"");
        let sim = dir.join(format!("sim-{mode}"));
        let o = formation(&["sim", s, "--set", &set, "--out", sim.to_str().unwrap()]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let events = summary(&sim)["events"].as_array().unwrap().clone();
        let peak = events
            .iter()
            .map(|e| e["peak_error_m"].as_f64().unwrap())
            .fold(0.0, f64::max);
        eprintln!("fallback {mode}: {events:?}");
        peaks.push(peak);
        if mode == "hover" {
            continue;
        }
        for e in &events {
            assert_eq!(e["violations_once_back"], 0, "{mode}: {e}");
            assert_eq!(e["steps_below_safety_during"], 0, "{mode}: {e}");
        }
        let run = dir.join(format!("run-{mode}"));
        let (code, stderr, r) = run_to_end(&[s, "--set", &set], &run);
        assert_eq!(code, 0, "{stderr}");
        assert!(
            same_file(&sim.join("trajectory.csv"), &run.join("trajectory.csv")),
            "{mode}: the lockstep run differs from sim"
        );
        assert!(residue_of(&r).is_empty());
    }
    assert!(peaks[0] <= 1.0, "slot: peak {} m", peaks[0]);
    assert!(
        peaks[1] < peaks[2],
        "hold {} m vs hover {} m",
        peaks[1],
        peaks[2]
    );
    assert!(
        peaks[2] > 2.0 * peaks[0],
        "hover {} m vs slot {} m",
        peaks[2],
        peaks[0]
    );
}

#[test]
fn a_killed_agent_is_replaced_under_on_failure_counted_measured_and_the_run_ends_with_exit_0() {
    let _one = one_at_a_time();
    let dir = temp_dir("kill-agent");
    let out = dir.join("run");
    let mut run = RunningRun::start(
        &[
            "--set",
            "simulation.duration_s=30",
            "--restart",
            "on-failure",
        ],
        &out,
    );
    wait_stepping(&run);
    let pid = run.agent_pid(1).expect("agent 2 runs");
    // SAFETY: a pid of this run's agent 2, just read.
    unsafe { libc::kill(pid as i32, libc::SIGKILL) };
    let id = run.id().expect("the run says its id");
    run.wait_for_line("taken over", Duration::from_secs(30))
        .expect("a new process takes over");
    // `formation ps` lists the new process, alive, once it has joined.
    let start = Instant::now();
    let listed = loop {
        let o = formation(&["ps", "--json"]);
        let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap_or_default();
        let agent2 = v["runs"].as_array().and_then(|runs| {
            runs.iter().find(|r| r["id"] == id.as_str()).and_then(|r| {
                r["processes"]
                    .as_array()?
                    .iter()
                    .find(|p| p["agent"] == 2)
                    .cloned()
            })
        });
        match agent2 {
            Some(p) if p["pid"] != pid && p["alive"] == true => break Some(p),
            _ if start.elapsed() > Duration::from_secs(10) => break None,
            _ => std::thread::sleep(Duration::from_millis(100)),
        }
    };
    assert!(listed.is_some(), "ps lists agent 2's new process");
    let (st, _) = run.wait(RUN_TIMEOUT).expect("the run ends");
    let stderr = run.stderr();
    assert_eq!(st.code(), Some(0), "{stderr}");
    assert!(
        stderr.contains(&format!(
            "agent 2 (--agent 1) (pid {pid}) was killed (SIGKILL); restarting it"
        )),
        "{stderr}"
    );
    let s = summary(&out);
    assert_eq!(s["agents"][1]["restarts"], 1);
    let died = s["events"]
        .as_array()
        .unwrap()
        .iter()
        .find(|e| e["kind"] == "died")
        .expect("the death is an event");
    assert_eq!(died["agent"], 2);
    assert!(died["recovered_after_s"].as_f64().is_some(), "{died}");
    assert!(died["restarted_after_ms"].as_f64().is_some(), "{died}");
    assert_eq!(s["diverged"], false);
    assert!(residue_of(&run).is_empty());
}

#[test]
fn a_killed_agent_of_a_realtime_run_is_replaced_on_the_wall_clock_counted_measured_exit_0() {
    let _one = one_at_a_time();
    let dir = temp_dir("kill-agent-realtime");
    let out = dir.join("run");
    let mut run = RunningRun::start(
        &[
            "--realtime",
            "--set",
            "simulation.duration_s=20",
            "--restart",
            "on-failure",
        ],
        &out,
    );
    wait_stepping(&run);
    // Mid-run, with a checkpoint of agent 2 to restore (one per second of the run).
    let ckpt = formation_config::node::restart::checkpoint_path(&out, 1);
    let start = Instant::now();
    while !ckpt.exists() || start.elapsed() < Duration::from_secs(6) {
        assert!(start.elapsed() < RUN_TIMEOUT, "{}", run.stderr());
        std::thread::sleep(Duration::from_millis(50));
    }
    let pid = run.agent_pid(1).expect("agent 2 runs");
    // SAFETY: a pid of this run's agent 2, just read.
    unsafe { libc::kill(pid as i32, libc::SIGKILL) };
    run.wait_for_line("taken over", Duration::from_secs(30))
        .expect("a new process takes over");
    let (st, _) = run.wait(RUN_TIMEOUT).expect("the run ends");
    let stderr = run.stderr();
    assert_eq!(st.code(), Some(0), "{stderr}");
    assert!(
        stderr.contains(&format!(
            "agent 2 (--agent 1) (pid {pid}) was killed (SIGKILL); restarting it"
        )) && stderr.contains("warm"),
        "{stderr}"
    );
    let s = summary(&out);
    assert_eq!(s["mode"], "realtime");
    assert_eq!(s["agents"][1]["restarts"], 1);
    let died = s["events"]
        .as_array()
        .unwrap()
        .iter()
        .find(|e| e["kind"] == "died")
        .expect("the death is an event");
    eprintln!("realtime kill -9 of agent 2: {died}");
    assert_eq!(died["agent"], 2);
    assert!(died["detected_after_ms"].as_f64().is_some(), "{died}");
    assert!(died["restarted_after_ms"].as_f64().is_some(), "{died}");
    assert!(died["recovered_after_s"].as_f64().is_some(), "{died}");
    assert_eq!(s["diverged"], false);
    assert!(residue_of(&run).is_empty());
}

#[test]
fn a_killed_plant_or_leader_ends_the_run_with_a_non_zero_exit_naming_it_even_under_on_failure() {
    for (role, name) in [("plant", "fm-plant"), ("leader", "fm-leader")] {
        let dir = temp_dir(&format!("kill-{role}"));
        let mut run = RunningRun::start(
            &[
                "--set",
                "simulation.duration_s=600",
                "--restart",
                "on-failure",
            ],
            &dir.join("run"),
        );
        wait_stepping(&run);
        let pid = run
            .role_processes()
            .into_iter()
            .find(|p| {
                std::fs::read_to_string(format!("/proc/{p}/comm")).is_ok_and(|c| c.trim() == name)
            })
            .expect("the role process runs");
        // SAFETY: a pid of this run's role process, just read.
        unsafe { libc::kill(pid as i32, libc::SIGKILL) };
        let (st, _) = run.wait(RUN_TIMEOUT).expect("the run ends");
        let stderr = run.stderr();
        assert_eq!(st.code(), Some(1), "{stderr}");
        assert!(
            stderr.contains(&format!("{role} (pid {pid}) was killed (SIGKILL)"))
                && stderr.contains("not restarted"),
            "{stderr}"
        );
        std::thread::sleep(Duration::from_millis(300));
        assert!(run.role_processes().is_empty(), "no orphan");
        assert!(residue_of(&run).is_empty());
    }
}

#[test]
fn a_stopped_agent_is_named_within_1_5_s_replaced_and_the_run_completes() {
    let _one = one_at_a_time();
    let dir = temp_dir("stop-agent");
    let out = dir.join("run");
    let mut run = RunningRun::start(
        &[
            "--set",
            "simulation.duration_s=30",
            "--restart",
            "on-failure",
            "--stall-timeout-ms",
            "1000",
        ],
        &out,
    );
    wait_stepping(&run);
    let pid = run.agent_pid(2).expect("agent 3 runs");
    // SAFETY: a pid of this run's agent 3, just read.
    unsafe { libc::kill(pid as i32, libc::SIGSTOP) };
    let stopped = Instant::now();
    let line = run
        .wait_for_line("made no progress", Duration::from_secs(10))
        .expect("the hang is named");
    let named_after = stopped.elapsed();
    assert!(
        line.contains(&format!("agent 3 (--agent 2) (pid {pid})")),
        "{line}"
    );
    assert!(
        named_after < Duration::from_millis(1500),
        "named after {named_after:?}"
    );
    let (st, _) = run.wait(RUN_TIMEOUT).expect("the run ends");
    assert_eq!(st.code(), Some(0), "{}", run.stderr());
    let s = summary(&out);
    assert_eq!(s["agents"][2]["restarts"], 1);
    assert!(s["events"]
        .as_array()
        .unwrap()
        .iter()
        .any(|e| e["kind"] == "hung"));
    assert!(residue_of(&run).is_empty());
}

#[test]
fn a_stopped_agent_of_a_realtime_run_is_named_by_its_silence_replaced_and_the_run_completes() {
    let _one = one_at_a_time();
    let dir = temp_dir("stop-agent-realtime");
    let out = dir.join("run");
    let mut run = RunningRun::start(
        &[
            "--realtime",
            "--set",
            "simulation.duration_s=20",
            "--restart",
            "on-failure",
            "--stall-timeout-ms",
            "1000",
        ],
        &out,
    );
    wait_stepping(&run);
    std::thread::sleep(Duration::from_secs(4));
    let pid = run.agent_pid(2).expect("agent 3 runs");
    // SAFETY: a pid of this run's agent 3, just read.
    unsafe { libc::kill(pid as i32, libc::SIGSTOP) };
    let stopped = Instant::now();
    let line = run
        .wait_for_line("sent no command", Duration::from_secs(10))
        .expect("the hang is named");
    let named_after = stopped.elapsed();
    eprintln!("realtime SIGSTOP of agent 3 named after {named_after:?}: {line}");
    assert!(
        line.contains(&format!("agent 3 (--agent 2) (pid {pid})")) && line.contains("(stopped)"),
        "{line}"
    );
    assert!(
        named_after < Duration::from_millis(1500),
        "named after {named_after:?}"
    );
    run.wait_for_line("taken over", Duration::from_secs(30))
        .expect("a new process takes over");
    let (st, _) = run.wait(RUN_TIMEOUT).expect("the run ends");
    assert_eq!(st.code(), Some(0), "{}", run.stderr());
    let s = summary(&out);
    assert_eq!(s["agents"][2]["restarts"], 1);
    let hung = s["events"]
        .as_array()
        .unwrap()
        .iter()
        .find(|e| e["kind"] == "hung")
        .expect("the hang is an event");
    eprintln!("realtime SIGSTOP of agent 3: {hung}");
    // The failsafe flies agent 3's slot while it is silent (docs/failures.md).
    let peak = hung["peak_error_m"].as_f64().expect("measured");
    assert!(peak <= 1.5, "peak formation error {peak} m: {hung}");
    let worst = s["agents"]
        .as_array()
        .unwrap()
        .iter()
        .map(|a| a["max_formation_error_m"]["whole"].as_f64().unwrap_or(0.0))
        .fold(0.0, f64::max);
    eprintln!("realtime SIGSTOP of agent 3: worst formation error over the run {worst} m");
    assert_eq!(s["diverged"], false);
    assert!(residue_of(&run).is_empty());
}

#[test]
fn link_faults_and_message_loss_are_flagged_survived_and_identical_in_run_and_sim() {
    let dir = temp_dir("links");
    let link = scenario_with(
        &dir,
        "link",
        14.0,
        "[[events]]\nat_s = 5.0\nkind = \"link_down\"\nagents = [2, 3]\n\n[[events]]\nat_s = 10.0\nkind = \"link_up\"\nagents = [2, 3]\n",
    );
    let loss = scenario_with(
        &dir,
        "loss",
        14.0,
        "[[events]]\nat_s = 0.0\nkind = \"message_loss\"\nprobability = 0.2\nseed = 7\n",
    );
    let clean = scenario_with(&dir, "clean", 14.0, "");
    for (name, s) in [("link", &link), ("loss", &loss), ("clean", &clean)] {
        let out = dir.join(format!("sim-{name}"));
        let o = formation(&["sim", s.to_str().unwrap(), "--out", out.to_str().unwrap()]);
        assert!(
            o.status.success(),
            "{name}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
    }
    let l = summary(&dir.join("sim-link"));
    assert_eq!(
        l["connectivity"]["assumption1_held"], false,
        "the path 1-2-3-4-5 is cut"
    );
    assert_eq!(l["connectivity"]["first_violated_at_s"], 5.0);
    assert_eq!(l["diverged"], false);
    let rms = |v: &serde_json::Value| {
        v["agents"]
            .as_array()
            .unwrap()
            .iter()
            .map(|a| a["rms_formation_error_m"]["whole"].as_f64().unwrap())
            .fold(0.0, f64::max)
    };
    let lossy = summary(&dir.join("sim-loss"));
    let clean = summary(&dir.join("sim-clean"));
    assert_eq!(lossy["diverged"], false);
    eprintln!(
        "worst whole-run RMS: loss-free {:.4} m, 20 % loss {:.4} m, link 2-3 down 5 s {:.4} m",
        rms(&clean),
        rms(&lossy),
        rms(&l)
    );
    assert!(rms(&lossy) < 2.0 * rms(&clean), "loss costs little");
    for (name, s) in [("link", &link), ("loss", &loss)] {
        let (code, stderr, run) =
            run_to_end(&[s.to_str().unwrap()], &dir.join(format!("run-{name}")));
        assert_eq!(code, 0, "{stderr}");
        assert!(
            same_file(
                &dir.join(format!("sim-{name}/trajectory.csv")),
                &dir.join(format!("run-{name}/trajectory.csv"))
            ),
            "{name}: lockstep run differs from sim"
        );
        assert!(residue_of(&run).is_empty());
    }
}

#[test]
fn a_live_run_with_injected_fault_and_crash_replayed_from_its_events_jsonl_is_byte_identical_and_lists_the_same_events(
) {
    let dir = temp_dir("replay");
    let out = dir.join("live");
    let mut run = RunningRun::start(&["--set", "simulation.duration_s=20"], &out);
    wait_stepping(&run);
    let id = run.id().expect("the run says its id");
    let inject = |args: &[&str]| {
        let o = Command::new(bin("formation"))
            .arg("inject")
            .args(args)
            .args(["--run", &id])
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    };
    inject(&[
        "fault",
        "--agent",
        "2",
        "--gamma",
        "0.6,0.6,0.6",
        "--delta",
        "0,0,0.1",
    ]);
    inject(&["crash", "--agent", "4", "--down", "0.4"]);
    let (st, _) = run.wait(RUN_TIMEOUT).expect("the run ends");
    assert_eq!(st.code(), Some(0), "{}", run.stderr());
    assert!(
        run.stderr().contains("agent 4 taken over"),
        "{}",
        run.stderr()
    );
    let events = out.join("events.jsonl");
    let replay = dir.join("replay");
    let o = formation(&[
        "sim",
        "--set",
        "simulation.duration_s=20",
        "--events",
        events.to_str().unwrap(),
        "--out",
        replay.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(
        same_file(&out.join("trajectory.csv"), &replay.join("trajectory.csv")),
        "the replay of the live run's events differs"
    );
    // summary.json's events[]: the live run lists its fault injection (and crash) as the replay does.
    let listed = |d: &Path| -> Vec<(String, serde_json::Value, String)> {
        summary(d)["events"]
            .as_array()
            .unwrap()
            .iter()
            .map(|e| {
                (
                    e["kind"].as_str().unwrap_or("").to_string(),
                    e["agent"].clone(),
                    format!("{:.3}", e["at_s"].as_f64().unwrap_or(-1.0)),
                )
            })
            .collect()
    };
    let live = listed(&out);
    assert!(live.iter().any(|e| e.0 == "fault"), "{live:?}");
    assert_eq!(live, listed(&replay));
    assert!(residue_of(&run).is_empty());
}

/// VmRSS of a process, kB.
fn rss_kb(pid: u32) -> u64 {
    std::fs::read_to_string(format!("/proc/{pid}/status"))
        .unwrap_or_default()
        .lines()
        .find_map(|l| l.strip_prefix("VmRSS:"))
        .and_then(|v| v.split_whitespace().next()?.parse().ok())
        .unwrap_or(0)
}

#[test]
fn ten_restarts_of_one_agent_keep_the_orchestrators_memory_flat_and_leave_no_residue() {
    let dir = temp_dir("ten-restarts");
    let events: String = (0..10)
        .map(|k| {
            format!(
                "[[events]]\nat_s = {}.0\nkind = \"crash\"\nagent = 2\ndown_s = 0.2\n\n",
                2 + 2 * k
            )
        })
        .collect();
    let s = scenario_with(&dir, "ten", 23.0, &events);
    let mut run = RunningRun::start(&[s.to_str().unwrap()], &dir.join("run"));
    let mut after_second = None;
    let mut last = 0;
    let start = Instant::now();
    while run.wait(Duration::from_millis(20)).is_none() {
        assert!(start.elapsed() < RUN_TIMEOUT);
        let taken = run.stderr().matches("agent 2 taken over").count();
        let rss = rss_kb(run.pid());
        if taken >= 2 && after_second.is_none() && rss > 0 {
            after_second = Some(rss);
        }
        if taken >= 10 && rss > 0 {
            last = rss;
        }
    }
    let stderr = run.stderr();
    assert_eq!(stderr.matches("agent 2 taken over").count(), 10, "{stderr}");
    let first = after_second.expect("sampled after the second restart");
    assert!(last > 0, "sampled after the tenth restart");
    assert!(
        last <= first + 4096,
        "orchestrator VmRSS {first} kB after 2 restarts, {last} kB after 10"
    );
    assert!(residue_of(&run).is_empty());
}
