//! One machine, one user, no setup (docs/multi-host.md, "One machine"): a plain `formation host`
//! daemon of this user on this machine shares the orchestrator's /dev/shm, so it is *co-located*:
//! it starts, signals and reports its agents as any host does, but creates no iceoryx2 service and
//! runs no bridge; its agents use the orchestrator's services. Lockstep stays byte-identical to
//! `formation sim`, and nothing of the run is left in /dev/shm or the iceoryx2 root afterwards,
//! whether the run ends or the daemon is killed. A daemon sharing /dev/shm as another user is
//! refused before anything starts (root only: it acts as a second uid).
//!
//! No namespaces: the daemons run as they would for a user who types `formation host --name b &`,
//! each test with a runtime folder (`XDG_RUNTIME_DIR`) of its own, shared with its orchestrator.

use formation_tests::host::{
    agent_4_checkpoint_step, assert_gone, formation_rt, runs_root, runtime, unique, Daemon,
};
use formation_tests::{
    assert_trajectory_is_sims, bin, root_or_skip, stderr_of, temp_dir, OTHER_UID,
};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// The scenario of these runs: the paper's, shortened.
const SHORT: [&str; 2] = ["--set", "simulation.duration_s=2"];

/// The run's iceoryx2 prefix and the pids of its role processes (plant, leader, agents 1..=5),
/// from its start line (`formation run: id ID, iceoryx2 prefix P, ...; pids P L A1 ...; ...`).
fn start_line(err: &str) -> (String, Vec<u32>) {
    let line = err
        .lines()
        .find(|l| l.contains("formation run: id"))
        .unwrap_or_else(|| panic!("no start line: {err}"));
    let prefix = line
        .split("iceoryx2 prefix ")
        .nth(1)
        .and_then(|r| r.split(',').next())
        .expect("the prefix is named")
        .to_string();
    (prefix, formation_tests::run::start_line_pids(line))
}

/// Files whose name starts with `prefix` in /dev/shm and, recursively, in `iox2_root`.
fn residue(prefix: &str, iox2_root: &Path) -> Vec<PathBuf> {
    fn walk(dir: &Path, prefix: &str, out: &mut Vec<PathBuf>) {
        let Ok(rd) = std::fs::read_dir(dir) else {
            return;
        };
        for e in rd.flatten() {
            let p = e.path();
            if e.file_name().to_string_lossy().starts_with(prefix) {
                out.push(p.clone());
            }
            if e.file_type().is_ok_and(|t| t.is_dir()) {
                walk(&p, prefix, out);
            }
        }
    }
    let mut out = Vec::new();
    walk(Path::new("/dev/shm"), prefix, &mut out);
    walk(iox2_root, prefix, &mut out);
    out
}

/// Waits up to 10 s for nothing of `prefix` to be left (the daemon's agents may exit just after
/// the orchestrator).
fn assert_no_residue(prefix: &str, rt: &Path) {
    assert_no_residue_within(prefix, rt, Duration::from_secs(10));
}

