//! End to end: `formation run` starts the real role processes (one process per quadrotor, plant,
//! leader) over iceoryx2 and must match `formation sim` byte for byte, stop cleanly on Ctrl-C and on
//! a dead child, keep concurrent runs apart, and leave nothing in /dev/shm or /tmp/iceoryx2.

use formation_tests::run::RunningRun;
use formation_tests::{bin, cpus_allowed, sim, temp_dir};
use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

/// Long enough for any test here; a run that takes longer is a hang.
const RUN_TIMEOUT: Duration = Duration::from_secs(120);

fn residue(prefix: &str) -> Vec<std::path::PathBuf> {
    formation_config::node::ipc::residue(prefix).expect("can list /dev/shm and /tmp/iceoryx2")
}

fn summary_without_timing(dir: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(dir.join("summary.json")).expect("summary.json exists");
    let mut v: serde_json::Value = serde_json::from_str(&text).expect("summary.json parses");
    let obj = v.as_object_mut().expect("summary is an object");
    for key in ["wall_time_s", "realtime_factor", "mode", "timing"] {
        obj.remove(key);
    }
    v
}

/// Starts a run that lasts long enough to be interrupted, and waits until it is stepping.
fn start_long_run(dir: &Path) -> RunningRun {
    let run = RunningRun::start(&["--set", "simulation.duration_s=600"], &dir.join("run"));
    assert!(
        run.prefix().is_some(),
        "the run did not start: {}",
        run.stderr()
    );
    // Wait until steps are being recorded (the CSV grows past its header).
    let csv = run.out.join("trajectory.csv");
    let start = Instant::now();
    while std::fs::metadata(&csv).map_or(0, |m| m.len()) < 4096 {
        assert!(
            start.elapsed() < RUN_TIMEOUT,
            "no progress: {}",
            run.stderr()
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    run
}

#[test]
fn lockstep_run_is_byte_identical_to_in_process_sim() {
    let dir = temp_dir("identical");
    let set = ["--set", "simulation.duration_s=2"];
    let mut run = RunningRun::start(&set, &dir.join("lockstep"));
    let (st, _) = run.wait(RUN_TIMEOUT).expect("the run ends");
    assert!(st.success(), "formation run failed: {}", run.stderr());
    sim(&set, &dir.join("sim"));
    let a = std::fs::read(dir.join("lockstep/trajectory.csv")).unwrap();
    let b = std::fs::read(dir.join("sim/trajectory.csv")).unwrap();
    assert!(a.len() > 1000, "trajectory.csv is too short");
    assert!(a == b, "trajectory.csv differs between run and sim");
    // The lockstep run times its steady state (every step after the warm-up); sim does not.
    let text = std::fs::read_to_string(dir.join("lockstep/summary.json")).unwrap();
    let summary: serde_json::Value = serde_json::from_str(&text).unwrap();
    let timing = &summary["timing"];
    // Timing starts at the first batch recorded after the warm-up (batches are a few steps).
    let timed = timing["timed_steps"].as_u64().expect("timed steps");
    let after_warmup = 2000 - timing["warmup_steps"].as_u64().expect("warm-up steps");
    assert!(
        timed <= after_warmup && timed + 64 >= after_warmup,
        "timed {timed} of {after_warmup} steps"
    );
    let mean = timing["step_us"]["mean"].as_f64().expect("mean step time");
    assert!(mean > 0.0 && mean < 1e6, "step time {mean} µs");
    let sim_text = std::fs::read_to_string(dir.join("sim/summary.json")).unwrap();
    let sim_summary: serde_json::Value = serde_json::from_str(&sim_text).unwrap();
    assert_eq!(sim_summary.get("timing"), None, "sim has no timing");
    let closest = &sim_summary["separation"]["min_distance"]["whole"];
    assert!(
        closest["distance_m"].as_f64().is_some_and(|d| d > 0.0),
        "{closest}"
    );
    assert_eq!(
        summary_without_timing(&dir.join("lockstep")),
        summary_without_timing(&dir.join("sim"))
    );
    drop(run);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_run_leaves_no_residue_in_dev_shm() {
    let dir = temp_dir("residue");
    let mut run = RunningRun::start(&["--set", "simulation.duration_s=0.3"], &dir.join("run"));
    let prefix = run.prefix().expect("the run announces its prefix");
    let (st, _) = run.wait(RUN_TIMEOUT).expect("the run ends");
    assert!(st.success(), "formation run failed: {}", run.stderr());
    assert_eq!(residue(&prefix), Vec::<std::path::PathBuf>::new());
    assert!(run.role_processes().is_empty(), "role processes survived");
    drop(run);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn ctrl_c_stops_every_process_within_two_seconds_with_exit_130() {
    let dir = temp_dir("ctrl-c");
    let mut run = start_long_run(&dir);
    let prefix = run.prefix().unwrap();
    assert_eq!(
        run.role_processes().len(),
        7,
        "plant, leader and 5 agents; stderr: {}",
        run.stderr()
    );
    run.signal(libc::SIGINT);
    let (st, took) = run.wait(Duration::from_secs(10)).expect("the run stops");
    assert!(took <= Duration::from_secs(2), "took {took:?}");
    assert_eq!(st.code(), Some(130), "stderr: {}", run.stderr());
    assert!(run.role_processes().is_empty(), "role processes survived");
    assert_eq!(residue(&prefix), Vec::<std::path::PathBuf>::new());
    let csv = std::fs::read_to_string(run.out.join("trajectory.csv")).unwrap();
    assert!(
        csv.lines().count() > 2 && csv.ends_with('\n'),
        "CSV not flushed"
    );
    assert!(run.out.join("summary.json").is_file());
    drop(run);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn sigkill_of_an_agent_is_reported_and_the_run_stops_cleanly() {
    let dir = temp_dir("sigkill");
    let mut run = start_long_run(&dir);
    let prefix = run.prefix().unwrap();
    let victim = run
        .role_processes()
        .into_iter()
        .find(|pid| {
            std::fs::read(format!("/proc/{pid}/cmdline"))
                .map(|c| String::from_utf8_lossy(&c).contains("--agent\u{0}2\u{0}"))
                .unwrap_or(false)
        })
        .expect("agent 3 (--agent 2) is running");
    // SAFETY: kill with a pid of the run.
    unsafe {
        libc::kill(victim as i32, libc::SIGKILL);
    }
    let (st, took) = run.wait(Duration::from_secs(10)).expect("the run stops");
    let stderr = run.stderr();
    assert!(took <= Duration::from_secs(2), "took {took:?}");
    assert_ne!(st.code(), Some(0));
    assert!(
        st.code().is_some(),
        "the orchestrator must exit, not be killed"
    );
    let error = stderr
        .lines()
        .find(|l| l.starts_with("error:"))
        .unwrap_or_else(|| panic!("no error line: {stderr}"));
    assert!(
        error.contains("agent 3"),
        "error does not name agent 3: {error}"
    );
    assert!(error.contains(&victim.to_string()), "error: {error}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert!(run.role_processes().is_empty(), "role processes survived");
    assert_eq!(residue(&prefix), Vec::<std::path::PathBuf>::new());
    drop(run);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn two_concurrent_runs_do_not_see_each_other() {
    let dir = temp_dir("concurrent");
    let set = ["--set", "simulation.duration_s=1"];
    let mut a = RunningRun::start(&set, &dir.join("a"));
    let mut b = RunningRun::start(&set, &dir.join("b"));
    let (pa, pb) = (a.prefix().unwrap(), b.prefix().unwrap());
    assert_ne!(pa, pb);
    let (sa, _) = a.wait(RUN_TIMEOUT).expect("run a ends");
    let (sb, _) = b.wait(RUN_TIMEOUT).expect("run b ends");
    assert!(sa.success(), "run a: {}", a.stderr());
    assert!(sb.success(), "run b: {}", b.stderr());
    let ta = std::fs::read(dir.join("a/trajectory.csv")).unwrap();
    let tb = std::fs::read(dir.join("b/trajectory.csv")).unwrap();
    assert!(
        ta == tb,
        "the same scenario must give the same trajectory in both runs"
    );
    assert!(residue(&pa).is_empty() && residue(&pb).is_empty());
    drop((a, b));
    let _ = std::fs::remove_dir_all(&dir);
}

fn cmdline(pid: u32) -> String {
    std::fs::read(format!("/proc/{pid}/cmdline"))
        .map(|b| String::from_utf8_lossy(&b).replace('\0', " "))
        .unwrap_or_default()
}

#[test]
fn a_lockstep_run_pins_the_plant_to_the_first_cpu_and_the_agents_round_robin_after_it() {
    let allowed = cpus_allowed(std::process::id());
    let cpus: Vec<usize> = allowed.iter().copied().take(2).collect();
    let list: Vec<String> = cpus.iter().map(|c| c.to_string()).collect();
    let dir = temp_dir("pin");
    let run = RunningRun::start(
        &[
            "--set",
            "simulation.duration_s=600",
            "--pin",
            &list.join(","),
        ],
        &dir.join("run"),
    );
    assert!(run.prefix().is_some(), "not started: {}", run.stderr());
    let mut seen = 0;
    for pid in run.role_processes() {
        let cmd = cmdline(pid);
        let expected = if cmd.contains("node plant") {
            vec![cpus[0]]
        } else if let Some(i) = cmd
            .split("--agent ")
            .nth(1)
            .and_then(|r| r.split(' ').next())
        {
            let i: usize = i.parse().unwrap();
            vec![cpus[(i + 1) % cpus.len()]]
        } else {
            // The leader is not pinned.
            allowed.clone()
        };
        assert_eq!(cpus_allowed(pid), expected, "{cmd}");
        seen += 1;
    }
    assert_eq!(seen, 7, "plant, leader and 5 agents: {}", run.stderr());
    drop(run);
    let _ = std::fs::remove_dir_all(&dir);
}

/// CPU-bound loops (`sh -c 'while :; do :; done'`), one pinned to each CPU given; killed when
/// dropped.
struct BusyLoops(Vec<std::process::Child>);

impl BusyLoops {
    fn on(cpus: &[usize]) -> BusyLoops {
        BusyLoops(
            cpus.iter()
                .map(|&cpu| {
                    let child = Command::new("sh")
                        .args(["-c", "while :; do :; done"])
                        .spawn()
                        .expect("sh starts");
                    // SAFETY: a zeroed cpu_set_t is a valid empty set; CPU_SET within its size;
                    // sched_setaffinity on our own child.
                    unsafe {
                        let mut set: libc::cpu_set_t = std::mem::zeroed();
                        libc::CPU_SET(cpu, &mut set);
                        libc::sched_setaffinity(
                            child.id() as libc::pid_t,
                            std::mem::size_of::<libc::cpu_set_t>(),
                            &set,
                        );
                    }
                    child
                })
                .collect(),
        )
    }
}

impl Drop for BusyLoops {
    fn drop(&mut self) {
        for c in &mut self.0 {
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}

/// (nice value, scheduling policy) of process `pid`'s main thread, from `/proc/<pid>/stat`
/// (fields 19 and 41; the command name in parentheses may hold spaces).
fn nice_and_policy(pid: u32) -> (i64, u64) {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).expect("the process exists");
    let rest: Vec<&str> = stat
        .rsplit_once(')')
        .expect("a stat line")
        .1
        .split_ascii_whitespace()
        .collect();
    // rest[0] is field 3 (state).
    (rest[16].parse().unwrap(), rest[38].parse().unwrap())
}

/// A long paper run started with `extra` arguments beside a CPU-bound loop on every CPU this
/// process may use: (the loops, the run, its start line, its folder, those CPUs); `None` on one
/// CPU (the automatic layout pins nothing there).
fn run_beside_busy_loops(
    extra: &[&str],
    name: &str,
) -> Option<(
    BusyLoops,
    RunningRun,
    String,
    formation_tests::TempDir,
    Vec<usize>,
)> {
    if !formation_tests::two_cpus_or_skip(name) {
        return None;
    }
    let allowed = cpus_allowed(std::process::id());
    let busy = BusyLoops::on(&allowed);
    // Let the loops show in /proc/stat before the run samples it.
    std::thread::sleep(Duration::from_millis(300));
    let dir = temp_dir(name);
    let mut args = vec!["--set", "simulation.duration_s=600"];
    args.extend(extra);
    let run = RunningRun::start(&args, &dir.join("run"));
    let line = run
        .wait_for_line("formation run: id ", Duration::from_secs(60))
        .unwrap_or_else(|| panic!("not started: {}", run.stderr()));
    Some((busy, run, line, dir, allowed))
}

#[test]
fn beside_programs_keeping_every_cpu_busy_a_lockstep_run_starts_unpinned_and_says_why() {
    let Some((busy, run, line, dir, allowed)) = run_beside_busy_loops(&[], "pin-busy") else {
        return;
    };
    assert!(
        line.contains("not pinned: cpu ") && line.contains("busy with other work"),
        "{line}"
    );
    let mut seen = 0;
    let mut preempting = 0;
    for pid in run.role_processes() {
        assert_eq!(cpus_allowed(pid), allowed, "{}", cmdline(pid));
        seen += 1;
        let (nice, policy) = nice_and_policy(pid);
        if cmdline(pid).contains("leader") {
            continue;
        }
        // Plant and agents wake up ahead of the loops: SCHED_OTHER (0), never SCHED_BATCH (3),
        // at nice -10 as root (the test's user in CI), nice 0 otherwise.
        assert_eq!(policy, 0, "{}: policy {policy}", cmdline(pid));
        // SAFETY: geteuid has no preconditions.
        let root = unsafe { libc::geteuid() } == 0;
        assert_eq!(nice, if root { -10 } else { 0 }, "{}", cmdline(pid));
        preempting += 1;
    }
    assert_eq!(seen, 7, "plant, leader and 5 agents: {}", run.stderr());
    assert_eq!(preempting, 6, "plant and 5 agents: {}", run.stderr());
    assert!(
        line.contains("plant and agents under SCHED_OTHER at nice "),
        "{line}"
    );
    drop((run, busy));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn pin_always_pins_the_automatic_layout_whatever_the_load() {
    let Some((busy, run, line, dir, _)) = run_beside_busy_loops(&["--pin", "always"], "pin-always")
    else {
        return;
    };
    assert!(line.contains("plant cpu "), "{line}");
    let pinned = run
        .role_processes()
        .into_iter()
        .filter(|&pid| cpus_allowed(pid).len() == 1)
        .count();
    assert_eq!(pinned, 6, "plant and 5 agents: {}", run.stderr());
    drop((run, busy));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn an_unavailable_cpu_in_pin_is_rejected_with_exit_2_naming_the_flag() {
    let out = Command::new(bin("formation"))
        .args(["run", "--pin", "100000", "--out"])
        .arg(temp_dir("pin-bad"))
        .output()
        .expect("formation runs");
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("--pin"), "{err}");
}
