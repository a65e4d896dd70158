//! End to end: the runs folder, the output folder and a killed run hold up against hostile
//! neighbours and lost processes. A runs folder others could write to (or that others own) is
//! refused; foreign files in it are never deleted, stale records of dead runs are; a second run
//! into a busy output folder is refused at once; a SIGKILLed orchestrator leaves no iceoryx2 file,
//! no child and a readable CSV; concurrent runs get different plant CPUs; a dead child is named at
//! once; another user's run is a permission error; the wall time excludes building the binaries.
//!
//! Every test uses its own runs directory (`FORMATION_RUNS_DIR`). Some need root (to own files as
//! another uid, as in CI's container); they say so and pass vacuously otherwise.

use formation_tests::run::RunningRun;
use formation_tests::{bin, formation_in as formation, stderr_of as stderr, temp_dir};
use std::os::unix::fs::PermissionsExt;
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// Generous bound for anything to happen; reaching it means a hang.
const TIMEOUT: Duration = Duration::from_secs(120);
/// A uid that is not ours (`nobody` on most systems).
const OTHER_UID: u32 = 65534;

fn is_root() -> bool {
    // SAFETY: getuid has no preconditions.
    unsafe { libc::getuid() == 0 }
}

fn chown(path: &Path, uid: u32) {
    let c = std::ffi::CString::new(path.as_os_str().as_encoded_bytes()).unwrap();
    // SAFETY: lchown on a valid C string path.
    assert_eq!(unsafe { libc::lchown(c.as_ptr(), uid, uid) }, 0, "chown");
}

/// A private runs folder (mode 0700) under `dir`.
fn runs_dir(dir: &Path) -> PathBuf {
    let runs = dir.join("runs");
    std::fs::create_dir_all(&runs).unwrap();
    std::fs::set_permissions(&runs, std::fs::Permissions::from_mode(0o700)).unwrap();
    runs
}

/// Starts a 600 s run registered in `runs`, and waits until it is stepping.
fn start_long_run(runs: &Path, out: &Path) -> RunningRun {
    let run = RunningRun::start_with_env(
        &["--set", "simulation.duration_s=600"],
        out,
        &[("FORMATION_RUNS_DIR", runs)],
    );
    assert!(
        run.wait_for_line("run registered", TIMEOUT).is_some(),
        "the run did not start: {}",
        run.stderr()
    );
    // Stepping: rows reach the CSV (flushed at least every second).
    let csv = out.join("trajectory.csv");
    let start = Instant::now();
    while std::fs::read_to_string(&csv).map_or(0, |t| t.lines().count()) < 2 {
        assert!(start.elapsed() < TIMEOUT, "no rows: {}", run.stderr());
        std::thread::sleep(Duration::from_millis(20));
    }
    run
}

/// The run id on the start line of a run.
fn run_id(run: &RunningRun) -> String {
    run.id()
        .unwrap_or_else(|| panic!("no run id: {}", run.stderr()))
}

/// What follows `needle` on the first stderr line holding it, up to a comma.
fn field_after(run: &RunningRun, needle: &str) -> String {
    let line = run
        .wait_for_line(needle, TIMEOUT)
        .unwrap_or_else(|| panic!("no '{needle}': {}", run.stderr()));
    let rest = line.split(needle).nth(1).unwrap();
    rest.split(',').next().unwrap().to_string()
}

/// Start time after boot of `pid`, clock ticks (`/proc/<pid>/stat` field 22).
fn start_ticks(pid: u32) -> u64 {
    let text = std::fs::read_to_string(format!("/proc/{pid}/stat")).unwrap();
    let rest = &text[text.rfind(')').unwrap() + 1..];
    rest.split_whitespace().nth(19).unwrap().parse().unwrap()
}

/// A run record as `formation run` writes it.
fn record(id: &str, pid: u32, ticks: u64, out_dir: &Path) -> String {
    serde_json::json!({
        "format": "formation-run-record/1", "id": id, "prefix": format!("fm{id}_"),
        "out_dir": out_dir, "scenario": "paper", "variant": "proposed", "n_agents": 5,
        "steps": 1000, "dt_s": 0.001, "orchestrator_start_ticks": ticks, "started_unix_s": 0.0,
        "processes": [{"role": "orchestrator", "agent": null, "pid": pid}],
        "last_step": 0, "steps_per_s": 0.0
    })
    .to_string()
}