/// Waits up to `within` for nothing of `prefix` to be left.
fn assert_no_residue_within(prefix: &str, rt: &Path, within: Duration) {
    let root = rt.join("formation").join("iox2");
    let t0 = Instant::now();
    loop {
        let left = residue(prefix, &root);
        if left.is_empty() {
            return;
        }
        assert!(
            t0.elapsed() < within,
            "{} files of the run are left after {within:?}: {left:?}",
            left.len()
        );
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// `run --set simulation.duration_s=2 --hosts NAME --place 4,5@NAME EXTRA --out OUT`.
fn split_run(name: &str, extra: &[&str], out: &Path) -> Vec<String> {
    let mut v: Vec<String> = ["run", SHORT[0], SHORT[1], "--hosts", name, "--place"]
        .iter()
        .map(|s| s.to_string())
        .collect();
    v.push(format!("4,5@{name}"));
    v.extend(extra.iter().map(|s| s.to_string()));
    v.push("--out".into());
    v.push(out.display().to_string());
    v
}

#[test]
fn a_same_user_daemon_on_this_machine_starts_its_agents_on_the_orchestrators_services_byte_identical_to_sim(
) {
    let dir = temp_dir("colocated-run");
    let rt = runtime(&dir, 0o700);
    let name = unique("co");
    let daemon = Daemon::start(&rt, &["--name", &name]);
    let out = dir.join("run");
    let o = formation_rt(&rt, &split_run(&name, &[], &out));
    let err = stderr_of(&o);
    assert_eq!(
        o.status.code(),
        Some(0),
        "{err}\ndaemon: {}",
        daemon.log_text()
    );
    assert_trajectory_is_sims(&out, &SHORT, &dir.join("sim"));
    let (prefix, pids) = start_line(&err);
    assert_eq!(pids.len(), 7, "plant, leader and five agents: {err}");
    // Agents 4 and 5 were the daemon's children: it says it started them, with those pids.
    let log = daemon.log_text();
    for (a, pid) in [(4, pids[5]), (5, pids[6])] {
        assert!(
            log.contains(&format!("agent {a} started, pid {pid}")),
            "the daemon started agent {a} (pid {pid}): {log}"
        );
    }
    assert!(
        log.contains("co-located") && log.contains("no bridge"),
        "the daemon prepared the run co-located: {log}"
    );
    assert!(
        !log.contains("services forwarded"),
        "no bridge ran on the daemon: {log}"
    );
    let s = formation_tests::summary(&out);
    let hosts: Vec<&str> = s["agents"]
        .as_array()
        .unwrap()
        .iter()
        .map(|a| a["host"].as_str().unwrap())
        .collect();
    assert_eq!(hosts, ["local", "local", "local", &name, &name]);
    daemon
        .wait_for_line("ended", Duration::from_secs(10))
        .unwrap_or_else(|| panic!("the daemon ended the run: {}", daemon.log_text()));
    assert_gone(&pids);
    assert_no_residue(&prefix, &rt);
    drop(daemon);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_killed_co_located_daemon_under_on_failure_has_its_agents_taken_over_here_and_leaves_nothing() {
    let dir = temp_dir("colocated-lost");
    let rt = runtime(&dir, 0o700);
    let name = unique("cl");
    let mut daemon = Daemon::start(&rt, &["--name", &name]);
    let out = dir.join("run");
    let err_path = dir.join("run.err");
    let mut run = start_split_run(
        &rt,
        &name,
        &["simulation.duration_s=8"],
        &["--restart-state", "warm"],
        &out,
        &err_path,
    );
    // Past the start-up transient: once agent 4 has checkpointed t = 3 s.
    until_agent_4_checkpointed(&daemon, &mut run, &err_path, 3000);
    let (prefix, pids) = start_line(&std::fs::read_to_string(&err_path).unwrap());
    // SAFETY: kill(2) on our own child.
    unsafe { libc::kill(daemon.child.id() as libc::pid_t, libc::SIGKILL) };
    let _ = daemon.child.wait();
    let st = wait_exit(&mut run, &err_path);
    let err = std::fs::read_to_string(&err_path).unwrap();
    assert_eq!(st.code(), Some(0), "{err}");
    assert!(
        err.contains(&format!(
            "host {name} lost; its agents 4, 5 are taken over on local"
        )),
        "the lost host and its agents are named: {err}"
    );
    for a in [4, 5] {
        let line = err
            .lines()
            .find(|l| l.contains(&format!("formation run: agent {a} taken over at step")))
            .unwrap_or_else(|| panic!("agent {a} is taken over: {err}"));
        assert!(line.contains("(warm,"), "agent {a} restarts warm: {line}");
    }
    let s = formation_tests::summary(&out);
    for a in s["agents"].as_array().unwrap() {
        assert_eq!(a["host"], "local", "every agent ends here");
    }
    assert_eq!(s["diverged"], false, "{s}");
    assert_gone(&pids);
    assert_no_residue(&prefix, &rt);
    let _ = std::fs::remove_dir_all(&dir);
}

/// Starts `formation run --restart on-failure --hosts NAME --place 4,5@NAME` with `sets` and
/// `extra` arguments, its stderr into `err_path`.
fn start_split_run(
    rt: &Path,
    name: &str,
    sets: &[&str],
    extra: &[&str],
    out: &Path,
    err_path: &Path,
) -> std::process::Child {
    let place = format!("4,5@{name}");
    let mut cmd = Command::new(bin("formation"));
    cmd.args([
        "run",
        "--restart",
        "on-failure",
        "--hosts",
        name,
        "--place",
        &place,
    ]);
    for s in sets {
        cmd.args(["--set", s]);
    }
    cmd.args(extra)
        .arg("--out")
        .arg(out)
        .env("XDG_RUNTIME_DIR", rt)
        .env_remove("CARGO")
        .stdout(Stdio::null())
        .stderr(std::fs::File::create(err_path).unwrap())
        .spawn()
        .expect("formation run starts")
}

/// Waits until agent 4 on `daemon` has checkpointed step `step` (the run still going).
fn until_agent_4_checkpointed(
    daemon: &Daemon,
    run: &mut std::process::Child,
    err_path: &Path,
    step: u64,
) {
    let t0 = Instant::now();
    while runs_root(&daemon.log)
        .and_then(|r| agent_4_checkpoint_step(&r))
        .is_none_or(|s| s < step)
    {
        assert!(
            run.try_wait().unwrap().is_none(),
            "the run ended early: {}",
            std::fs::read_to_string(err_path).unwrap_or_default()
        );
        assert!(
            t0.elapsed() < Duration::from_secs(120),
            "no checkpoint of agent 4 on the daemon: {}",
            daemon.log_text()
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Waits (up to 180 s) for `run` to exit.
fn wait_exit(run: &mut std::process::Child, err_path: &Path) -> std::process::ExitStatus {
    let t0 = Instant::now();
    loop {
        if let Some(st) = run.try_wait().unwrap() {
            return st;
        }
        assert!(
            t0.elapsed() < Duration::from_secs(180),
            "the run hangs: {}",
            std::fs::read_to_string(err_path).unwrap_or_default()
        );
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// A co-located daemon paused (SIGSTOP) past the lease while its agents run on: the host is
/// declared lost, its agents are fenced here (killed before their successors start), each is
/// taken over once, and the run ends with exit 0; nothing is left once the daemon is resumed.
fn a_paused_co_located_daemon_is_fenced(tag: &str, mode: &[&str], duration: &str, pause_at: u64) {
    let dir = temp_dir(tag);
    let rt = runtime(&dir, 0o700);
    let name = unique("cp");
    let daemon = Daemon::start(&rt, &["--name", &name]);
    let out = dir.join("run");
    let err_path = dir.join("run.err");
    let mut extra = vec!["--lease-ms", "1000"];
    extra.extend(mode);
    let mut run = start_split_run(&rt, &name, &[duration], &extra, &out, &err_path);
    until_agent_4_checkpointed(&daemon, &mut run, &err_path, pause_at);
    let (prefix, pids) = start_line(&std::fs::read_to_string(&err_path).unwrap());
    let lost = format!("host {name} lost; its agents 4, 5 are taken over on local");
    // SAFETY: kill(2) on our own child.
    unsafe { libc::kill(daemon.child.id() as libc::pid_t, libc::SIGSTOP) };
    let paused = Instant::now();
    while !std::fs::read_to_string(&err_path).unwrap().contains(&lost)
        && run.try_wait().unwrap().is_none()
        && paused.elapsed() < Duration::from_secs(30)
    {
        std::thread::sleep(Duration::from_millis(20));
    }
    // Paused well past the lease, as a partition that heals.
    std::thread::sleep(Duration::from_millis(1000));
    // SAFETY: kill(2) on our own child.
    unsafe { libc::kill(daemon.child.id() as libc::pid_t, libc::SIGCONT) };
    let st = wait_exit(&mut run, &err_path);
    let err = std::fs::read_to_string(&err_path).unwrap();
    assert_eq!(st.code(), Some(0), "{err}");
    assert!(err.contains(&lost), "the host is declared lost: {err}");
    for a in [4, 5] {
        let fenced = err.lines().filter(|l| {
            l.contains(&format!("agent {a} (--agent {})", a - 1))
                && l.contains("fenced: its process ended here (SIGKILL)")
        });
        assert_eq!(fenced.count(), 1, "agent {a} is fenced once: {err}");
        let started = err
            .lines()
            .filter(|l| l.contains(&format!("formation run: agent {a} taken over at step")));
        assert_eq!(started.count(), 1, "agent {a} is started once: {err}");
    }
    assert!(
        !err.contains("ExceedsMaxSupported") && !err.contains("exited with code"),
        "no successor finds its ports held: {err}"
    );
    assert_gone(&pids);
    assert_no_residue(&prefix, &rt);
    drop(daemon);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_paused_co_located_daemon_in_lockstep_is_fenced_and_each_agent_taken_over_once() {
    a_paused_co_located_daemon_is_fenced("co-pause", &[], "simulation.duration_s=120", 1000);
}

#[test]
fn a_paused_co_located_daemon_in_realtime_is_fenced_and_each_agent_taken_over_once() {
    a_paused_co_located_daemon_is_fenced(
        "co-pause-rt",
        &["--realtime"],
        "simulation.duration_s=10",
        2000,
    );
}

/// The orchestrator SIGKILLed in the middle of a realtime run whose agents 4, 5 are on a
/// co-located daemon: its role processes die with it, the daemon ends its agents when it sees the
/// orchestrator gone and, the last of the run, removes the run's files: none within 5 s.
#[test]
fn an_orchestrator_killed_beside_a_co_located_daemon_leaves_no_file_within_5_s() {
    let dir = temp_dir("co-orch-kill");
    let rt = runtime(&dir, 0o700);
    let name = unique("ck");
    let daemon = Daemon::start(&rt, &["--name", &name]);
    let out = dir.join("run");
    let err_path = dir.join("run.err");
    let mut run = start_split_run(
        &rt,
        &name,
        &["simulation.duration_s=30"],
        &["--realtime"],
        &out,
        &err_path,
    );
    until_agent_4_checkpointed(&daemon, &mut run, &err_path, 1000);
    let (prefix, pids) = start_line(&std::fs::read_to_string(&err_path).unwrap());
    run.kill().unwrap();
    run.wait().unwrap();
    assert_no_residue_within(&prefix, &rt, Duration::from_secs(5));
    assert_gone(&pids);
    drop(daemon);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_daemon_sharing_dev_shm_as_another_user_is_refused_before_anything_starts_saying_what_to_do() {
    if !root_or_skip(
        "a_daemon_sharing_dev_shm_as_another_user_is_refused_before_anything_starts_saying_what_to_do",
    ) {
        return;
    }
    use std::os::unix::fs::PermissionsExt;
    let dir = temp_dir("colocated-uid");
    std::fs::set_permissions(&dir, std::fs::Permissions::from_mode(0o755)).unwrap();
    // The other user's runtime folder, where its daemon listens.
    let other_rt = dir.join("other");
    std::fs::create_dir_all(&other_rt).unwrap();
    std::fs::set_permissions(&other_rt, std::fs::Permissions::from_mode(0o700)).unwrap();
    formation_tests::chown(&other_rt, OTHER_UID);
    let name = unique("cu");
    let daemon = Daemon::start_as(&other_rt, &["--name", &name], Some(OTHER_UID));
    let sock = other_rt.join("formation").join(format!("{name}.sock"));
    let rt = runtime(&dir, 0o700);
    let out = dir.join("run");
    let connect = format!("unixsock-stream/{}", sock.display());
    let o = formation_rt(&rt, &split_run(&name, &["--connect", &connect], &out));
    let err = stderr_of(&o);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(
        err.contains(&format!("host {name}"))
            && err.contains(&format!("uid {OTHER_UID}"))
            && err.contains("Start `formation host` as uid 0"),
        "the refusal names the host, both users and what to do: {err}"
    );
    assert!(
        !daemon.log_text().contains("prepared") && daemon.children().trim().is_empty(),
        "nothing started on the daemon: {}",
        daemon.log_text()
    );
    assert!(!out.join("trajectory.csv").exists(), "nothing ran");
    drop(daemon);
    let _ = std::fs::remove_dir_all(&dir);
}
