//! End to end, as an outside tester with a second uid would probe a run: output folders another
//! user owns or planted links in them, the run's shared memory, two users running side by side,
//! residue of killed runs, checkpoints that lie, and logs across restarts.
//!
//! Tests that need a second uid (65534) need root; they say so and skip elsewhere, unless
//! `FORMATION_REQUIRE_ROOT=1` (set by `.ci/run`, which runs as root) makes them required.

use formation_tests::run::RunningRun;
use formation_tests::{
    assert_trajectory_is_sims, bin, chown, formation, root_or_skip, stderr_of as stderr, summary,
    temp_dir, OTHER_UID,
};
use std::os::unix::fs::{MetadataExt, PermissionsExt};
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// Generous bound for anything to happen; reaching it means a hang.
const TIMEOUT: Duration = Duration::from_secs(240);

/// Waits until the run's CSV has rows.
fn wait_stepping(run: &RunningRun) {
    let csv = run.out.join("trajectory.csv");
    let start = Instant::now();
    while std::fs::read_to_string(&csv).map_or(0, |t| t.lines().count()) < 2 {
        assert!(start.elapsed() < TIMEOUT, "no rows: {}", run.stderr());
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Sets the modification time of `path` one minute back (what the reaper takes as old enough).
fn backdate(path: &Path) {
    let c = std::ffi::CString::new(path.as_os_str().as_encoded_bytes()).unwrap();
    let now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_secs() as i64;
    let t = libc::timespec {
        tv_sec: now - 60,
        tv_nsec: 0,
    };
    // SAFETY: a valid path and two timespecs.
    unsafe {
        libc::utimensat(
            libc::AT_FDCWD,
            c.as_ptr(),
            [t, t].as_ptr(),
            libc::AT_SYMLINK_NOFOLLOW,
        )
    };
}

#[test]
fn a_folder_another_user_owns_with_a_planted_summary_link_is_refused_and_the_victim_kept() {
    if !root_or_skip(
        "a_folder_another_user_owns_with_a_planted_summary_link_is_refused_and_the_victim_kept",
    ) {
        return;
    }
    let dir = temp_dir("hostile-foreign-out");
    let victim = dir.join("victim.txt");
    std::fs::write(&victim, "precious").unwrap();
    // uid 65534 owns the folder (mode 0755) and planted the link.
    let out = dir.join("sh").join("out");
    std::fs::create_dir_all(&out).unwrap();
    std::os::unix::fs::symlink(&victim, out.join("summary.json")).unwrap();
    chown(&dir.join("sh"), OTHER_UID);
    chown(&out, OTHER_UID);
    chown(&out.join("summary.json"), OTHER_UID);
    for cmd in ["sim", "run"] {
        let o = formation(&[
            cmd,
            "--set",
            "simulation.duration_s=1",
            "--out",
            out.to_str().unwrap(),
        ]);
        assert_eq!(o.status.code(), Some(2), "{cmd}: {}", stderr(&o));
        let e = stderr(&o);
        assert!(
            e.contains(&out.display().to_string()) && e.contains(&format!("uid {OTHER_UID}")),
            "{cmd}: {e}"
        );
        assert_eq!(
            std::fs::read_to_string(&victim).unwrap(),
            "precious",
            "{cmd}"
        );
    }
    // A folder others may write to is refused too, whoever owns it.
    let shared = dir.join("shared");
    std::fs::create_dir(&shared).unwrap();
    std::fs::set_permissions(&shared, std::fs::Permissions::from_mode(0o777)).unwrap();
    let o = formation(&[
        "sim",
        "--set",
        "simulation.duration_s=1",
        "--out",
        shared.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("world-writable"), "{}", stderr(&o));
}

#[test]
fn links_planted_in_an_own_output_folder_are_replaced_never_written_through() {
    let dir = temp_dir("hostile-own-out");
    let victim = dir.join("victim.txt");
    std::fs::write(&victim, "precious").unwrap();
    let out = dir.join("out");
    std::fs::create_dir(&out).unwrap();
    for name in [
        "summary.json",
        "trajectory.csv",
        "scenario.toml",
        "run.mcap",
    ] {
        std::os::unix::fs::symlink(&victim, out.join(name)).unwrap();
    }
    let o = formation(&[
        "sim",
        "--set",
        "simulation.duration_s=0.5",
        "--record",
        "mcap",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(std::fs::read_to_string(&victim).unwrap(), "precious");
    for name in [
        "summary.json",
        "trajectory.csv",
        "scenario.toml",
        "run.mcap",
    ] {
        let m = std::fs::symlink_metadata(out.join(name)).unwrap();
        assert!(m.is_file(), "{name} is a file of its own");
        assert_eq!(m.mode() & 0o077, 0, "{name} is owner-only");
    }
    // A planted subfolder link (an attacker's checkpoints folder) is refused, naming it.
    let elsewhere = dir.join("elsewhere");
    std::fs::create_dir(&elsewhere).unwrap();
    std::os::unix::fs::symlink(&elsewhere, out.join("checkpoints")).unwrap();
    let o = formation(&[
        "run",
        "--set",
        "simulation.duration_s=0.2",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("checkpoints"), "{}", stderr(&o));
    assert_eq!(std::fs::read_dir(&elsewhere).unwrap().count(), 0);
}

/// The run's `…global_mgmt` segment in /dev/shm.
fn global_mgmt(prefix: &str) -> PathBuf {
    std::fs::read_dir("/dev/shm")
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .find(|p| {
            let n = p.file_name().unwrap().to_string_lossy().into_owned();
            n.starts_with(prefix) && n.ends_with(".global_mgmt")
        })
        .unwrap_or_else(|| panic!("no global_mgmt of {prefix}"))
}

#[test]
fn another_uid_cannot_write_16_bytes_into_a_runs_global_mgmt_and_every_file_of_it_is_owner_only() {
    if !root_or_skip("another_uid_cannot_write_16_bytes_into_a_runs_global_mgmt_and_every_file_of_it_is_owner_only") {
        return;
    }
    let dir = temp_dir("hostile-shm");
    let out = dir.join("run");
    let mut run = RunningRun::start(&["--set", "simulation.duration_s=3"], &out);
    wait_stepping(&run);
    let prefix = run.prefix().expect("the run names its prefix");
    let mgmt = global_mgmt(&prefix);
    let before = std::fs::read(&mgmt).unwrap();
    let o = Command::new("/bin/sh")
        .arg("-c")
        .arg("printf 0123456789abcdef > \"$1\"")
        .arg("sh")
        .arg(&mgmt)
        .uid(OTHER_UID)
        .gid(OTHER_UID)
        .output()
        .expect("sh starts as another uid");
    assert!(
        !o.status.success(),
        "uid {OTHER_UID} wrote into {}",
        mgmt.display()
    );
    assert_eq!(std::fs::read(&mgmt).unwrap(), before);
    for f in formation_config::node::ipc::residue(&prefix).unwrap() {
        let m = std::fs::symlink_metadata(&f).unwrap();
        assert_eq!(
            m.mode() & 0o077,
            0,
            "{} is mode {:o}",
            f.display(),
            m.mode() & 0o777
        );
    }
    // The iceoryx2 root holding the node records and event sockets is the user's alone.
    let root = std::fs::symlink_metadata(formation_config::node::ipc::root_dir()).unwrap();
    assert_eq!(root.mode() & 0o777, 0o700);
    let (st, _) = run.wait(TIMEOUT).expect("the run ends");
    assert_eq!(st.code(), Some(0), "{}", run.stderr());
}

#[test]
fn a_second_user_runs_side_by_side_with_roots_run_and_both_are_byte_identical_to_sim() {
    if !root_or_skip(
        "a_second_user_runs_side_by_side_with_roots_run_and_both_are_byte_identical_to_sim",
    ) {
        return;
    }
    let dir = temp_dir("hostile-two-users");
    let mine = dir.join("root-run");
    let mut run = RunningRun::start(&["--set", "simulation.duration_s=3"], &mine);
    wait_stepping(&run);
    // The other user's own folder, from which it runs.
    let theirs = dir.join("nobody");
    std::fs::create_dir(&theirs).unwrap();
    chown(&theirs, OTHER_UID);
    let their_out = theirs.join("out");
    let o = Command::new(bin("formation"))
        .args(["run", "--set", "simulation.duration_s=2", "--out"])
        .arg(&their_out)
        .env_remove("CARGO")
        .env_remove("XDG_RUNTIME_DIR")
        .env_remove("FORMATION_RUNS_DIR")
        .env("HOME", &theirs)
        .current_dir(&theirs)
        .uid(OTHER_UID)
        .gid(OTHER_UID)
        .stdin(Stdio::null())
        .output()
        .expect("formation starts as another uid");
    assert!(
        o.status.success(),
        "the second user's run failed: {}",
        stderr(&o)
    );
    let (st, _) = run.wait(TIMEOUT).expect("root's run ends");
    assert_eq!(st.code(), Some(0), "{}", run.stderr());
    assert_eq!(
        std::fs::metadata(their_out.join("trajectory.csv"))
            .unwrap()
            .uid(),
        OTHER_UID
    );
    assert_trajectory_is_sims(
        &their_out,
        &["--set", "simulation.duration_s=2"],
        &dir.join("sim2"),
    );
    assert_trajectory_is_sims(
        &mine,
        &["--set", "simulation.duration_s=3"],
        &dir.join("sim3"),
    );
}

#[test]
fn ps_reaps_the_files_of_a_killed_run_and_never_those_of_a_live_one() {
    let dir = temp_dir("hostile-reap");
    let runs = |tag: &str| {
        let d = dir.join(tag);
        std::fs::create_dir(&d).unwrap();
        std::fs::set_permissions(&d, std::fs::Permissions::from_mode(0o700)).unwrap();
        d
    };
    let (runs_live, runs_dead, runs_ps) = (runs("runs-live"), runs("runs-dead"), runs("runs-ps"));
    let live_out = dir.join("live");
    let mut live = RunningRun::start_with_env(
        &["--set", "simulation.duration_s=600"],
        &live_out,
        &[("FORMATION_RUNS_DIR", &runs_live)],
    );
    wait_stepping(&live);
    let dead = RunningRun::start_with_env(
        &["--set", "simulation.duration_s=600"],
        &dir.join("dead"),
        &[("FORMATION_RUNS_DIR", &runs_dead)],
    );
    wait_stepping(&dead);
    // Every process of the second run stopped, then killed: nobody cleans up.
    let mut pids = dead.role_processes();
    pids.push(dead.pid());
    for &sig in &[libc::SIGSTOP, libc::SIGKILL] {
        for &p in &pids {
            // SAFETY: pids of the run this test started.
            unsafe { libc::kill(p as i32, sig) };
        }
    }
    let start = Instant::now();
    while pids.iter().any(|p| {
        Path::new(&format!("/proc/{p}")).exists()
            && !std::fs::read_to_string(format!("/proc/{p}/stat")).is_ok_and(|s| s.contains(") Z"))
    }) {
        assert!(
            start.elapsed() < TIMEOUT,
            "the killed run's processes linger"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    let (live_prefix, dead_prefix) = (live.prefix().unwrap(), dead.prefix().unwrap());
    let residue = |p: &str| formation_config::node::ipc::residue(p).unwrap();
    assert!(
        !residue(&dead_prefix).is_empty(),
        "the killed run left files"
    );
    // Both old enough to be reaped, were they dead.
    for f in residue(&dead_prefix)
        .into_iter()
        .chain(residue(&live_prefix))
    {
        backdate(&f);
    }
    let live_files = residue(&live_prefix).len();
    // A `ps` that knows neither run (another runs folder).
    let o = Command::new(bin("formation"))
        .arg("ps")
        .env("FORMATION_RUNS_DIR", &runs_ps)
        .env_remove("CARGO")
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains(&dead_prefix), "{}", stderr(&o));
    assert!(
        residue(&dead_prefix).is_empty(),
        "{:?}",
        residue(&dead_prefix)
    );
    assert!(!stderr(&o).contains(&live_prefix), "{}", stderr(&o));
    assert_eq!(
        residue(&live_prefix).len(),
        live_files,
        "the live run's files are kept"
    );
    // The live run goes on and ends normally.
    let rows = |d: &Path| {
        std::fs::read_to_string(d.join("trajectory.csv")).map_or(0, |t| t.lines().count())
    };
    let before = rows(&live_out);
    let start = Instant::now();
    while rows(&live_out) <= before {
        assert!(
            start.elapsed() < TIMEOUT,
            "the live run stopped: {}",
            live.stderr()
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    live.signal(libc::SIGINT);
    let (st, _) = live.wait(TIMEOUT).expect("the live run ends");
    assert!(st.code().is_some(), "{}", live.stderr());
    assert!(residue(&live_prefix).is_empty());
    drop(dead);
}

/// The paper scenario of `duration_s` with `events` appended.
fn scenario_with(dir: &Path, duration_s: f64, events: &str) -> PathBuf {
    let mut text = formation_config::scenario::PAPER_TOML
        .replace("duration_s = 60.0", &format!("duration_s = {duration_s}"));
    assert!(text.contains(&format!("duration_s = {duration_s}")));
    text.push('\n');
    text.push_str(events);
    let path = dir.join("scenario.toml");
    std::fs::write(&path, text).unwrap();
    path
}

#[test]
fn a_restarted_agent_appends_to_its_log_after_a_line_naming_its_new_pid() {
    let dir = temp_dir("hostile-log");
    let scenario = scenario_with(
        &dir,
        1.5,
        "[[events]]\nat_s = 0.5\nkind = \"crash\"\nagent = 1\ndown_s = 0.3\n",
    );
    let out = dir.join("run");
    let mut run = RunningRun::start(&[scenario.to_str().unwrap()], &out);
    let (st, _) = run.wait(TIMEOUT).expect("the run ends");
    assert_eq!(st.code(), Some(0), "{}", run.stderr());
    let log = std::fs::read_to_string(out.join("logs").join("agent-1.log")).unwrap();
    let separators: Vec<&str> = log
        .lines()
        .filter(|l| l.contains("new process: pid"))
        .collect();
    assert_eq!(separators.len(), 1, "{log}");
    let starts = log.lines().filter(|l| l.contains("starting")).count();
    assert_eq!(starts, 2, "the first process's lines are kept: {log}");
    let sep_at = log.find("new process: pid").unwrap();
    assert!(
        log[..sep_at].contains("starting") && log[sep_at..].contains("taking over"),
        "{log}"
    );
}

#[test]
fn another_agents_checkpoint_is_refused_named_and_the_restart_goes_cold_at_once_counted() {
    let dir = temp_dir("hostile-ckpt");
    let out = dir.join("run");
    let mut run = RunningRun::start(
        &[
            "--set",
            "simulation.duration_s=6",
            "--restart",
            "on-failure",
            "--restart-state",
            "warm",
        ],
        &out,
    );
    let ckpt = |id: usize| out.join("checkpoints").join(format!("agent-{id}.ckpt"));
    let start = Instant::now();
    while !(ckpt(2).exists() && ckpt(3).exists()) {
        assert!(
            start.elapsed() < TIMEOUT,
            "no checkpoints: {}",
            run.stderr()
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    wait_stepping(&run);
    let pid = run.agent_pid(1).expect("agent 2 runs");
    // SAFETY: this run's agent 2: stopped so it writes no newer checkpoint, then killed.
    unsafe { libc::kill(pid as i32, libc::SIGSTOP) };
    let swapped = out.join("checkpoints").join("swap.tmp");
    std::fs::copy(ckpt(3), &swapped).unwrap();
    std::fs::rename(&swapped, ckpt(2)).unwrap();
    // SAFETY: as above.
    unsafe { libc::kill(pid as i32, libc::SIGKILL) };
    let (st, _) = run.wait(TIMEOUT).expect("the run ends");
    let e = run.stderr();
    assert_eq!(st.code(), Some(0), "{e}");
    assert!(
        e.contains("agent-2.ckpt refused") && e.contains("agent 3's checkpoint"),
        "{e}"
    );
    assert!(e.contains("restarting cold"), "{e}");
    assert_eq!(
        e.matches("taken over").count(),
        1,
        "one restart, not retries: {e}"
    );
    let s = summary(&out);
    assert_eq!(s["agents"][1]["checkpoints_refused"], 1);
    assert_eq!(s["agents"][1]["restarts"], 1);
}