#[test]
fn a_runs_folder_others_can_write_to_or_that_another_user_owns_is_refused_with_exit_2() {
    let dir = temp_dir("hard-runs-dir");
    let runs = runs_dir(&dir);
    assert_eq!(formation(&runs, &["ps"]).status.code(), Some(0));
    std::fs::set_permissions(&runs, std::fs::Permissions::from_mode(0o777)).unwrap();
    for args in [
        &["ps"][..],
        &["inspect", "--agent", "1"][..],
        &["run", "--set", "simulation.duration_s=0.01", "--out"][..],
    ] {
        let mut args = args.to_vec();
        let out = dir.join("out");
        let out_s = out.to_string_lossy().into_owned();
        if args.last() == Some(&"--out") {
            args.push(&out_s);
        }
        let o = formation(&runs, &args);
        let e = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {e}");
        assert!(
            e.contains(&runs.display().to_string()) && e.contains("world-writable"),
            "{args:?}: {e}"
        );
        assert!(!out.join("trajectory.csv").exists(), "the run started");
    }
    if is_root() {
        std::fs::set_permissions(&runs, std::fs::Permissions::from_mode(0o700)).unwrap();
        chown(&runs, OTHER_UID);
        let o = formation(&runs, &["ps"]);
        assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
        assert!(
            stderr(&o).contains(&format!("uid {OTHER_UID}")),
            "{}",
            stderr(&o)
        );
    } else {
        eprintln!("not root: the ownership refusal is not exercised");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn foreign_files_in_the_runs_folder_survive_and_stale_records_of_dead_runs_are_reaped() {
    let dir = temp_dir("hard-foreign");
    let runs = runs_dir(&dir);
    std::fs::write(runs.join("package.json"), r#"{"name": "mine"}"#).unwrap();
    std::fs::write(runs.join("notes.json"), "not a record").unwrap();
    // A record of a run whose orchestrator no longer exists (pid above pid_max).
    let stale = runs.join("dead1.json");
    std::fs::write(&stale, record("dead1", 4_194_300, 1, &dir)).unwrap();
    let o = formation(&runs, &["ps", "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        runs.join("package.json").exists(),
        "package.json was deleted"
    );
    assert!(runs.join("notes.json").exists(), "notes.json was deleted");
    assert!(!stale.exists(), "the stale record was kept");
    // `inspect` and `inject` reap too.
    for args in [
        &["inspect", "--agent", "1"][..],
        &["inject", "delay", "--agent", "1", "--tau", "0.01"][..],
    ] {
        std::fs::write(&stale, record("dead1", 4_194_300, 1, &dir)).unwrap();
        let o = formation(&runs, args);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {}", stderr(&o));
        assert!(!stale.exists(), "{args:?} kept the stale record");
    }
    assert!(runs.join("package.json").exists());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_second_run_into_a_busy_output_folder_is_refused_at_once_naming_the_first() {
    let dir = temp_dir("hard-busy");
    let runs = runs_dir(&dir);
    let out = dir.join("out");
    let mut first = start_long_run(&runs, &out);
    let id = run_id(&first);
    let out_s = out.to_string_lossy().into_owned();
    for args in [
        &[
            "run",
            "--variant",
            "no-rbfnn",
            "--set",
            "simulation.duration_s=0.2",
            "--out",
            &out_s,
        ][..],
        &[
            "sim",
            "--variant",
            "no-rbfnn",
            "--set",
            "simulation.duration_s=0.2",
            "--out",
            &out_s,
        ][..],
    ] {
        let t0 = Instant::now();
        let o = formation(&runs, args);
        let e = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {e}");
        assert!(
            t0.elapsed() < Duration::from_secs(5),
            "{args:?} was not refused at once"
        );
        assert!(e.contains(&format!("run {id}")), "{e}");
        assert!(e.contains(&format!("pid {}", first.pid())), "{e}");
    }
    first.signal(libc::SIGINT);
    let (st, _) = first
        .wait(Duration::from_secs(10))
        .expect("the first run stops");
    assert_eq!(st.code(), Some(130), "{}", first.stderr());
    let summary = std::fs::read_to_string(out.join("summary.json")).unwrap();
    assert!(summary.contains("\"proposed\""), "{summary}");
    // Free again once the first run is over.
    let o = formation(
        &runs,
        &[
            "sim",
            "--set",
            "simulation.duration_s=0.05",
            "--out",
            &out_s,
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    drop(first);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn sigkill_of_the_orchestrator_leaves_no_iceoryx2_file_no_child_and_a_readable_csv() {
    let dir = temp_dir("hard-kill9");
    let runs = runs_dir(&dir);
    let run = start_long_run(&runs, &dir.join("out"));
    let prefix = run.prefix().expect("prefix");
    assert_eq!(run.role_processes().len(), 7, "{}", run.stderr());
    // Let it record for a while (more than the CSV's flush interval).
    std::thread::sleep(Duration::from_millis(2500));
    run.signal(libc::SIGKILL);
    std::thread::sleep(Duration::from_secs(3));
    let left = formation_config::node::ipc::residue(&prefix).unwrap();
    assert!(left.is_empty(), "left behind: {left:?}");
    assert!(run.role_processes().is_empty(), "role processes survived");
    let csv = std::fs::read_to_string(run.out.join("trajectory.csv")).unwrap();
    let lines: Vec<&str> = csv.lines().collect();
    assert!(lines.len() > 10, "{} lines in trajectory.csv", lines.len());
    assert!(lines[0].starts_with("step,t,agent,"), "{}", lines[0]);
    assert!(csv.ends_with('\n'), "a partial row");
    let columns = lines[0].split(',').count();
    assert!(lines.iter().all(|l| l.split(',').count() == columns));
    // The next client command reaps the dead run's record.
    let o = formation(&runs, &["ps", "--json"]);
    assert!(o.status.success());
    assert_eq!(String::from_utf8_lossy(&o.stdout).trim(), r#"{"runs":[]}"#);
    let records = std::fs::read_dir(&runs)
        .unwrap()
        .flatten()
        .filter(|e| e.file_name().to_string_lossy().ends_with(".json"))
        .count();
    assert_eq!(records, 0, "the stale record was kept");
    drop(run);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn runs_started_at_the_same_moment_put_their_plants_on_different_cpus() {
    if !formation_tests::two_cpus_or_skip(
        "runs_started_at_the_same_moment_put_their_plants_on_different_cpus",
    ) {
        return;
    }
    let dir = temp_dir("hard-slots");
    let runs = runs_dir(&dir);
    let env = [("FORMATION_RUNS_DIR", runs.as_path())];
    // `always`: the rotation of the automatic layout, whatever else runs on the machine.
    let set = ["--set", "simulation.duration_s=600", "--pin", "always"];
    let a = RunningRun::start_with_env(&set, &dir.join("a"), &env);
    let b = RunningRun::start_with_env(&set, &dir.join("b"), &env);
    let plant_cpu = |r: &RunningRun| field_after(r, "plant cpu ");
    let (ca, cb) = (plant_cpu(&a), plant_cpu(&b));
    assert_ne!(ca, cb, "both plants on CPU {ca}");
    drop((a, b));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_dead_child_is_named_on_stderr_as_soon_as_it_is_found_before_the_run_stops() {
    let dir = temp_dir("hard-dead-child");
    let runs = runs_dir(&dir);
    let mut run = start_long_run(&runs, &dir.join("out"));
    std::thread::sleep(Duration::from_millis(500));
    let victim = run.agent_pid(2).expect("agent 3 (--agent 2) is running");
    let t0 = Instant::now();
    // SAFETY: kill with a pid of the run.
    unsafe {
        libc::kill(victim as i32, libc::SIGKILL);
    }
    let line = run
        .wait_for_line("error:", Duration::from_secs(10))
        .expect("an error line");
    let took = t0.elapsed();
    eprintln!("error line {} ms after the kill", took.as_millis());
    assert!(
        line.contains("agent 3") && line.contains(&victim.to_string()),
        "{line}"
    );
    assert!(took < Duration::from_millis(500), "took {took:?}");
    let (st, _) = run.wait(Duration::from_secs(10)).expect("the run stops");
    assert_eq!(st.code(), Some(1));
    // Said when found: before the final progress line printed while the run stops, and once.
    let stderr = run.stderr();
    let lines: Vec<&str> = stderr.lines().collect();
    let error_at = lines.iter().position(|l| l.starts_with("error:")).unwrap();
    let progress_at = lines
        .iter()
        .rposition(|l| l.starts_with("step ") && l.contains("real time"))
        .expect("final progress line");
    assert!(error_at < progress_at, "{stderr}");
    assert_eq!(
        lines.iter().filter(|l| l.starts_with("error:")).count(),
        1,
        "{stderr}"
    );
    drop(run);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn another_users_run_is_refused_as_a_permission_problem_naming_its_owner() {
    if !formation_tests::root_or_skip(
        "another_users_run_is_refused_as_a_permission_problem_naming_its_owner",
    ) {
        return;
    }
    let dir = temp_dir("hard-other-user");
    let runs = runs_dir(&dir);
    // Stands in for the other user's orchestrator: a live process of that uid.
    let mut sleeper = Command::new("sleep")
        .arg("60")
        .uid(OTHER_UID)
        .stdout(Stdio::null())
        .spawn()
        .expect("sleep starts as another uid");
    let pid = sleeper.id();
    let path = runs.join("other1.json");
    std::fs::write(&path, record("other1", pid, start_ticks(pid), &dir)).unwrap();
    chown(&path, OTHER_UID);
    let o = formation(&runs, &["ps", "--json"]);
    assert!(
        String::from_utf8_lossy(&o.stdout).contains("other1"),
        "not listed"
    );
    for args in [
        &["inspect", "--agent", "1"][..],
        &["inject", "delay", "--agent", "1", "--tau", "0.01"][..],
    ] {
        let o = formation(&runs, args);
        let e = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {e}");
        assert!(e.contains("permission denied"), "{args:?}: {e}");
        assert!(e.contains(&format!("uid {OTHER_UID}")), "{args:?}: {e}");
    }
    assert!(path.exists(), "another user's record was deleted");
    let _ = sleeper.kill();
    let _ = sleeper.wait();
    // Its run over, the record is still not ours to delete.
    let _ = formation(&runs, &["ps"]);
    assert!(path.exists(), "another user's record was deleted");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_lone_copy_of_formation_runs_every_role_without_cargo_and_times_only_the_steps() {
    let dir = temp_dir("hard-wall");
    let runs = runs_dir(&dir);
    // The `formation` executable alone in a folder (as `cargo install` leaves it), and a `cargo`
    // that would leave a mark if the product ever called it.
    let bin_dir = dir.join("bin");
    std::fs::create_dir_all(&bin_dir).unwrap();
    std::fs::copy(bin("formation"), bin_dir.join("formation")).unwrap();
    let cargo = dir.join("cargo");
    let called = dir.join("cargo-was-called");
    std::fs::write(
        &cargo,
        format!("#!/bin/sh\ntouch '{}'\nexit 1\n", called.display()),
    )
    .unwrap();
    std::fs::set_permissions(&cargo, std::fs::Permissions::from_mode(0o755)).unwrap();
    let out = dir.join("out");
    let t0 = Instant::now();
    let o = Command::new(bin_dir.join("formation"))
        .args(["run", "--set", "simulation.duration_s=1", "--out"])
        .arg(&out)
        .current_dir(&dir)
        .env("FORMATION_RUNS_DIR", &runs)
        .env("CARGO", &cargo)
        .output()
        .unwrap();
    let total = t0.elapsed().as_secs_f64();
    let e = stderr(&o);
    assert!(o.status.success(), "{e}");
    assert!(!called.exists(), "the product called cargo: {e}");
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    let wall = summary["wall_time_s"].as_f64().unwrap();
    let factor = summary["realtime_factor"].as_f64().unwrap();
    assert!(wall < total, "wall_time_s {wall} of {total} s in all");
    // The progress line's factor is the same measure.
    let progress: f64 = e
        .lines()
        .rfind(|l| l.contains("x real time"))
        .and_then(|l| l.split_whitespace().rev().nth(2))
        .and_then(|x| x.trim_end_matches('x').parse().ok())
        .unwrap_or_else(|| panic!("no progress line: {e}"));
    assert!(
        (factor - progress).abs() <= 0.1 * progress + 0.1,
        "summary {factor}x, progress line {progress}x"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
