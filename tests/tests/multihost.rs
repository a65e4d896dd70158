//! One formation across several "hosts" (docs/multi-host.md): Linux network namespaces, each with
//! its own /dev/shm and /tmp (a mount namespace with fresh tmpfs), the first joined to each other
//! one by its own veth pair (a star, as the Zenoh topology), so no shared memory can cross; a
//! `formation host` daemon in every namespace but the first, the orchestrator (plant, leader, the
//! launcher's agents) in the first. The proof is the lockstep contract: `trajectory.csv`
//! byte-identical to `formation sim` for the paper split over two hosts, with and without a crash
//! event, and for the 20-ring over three hosts with a crash, and nothing left in any namespace's
//! /dev/shm.
//!
//! Needs root (namespaces, veth): skipped with a message otherwise, and required (a failure)
//! when `FORMATION_REQUIRE_NETNS=1` (set by `.ci/run`, which runs as root).

use formation_tests::{bin, ip};
use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

static NEXT: AtomicUsize = AtomicUsize::new(0);

/// Longest wait for a daemon to listen or a run to start its processes: a bound on a failure
/// only, wide enough for a 2-core machine whose cores other programs keep busy (a nice-10 test
/// beside two CPU-bound loops at nice 0 gets about a tenth of a core).
const START_BOUND: Duration = Duration::from_secs(120);

/// Why these tests cannot run here, if they cannot.
fn unavailable() -> Option<String> {
    // SAFETY: geteuid has no preconditions.
    if unsafe { libc::geteuid() } != 0 {
        return Some(
            "not root (network namespaces and veth pairs need CAP_NET_ADMIN and CAP_SYS_ADMIN)"
                .into(),
        );
    }
    let ok = |c: &str, a: &[&str]| {
        Command::new(c)
            .args(a)
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .status()
            .is_ok_and(|s| s.success())
    };
    if !ok("ip", &["-V"]) {
        return Some("the `ip` command (iproute2) is missing".into());
    }
    if !ok("unshare", &["--version"]) {
        return Some("the `unshare` command (util-linux) is missing".into());
    }
    None
}

/// `true`: run the test; `false`: skipped (panics instead when FORMATION_REQUIRE_NETNS=1).
fn available(test: &str) -> bool {
    match unavailable() {
        None => true,
        Some(why) if std::env::var("FORMATION_REQUIRE_NETNS").as_deref() == Ok("1") => {
            panic!("{test}: FORMATION_REQUIRE_NETNS=1 but {why}")
        }
        Some(why) => {
            eprintln!("skipping {test}: {why}");
            false
        }
    }
}

/// A folder for the test's files outside /tmp (each namespace has its own /tmp).
fn work_dir(tag: &str) -> PathBuf {
    formation_tests::work_dir_beside_binaries("multihost-tests", tag)
}

/// Two or more namespaces "hosts", star-linked to the first; removed (with their daemons) on drop,
/// whatever happened.
struct Hosts {
    names: Vec<String>,
    addrs: Vec<String>,
    daemons: Vec<Child>,
    auth: PathBuf,
}

impl Hosts {
    fn new(count: usize, dir: &Path) -> Hosts {
        let k = (std::process::id() as usize * 7 + NEXT.fetch_add(1, Ordering::SeqCst)) % 200 + 20;
        let names: Vec<String> = (0..count).map(|h| format!("fm{k}h{h}")).collect();
        let mut hosts = Hosts {
            names: names.clone(),
            addrs: Vec::new(),
            daemons: Vec::new(),
            auth: dir.join("auth"),
        };
        for n in &names {
            let _ = Command::new("ip")
                .args(["netns", "del", n])
                .stderr(Stdio::null())
                .status();
            ip(&["netns", "add", n]);
            ip(&["-n", n, "link", "set", "lo", "up"]);
        }
        hosts.addrs.push(String::new());
        for h in 1..count {
            // One /24 per test and link: 10.<k>.<h>.0/24, launcher .1, host .2.
            let (a, b) = (format!("fm{k}a{h}"), format!("fm{k}b{h}"));
            ip(&["link", "add", &a, "type", "veth", "peer", "name", &b]);
            ip(&["link", "set", &a, "netns", &names[0]]);
            ip(&["link", "set", &b, "netns", &names[h]]);
            ip(&[
                "-n",
                &names[0],
                "addr",
                "add",
                &format!("10.{k}.{h}.1/24"),
                "dev",
                &a,
            ]);
            ip(&[
                "-n",
                &names[h],
                "addr",
                "add",
                &format!("10.{k}.{h}.2/24"),
                "dev",
                &b,
            ]);
            ip(&["-n", &names[0], "link", "set", &a, "up"]);
            ip(&["-n", &names[h], "link", "set", &b, "up"]);
            hosts.addrs.push(format!("10.{k}.{h}.2"));
        }
        std::fs::write(&hosts.auth, "formation:tests-only-secret\n").unwrap();
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(&hosts.auth, std::fs::Permissions::from_mode(0o600)).unwrap();
        hosts
    }

    /// A command running in namespace `h` with a private /dev/shm and /tmp; `residue` receives
    /// what is left in that /dev/shm and /tmp/iceoryx2 when the command ends (`None`: the
    /// command replaces the shell, so its pid is the child's; see [`residue_of`]).
    fn command(&self, h: usize, residue: Option<&Path>, args: &[&str]) -> Command {
        let script = match residue {
            Some(_) => {
                r#"mount -t tmpfs -o mode=1777 tmpfs /dev/shm && mount -t tmpfs -o mode=1777 tmpfs /tmp || exit 97
res="$1"; shift
"$@"; rc=$?
find /dev/shm -mindepth 1 > "$res"; find /tmp/iceoryx2 -type f >> "$res" 2>/dev/null
exit $rc"#
            }
            None => {
                r#"mount -t tmpfs -o mode=1777 tmpfs /dev/shm && mount -t tmpfs -o mode=1777 tmpfs /tmp || exit 97
shift
exec "$@""#
            }
        };
        let residue = residue.map_or_else(|| "-".into(), |p| p.display().to_string());
        let mut c = Command::new("ip");
        c.args([
            "netns",
            "exec",
            &self.names[h],
            "unshare",
            "--mount",
            "--propagation",
            "private",
            "sh",
            "-c",
            script,
            "sh",
        ])
        .arg(&residue)
        .arg(bin("formation"))
        .args(args)
        .env_remove("CARGO")
        .env("RUST_LOG", "warn");
        c
    }

    /// Starts `formation host --name h<h>` in namespace h, listening on its link address.
    fn start_daemon(&mut self, h: usize, dir: &Path, extra_env: &[(&str, &str)]) {
        let ep = format!("tcp/{}:7447", self.addrs[h]);
        let auth = self.auth.display().to_string();
        self.start_daemon_with(h, dir, &["--listen", &ep, "--auth", &auth], extra_env);
    }

    /// Starts `formation host --name h<h> LINK...` in namespace h.
    fn start_daemon_with(
        &mut self,
        h: usize,
        dir: &Path,
        link: &[&str],
        extra_env: &[(&str, &str)],
    ) {
        let log = dir.join(format!("daemon-{h}.log"));
        let name = format!("h{h}");
        let args: Vec<&str> = ["host", "--name", &name]
            .into_iter()
            .chain(link.iter().copied())
            .collect();
        let mut c = self.command(h, None, &args);
        for (k, v) in extra_env {
            c.env(k, v);
        }
        let child = c
            .stdout(Stdio::null())
            .stderr(std::fs::File::create(&log).unwrap())
            .spawn()
            .expect("formation host starts");
        let mut child = child;
        formation_tests::wait_until_listening(
            &mut child,
            &log,
            &format!("daemon {h}"),
            START_BOUND,
        );
        self.daemons.push(child);
    }

    /// What each daemon's namespace holds in /dev/shm and /tmp/iceoryx2 now (read through
    /// /proc/<pid>/root, its view of its own mounts), then stops the daemons (SIGTERM).
    fn stop_daemons(&mut self) -> Vec<String> {
        let residue = self.daemons.iter().map(|c| residue_of(c.id())).collect();
        self.end_daemons();
        residue
    }

    /// Stops the daemons (SIGTERM, then SIGKILL after 10 s) without reading what they left: for
    /// a daemon that may have died already (one whose TLS link broke, see the TLS test).
    fn end_daemons(&mut self) {
        for c in self.daemons.iter_mut() {
            // SAFETY: kill(2) on our own child.
            unsafe { libc::kill(c.id() as libc::pid_t, libc::SIGTERM) };
            let t0 = Instant::now();
            while t0.elapsed() < Duration::from_secs(10) {
                if let Ok(Some(_)) = c.try_wait() {
                    break;
                }
                std::thread::sleep(Duration::from_millis(20));
            }
            let _ = c.kill();
            let _ = c.wait();
        }
        self.daemons.clear();
    }

    fn connect_args(&self) -> Vec<String> {
        let mut v = Vec::new();
        for a in self.addrs.iter().skip(1) {
            v.push("--connect".to_string());
            v.push(format!("tcp/{a}:7447"));
        }
        v
    }
}

impl Drop for Hosts {
    fn drop(&mut self) {
        for c in self.daemons.iter_mut() {
            let _ = c.kill();
            let _ = c.wait();
        }
        for n in &self.names {
            // Deleting a namespace deletes the veth ends inside it.
            let _ = Command::new("ip").args(["netns", "del", n]).status();
        }
    }
}

/// Runs `formation run ARGS --out OUT` in the launcher namespace; (exit code, stderr, residue).
fn run_in(
    hosts: &Hosts,
    dir: &Path,
    args: &[&str],
    out: &Path,
    with_auth: bool,
) -> (i32, String, String) {
    let mut v: Vec<String> = args.iter().map(|s| s.to_string()).collect();
    v.extend(hosts.connect_args());
    if with_auth {
        v.push("--auth".into());
        v.push(hosts.auth.display().to_string());
    }
    let refs: Vec<&str> = v.iter().map(String::as_str).collect();
    run_in_with(hosts, dir, &refs, out)
}

/// Runs `formation run ARGS --out OUT` in the launcher namespace, with exactly these link options
/// in ARGS; (exit code, stderr, residue).
fn run_in_with(hosts: &Hosts, dir: &Path, args: &[&str], out: &Path) -> (i32, String, String) {
    let residue = dir.join("residue-launcher.txt");
    let mut v: Vec<String> = vec!["run".into()];
    v.extend(args.iter().map(|s| s.to_string()));
    v.push("--out".into());
    v.push(out.display().to_string());
    let refs: Vec<&str> = v.iter().map(String::as_str).collect();
    let mut child = hosts
        .command(0, Some(&residue), &refs)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("formation run starts");
    let mut err = String::new();
    child
        .stderr
        .take()
        .unwrap()
        .read_to_string(&mut err)
        .unwrap();
    let st = child.wait().unwrap();
    (
        st.code().unwrap_or(-1),
        err,
        std::fs::read_to_string(&residue).unwrap_or_default(),
    )
}

/// Files in /dev/shm and /tmp/iceoryx2 as process `pid` sees them (its mount namespace).
fn residue_of(pid: u32) -> String {
    fn walk(d: &Path, out: &mut Vec<String>) {
        if let Ok(rd) = std::fs::read_dir(d) {
            for e in rd.flatten() {
                let p = e.path();
                if p.is_dir() {
                    walk(&p, out);
                } else {
                    out.push(p.display().to_string());
                }
            }
        }
    }
    let root = PathBuf::from(format!("/proc/{pid}/root"));
    assert!(root.join("dev/shm").is_dir(), "process {pid} is gone");
    let mut v = Vec::new();
    walk(&root.join("dev/shm"), &mut v);
    walk(&root.join("tmp/iceoryx2"), &mut v);
    v.join("\n")
}

fn assert_no_residue(what: &str, residue: &str) {
    assert!(
        residue.trim().is_empty(),
        "{what} left files in /dev/shm or /tmp/iceoryx2: {residue}"
    );
}

/// Runs `formation run ARGS PLACE` over `count` hosts (a daemon on every host but the launcher)
/// and asserts the lockstep contract: exit 0, every remote host named, nothing left in any
/// namespace's /dev/shm or /tmp/iceoryx2, `trajectory.csv` byte-identical to `formation sim
/// ARGS`. Returns the run's stderr.
fn spread_run_matches_sim(tag: &str, count: usize, args: &[&str], place: &[&str]) -> String {
    let dir = work_dir(tag);
    let mut hosts = Hosts::new(count, &dir);
    for h in 1..count {
        hosts.start_daemon(h, &dir, &[]);
    }
    let out = dir.join("run");
    let run_args: Vec<&str> = args.iter().chain(place).copied().collect();
    let (code, err, residue) = run_in(&hosts, &dir, &run_args, &out, true);
    assert_eq!(code, 0, "formation run over {count} hosts failed:\n{err}");
    for h in 1..count {
        assert!(
            err.contains(&format!("on h{h}")),
            "the run names the remote host h{h}: {err}"
        );
    }
    assert_no_residue("the launcher", &residue);
    for (h, left) in hosts.stop_daemons().iter().enumerate() {
        assert_no_residue(&format!("host h{}", h + 1), left);
    }
    // Shown with a failure only (the test harness captures it): the run's own account of what
    // happened (a takeover's warm or cold start, warnings).
    eprintln!("formation run over {count} hosts, stderr:\n{err}");
    formation_tests::assert_trajectory_is_sims(&out, args, &dir.join("sim"));
    let _ = std::fs::remove_dir_all(&dir);
    err
}

fn split_run_matches_sim(tag: &str, scenario: &str, duration: &str, place: &str) {
    let set = format!("simulation.duration_s={duration}");
    spread_run_matches_sim(
        tag,
        2,
        &[scenario, "--set", &set],
        &["--hosts", "h1", "--place", place],
    );
}

#[test]
fn paper_split_three_two_over_two_hosts_is_byte_identical_to_sim_and_leaves_nothing() {
    if !available(
        "paper_split_three_two_over_two_hosts_is_byte_identical_to_sim_and_leaves_nothing",
    ) {
        return;
    }
    split_run_matches_sim("split", "paper", "5", "4,5@h1");
}

#[test]
fn a_crash_of_a_remote_agent_is_taken_over_warm_on_its_host_byte_identical_to_sim() {
    if !available("a_crash_of_a_remote_agent_is_taken_over_warm_on_its_host_byte_identical_to_sim")
    {
        return;
    }
    // crash-warm.toml crashes agent 3 at t = 20 s for 0.5 s; agent 3 is on the second host.
    let scenario = formation_tests::workspace_root().join("config/scenarios/crash-warm.toml");
    split_run_matches_sim("crash", scenario.to_str().unwrap(), "21", "3,4@h1");
}

/// Agents of the generated ring over three hosts, round-robin (agent i on `local`, `h1`, `h2` for
/// i mod 3 = 1, 2, 0): every agent's two ring neighbours are on the two other hosts, so shares
/// cross h1 <-> h2 (through the launcher, the hub of the star) as well as to and from it.
const RING_AGENTS: usize = 20;
/// Simulated time of the three-host run, s: three checkpoints and a crash with its warm takeover,
/// a few seconds of wall time even on a loaded 2-core machine.
const RING_DURATION_S: &str = "3";

#[test]
fn a_twenty_ring_round_robin_over_three_hosts_with_a_remote_crash_is_byte_identical_to_sim() {
    if !available(
        "a_twenty_ring_round_robin_over_three_hosts_with_a_remote_crash_is_byte_identical_to_sim",
    ) {
        return;
    }
    let dir = work_dir("ring3-files");
    let ring = dir.join("ring-20.toml");
    let n = RING_AGENTS.to_string();
    let o = formation_tests::formation(&[
        "scenario",
        "--n",
        &n,
        "--graph",
        "ring",
        "--out",
        ring.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", formation_tests::stderr_of(&o));
    // Agent 3 (on h2, between agent 2 on h1 and agent 4 here) crashes at t = 2 s and is taken
    // over warm on h2 0.5 s later from its checkpoint of t = 2 s.
    let events = dir.join("crash.toml");
    std::fs::write(
        &events,
        "[[events]]\nat_s = 2.0\nkind = \"crash\"\nagent = 3\ndown_s = 0.5\n",
    )
    .unwrap();
    let set = format!("simulation.duration_s={RING_DURATION_S}");
    let args = [
        ring.to_str().unwrap(),
        "--set",
        &set,
        "--events",
        events.to_str().unwrap(),
        "--restart-state",
        "warm",
    ];
    let err = spread_run_matches_sim("ring3", 3, &args, &["--hosts", "h1,h2"]);
    let ids = |first: usize| {
        (first..=RING_AGENTS)
            .step_by(3)
            .map(|i| i.to_string())
            .collect::<Vec<_>>()
            .join(",")
    };
    for (h, first) in [("h1", 2), ("h2", 3)] {
        assert!(
            err.contains(&format!("{} on {h}", ids(first))),
            "agents {} placed on {h}: {err}",
            ids(first)
        );
    }
    let takeover = err
        .lines()
        .find(|l| l.contains("formation run: agent 3 taken over at step"))
        .unwrap_or_else(|| panic!("agent 3 is taken over: {err}"));
    assert!(
        takeover.contains("(warm,"),
        "agent 3 restarts warm: {takeover}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// `formation hosts ARGS --auth FILE` in the launcher's namespace: (exit code, stdout, stderr).
fn hosts_in(hosts: &Hosts, args: &[&str]) -> (i32, String, String) {
    let auth = hosts.auth.display().to_string();
    let mut v: Vec<&str> = vec!["hosts"];
    v.extend_from_slice(args);
    v.extend_from_slice(&["--auth", &auth]);
    let o = hosts
        .command(0, None, &v)
        .output()
        .expect("formation hosts runs");
    (
        o.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&o.stdout).into_owned(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

#[test]
fn hosts_lists_every_daemon_reachable_through_several_connects_once_and_a_run_right_after_spans_them(
) {
    if !available(
        "hosts_lists_every_daemon_reachable_through_several_connects_once_and_a_run_right_after_spans_them",
    ) {
        return;
    }
    let dir = work_dir("hosts");
    let mut hosts = Hosts::new(3, &dir);
    hosts.start_daemon(1, &dir, &[]);
    hosts.start_daemon(2, &dir, &[]);
    let ep = |h: usize| format!("tcp/{}:7447", hosts.addrs[h]);
    let (a, b) = (ep(1), ep(2));
    // h1 given twice: one daemon, listed once. The two daemons' namespaces have no route to each
    // other, so each is reachable through its own endpoint only.
    let (code, out, err) = hosts_in(
        &hosts,
        &["--json", "--connect", &a, "--connect", &b, "--connect", &a],
    );
    assert_eq!(code, 0, "{err}");
    let listed: serde_json::Value = serde_json::from_str(&out).expect("--json prints JSON");
    let listed = listed.as_array().expect("a JSON array");
    let names: Vec<&str> = listed.iter().filter_map(|h| h["name"].as_str()).collect();
    assert_eq!(names, ["h1", "h2"], "both daemons, once each: {out}");
    for (h, endpoint) in listed.iter().zip([&a, &b]) {
        assert_eq!(h["listen"], serde_json::json!([endpoint]), "{h}");
        assert_eq!(h["via"], serde_json::json!([endpoint]), "{h}");
        assert!(h["pid"].as_u64().is_some_and(|p| p > 0), "{h}");
        assert!(
            h["identity"]["build"]
                .as_str()
                .is_some_and(|b| !b.is_empty()),
            "{h}"
        );
    }
    // The table, and an endpoint nothing answers on: named in a warning, the others listed.
    // 10.<k>.250.0/24: no link of the test, so no route from the launcher's namespace.
    let net: Vec<&str> = hosts.addrs[1].split('.').take(2).collect();
    let nowhere = format!("tcp/{}.250.2:7447", net.join("."));
    let (code, out, err) = hosts_in(
        &hosts,
        &["--connect", &nowhere, "--connect", &b, "--connect", &a],
    );
    assert_eq!(code, 0, "{err}");
    let rows: Vec<&str> = out.lines().skip(1).collect();
    assert_eq!(rows.len(), 2, "{out}");
    assert!(rows[0].starts_with("h1 ") && rows[0].contains(&a), "{out}");
    assert!(rows[1].starts_with("h2 ") && rows[1].contains(&b), "{out}");
    assert!(err.contains(&format!("warning: {nowhere}")), "{err}");
    // Only endpoints nothing answers on: exit 2.
    let (code, _, err) = hosts_in(&hosts, &["--connect", &nowhere]);
    assert_eq!(code, 2, "{err}");
    // A three-host run started right after the listing finds both daemons and stays lockstep.
    let out_dir = dir.join("run");
    let args = ["paper", "--set", "simulation.duration_s=1"];
    let run_args: Vec<&str> = args.iter().chain(&["--hosts", "h1,h2"]).copied().collect();
    let (code, err, residue) = run_in(&hosts, &dir, &run_args, &out_dir, true);
    assert_eq!(code, 0, "formation run right after formation hosts:\n{err}");
    assert_no_residue("the launcher", &residue);
    for (h, left) in hosts.stop_daemons().iter().enumerate() {
        assert_no_residue(&format!("host h{}", h + 1), left);
    }
    formation_tests::assert_trajectory_is_sims(&out_dir, &args, &dir.join("sim"));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_mismatched_build_is_refused_before_anything_starts_naming_both_hosts() {
    if !available("a_mismatched_build_is_refused_before_anything_starts_naming_both_hosts") {
        return;
    }
    let dir = work_dir("mismatch");
    let mut hosts = Hosts::new(2, &dir);
    hosts.start_daemon(1, &dir, &[("FORMATION_BUILD_ID", "0.0.0+other-build")]);
    let out = dir.join("run");
    let (code, err, residue) = run_in(&hosts, &dir, &["paper", "--hosts", "h1"], &out, true);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("h1") && err.contains("local"),
        "both hosts named: {err}"
    );
    assert!(
        err.contains("0.0.0+other-build"),
        "what differs is named: {err}"
    );
    assert!(!out.join("trajectory.csv").exists(), "nothing started");
    assert_no_residue("the launcher", &residue);
    let left = hosts.stop_daemons();
    assert_no_residue("host h1", &left[0]);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn an_orchestrator_without_or_with_wrong_credentials_is_refused_naming_the_host_and_why() {
    if !available(
        "an_orchestrator_without_or_with_wrong_credentials_is_refused_naming_the_host_and_why",
    ) {
        return;
    }
    let dir = work_dir("noauth");
    let mut hosts = Hosts::new(2, &dir);
    hosts.start_daemon(1, &dir, &[]);
    let out = dir.join("run");
    // Without credentials: refused before anything is sent, naming the option.
    let (code, err, residue) = run_in(&hosts, &dir, &["paper", "--hosts", "h1"], &out, false);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("--auth FILE"), "the option is named: {err}");
    assert_no_residue("the launcher", &residue);
    // With a password the daemon does not know: an authentication failure, the host named.
    let wrong = dir.join("wrong-auth");
    std::fs::write(&wrong, "formation:not-the-secret\n").unwrap();
    use std::os::unix::fs::PermissionsExt;
    std::fs::set_permissions(&wrong, std::fs::Permissions::from_mode(0o600)).unwrap();
    let mut args: Vec<String> = ["paper", "--hosts", "h1"].map(String::from).to_vec();
    args.extend(hosts.connect_args());
    args.extend(["--auth".to_string(), wrong.display().to_string()]);
    let refs: Vec<&str> = args.iter().map(String::as_str).collect();
    let (code, err, residue) = run_in_with(&hosts, &dir, &refs, &out);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("h1") && err.contains("authentication failed"),
        "the host and the authentication failure are named: {err}"
    );
    assert!(!out.join("trajectory.csv").exists(), "nothing started");
    assert_no_residue("the launcher", &residue);
    let left = hosts.stop_daemons();
    assert_no_residue("host h1", &left[0]);
    // A daemon refuses to listen on TCP without credentials at all, loopback included.
    for ep in ["tcp/0.0.0.0:7447", "tcp/127.0.0.1:7447"] {
        let o = Command::new(bin("formation"))
            .args(["host", "--name", "x", "--listen", ep])
            .output()
            .unwrap();
        assert_eq!(o.status.code(), Some(2));
        assert!(String::from_utf8_lossy(&o.stderr).contains("requires authentication"));
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// A lockstep run of the paper scenario (`args` after `run paper`) with agents 4 and 5 on a
/// second host, whose daemon is SIGKILLed (and its agents with it) `after` the run started.
struct LostHost {
    code: Option<i32>,
    err: String,
    /// From the SIGKILL to the end of the run.
    ended_after: Duration,
    /// From the SIGKILL to the run's stderr naming the lost agents (polled every 20 ms).
    named_after: Duration,
    out: PathBuf,
    /// What the launcher's namespace held in /dev/shm and /tmp/iceoryx2 at the end.
    residue: String,
    /// The pids of the agents the run started on the second host.
    remote_pids: Vec<u32>,
    dir: PathBuf,
}

/// The step of agent 4's newest checkpoint on the daemon of pid `daemon_pid` (its run folders are
/// in its own mount namespace, seen through `/proc/<pid>/root`).
fn remote_checkpoint_step(daemon_pid: u32, daemon_log: &Path) -> Option<u64> {
    let root = formation_tests::host::runs_root(daemon_log)?;
    formation_tests::host::agent_4_checkpoint_step(&PathBuf::from(format!(
        "/proc/{daemon_pid}/root{}",
        root.display()
    )))
}

/// When [`run_and_kill_the_remote_daemon`] kills the daemon.
enum KillAt {
    /// This long after the run started.
    After(Duration),
    /// Once agent 4 on the second host has written its checkpoint of this step (or a later one).
    Checkpoint(u64),
    /// Once the run's `trajectory.csv` holds this many bytes (its writer flushes 1 MiB at a time,
    /// some hundreds of the paper scenario's steps).
    Written(u64),
}

/// Starts `formation run paper --hosts h1 --place 4,5@h1 ARGS` (with credentials, output `out`)
/// in the launcher namespace, its stderr into `err_path`, with the runs folder `runs` if given.
fn spawn_split_paper_run(
    hosts: &Hosts,
    residue: &Path,
    args: &[&str],
    out: &Path,
    err_path: &Path,
    runs: Option<&Path>,
) -> Child {
    let mut v: Vec<String> = ["run", "paper", "--hosts", "h1", "--place", "4,5@h1"]
        .iter()
        .chain(args)
        .map(|s| s.to_string())
        .collect();
    v.extend(hosts.connect_args());
    v.extend(["--auth".to_string(), hosts.auth.display().to_string()]);
    v.extend(["--out".to_string(), out.display().to_string()]);
    let refs: Vec<&str> = v.iter().map(String::as_str).collect();
    let mut c = hosts.command(0, Some(residue), &refs);
    if let Some(runs) = runs {
        c.env("FORMATION_RUNS_DIR", runs);
    }
    c.stdout(Stdio::null())
        .stderr(std::fs::File::create(err_path).unwrap())
        .spawn()
        .expect("formation run starts")
}

/// Waits until `run` has written `bytes` of `out/trajectory.csv` (it still running), at most
/// `within`.
fn until_written(run: &mut Child, out: &Path, bytes: u64, within: Duration) {
    let t0 = Instant::now();
    let csv = out.join("trajectory.csv");
    while std::fs::metadata(&csv).map_or(0, |m| m.len()) < bytes {
        assert!(
            t0.elapsed() < within,
            "the run wrote no {bytes} bytes of trajectory.csv within {within:?}"
        );
        assert!(run.try_wait().unwrap().is_none(), "the run ended early");
        std::thread::sleep(Duration::from_millis(5));
    }
}

fn run_and_kill_the_remote_daemon(tag: &str, args: &[&str], at: KillAt) -> LostHost {
    run_and_lose_the_remote_host(tag, args, at, false)
}

/// [`run_and_kill_the_remote_daemon`], or with `link_down` its link taken down instead (the
/// daemon and its agents live on, silent, until the lease declares the host lost).
fn run_and_lose_the_remote_host(tag: &str, args: &[&str], at: KillAt, link_down: bool) -> LostHost {
    let dir = work_dir(tag);
    let mut hosts = Hosts::new(2, &dir);
    hosts.start_daemon(1, &dir, &[]);
    let residue = dir.join("residue-launcher.txt");
    let out = dir.join("run");
    let err_path = dir.join("run.err");
    let mut run = spawn_split_paper_run(&hosts, &residue, args, &out, &err_path, None);
    // Let it fly, then SIGKILL the daemon (and with it its agents).
    let t0 = Instant::now();
    let start_line = loop {
        let err = std::fs::read_to_string(&err_path).unwrap_or_default();
        if let Some(l) = err.lines().find(|l| l.contains("formation run: id")) {
            break l.to_string();
        }
        assert!(t0.elapsed() < START_BOUND, "the run did not start: {err}");
        std::thread::sleep(Duration::from_millis(50));
    };
    // `...; pids P L A1 A2 A3 A4 A5; agents ...`: plant, leader, then the agents in order.
    let pids = formation_tests::run::start_line_pids(&start_line);
    assert_eq!(pids.len(), 7, "plant, leader and 5 agents: {start_line}");
    match at {
        KillAt::After(d) => std::thread::sleep(d),
        KillAt::Written(bytes) => until_written(&mut run, &out, bytes, Duration::from_secs(120)),
        KillAt::Checkpoint(k) => {
            let log = dir.join("daemon-1.log");
            while remote_checkpoint_step(hosts.daemons[0].id(), &log).is_none_or(|s| s < k) {
                assert!(
                    t0.elapsed() < Duration::from_secs(240),
                    "no checkpoint of step {k} on h1"
                );
                assert!(run.try_wait().unwrap().is_none(), "the run ended early");
                std::thread::sleep(Duration::from_millis(20));
            }
        }
    }
    let killed = Instant::now();
    if link_down {
        // The launcher's end of the veth pair to h1 (`Hosts::new`: fm<k>a1 in fm<k>h0).
        let veth = hosts.names[0].replace("h0", "a1");
        ip(&["-n", &hosts.names[0], "link", "set", &veth, "down"]);
    } else {
        let mut daemon = hosts.daemons.remove(0);
        // SAFETY: kill(2) on our own child.
        unsafe { libc::kill(daemon.id() as libc::pid_t, libc::SIGKILL) };
        let _ = daemon.wait();
    }
    let mut named_after = None;
    let st = loop {
        if named_after.is_none()
            && std::fs::read_to_string(&err_path)
                .unwrap_or_default()
                .contains("lost with host h1")
        {
            named_after = Some(killed.elapsed());
        }
        if let Some(st) = run.try_wait().unwrap() {
            break st;
        }
        assert!(
            killed.elapsed() < Duration::from_secs(180),
            "the run did not end after its host was lost"
        );
        std::thread::sleep(Duration::from_millis(20));
    };
    LostHost {
        named_after: named_after.unwrap_or_else(|| killed.elapsed()),
        code: st.code(),
        err: std::fs::read_to_string(&err_path).unwrap(),
        ended_after: killed.elapsed(),
        out,
        residue: std::fs::read_to_string(&residue).unwrap_or_default(),
        remote_pids: pids[5..].to_vec(),
        dir,
    }
}

#[test]
fn a_killed_host_daemon_under_restart_never_is_named_at_once_and_the_run_stops_cleanly() {
    if !available(
        "a_killed_host_daemon_under_restart_never_is_named_at_once_and_the_run_stops_cleanly",
    ) {
        return;
    }
    let r = run_and_kill_the_remote_daemon(
        "lost",
        &["--restart", "never"],
        KillAt::After(Duration::from_millis(500)),
    );
    assert_eq!(r.code, Some(1), "{}", r.err);
    assert!(
        r.err.contains("lost with host h1"),
        "the lost host is named: {}",
        r.err
    );
    assert!(
        r.err.contains("host h1 held agents 4, 5"),
        "every agent lost with it is named: {}",
        r.err
    );
    // Named and stopped well within the lease (a killed daemon's TCP link closes at once).
    assert!(
        r.ended_after < Duration::from_secs(5),
        "stopped {:?} after the kill",
        r.ended_after
    );
    eprintln!(
        "run stopped {:.0} ms after the daemon's SIGKILL",
        r.ended_after.as_secs_f64() * 1e3
    );
    assert_no_residue("the launcher", &r.residue);
    formation_tests::host::assert_gone(&r.remote_pids);
    assert!(
        r.out.join("trajectory.csv").exists(),
        "the recorded prefix is kept"
    );
    let _ = std::fs::remove_dir_all(&r.dir);
}

/// Upper bound on the detection of a killed daemon, ms (docs/multi-host.md "Failure model"): its
/// TCP link closes at once; the lease (3000 ms) bounds only a silent link.
const KILLED_DAEMON_DETECTED_WITHIN_MS: f64 = 1000.0;
/// Upper bound on the formation error while a lost host's agents are flown on their failsafe and
/// taken over warm, m.
const HOST_LOSS_PEAK_ERROR_M: f64 = 0.5;

#[test]
fn a_killed_host_daemon_under_on_failure_has_its_agents_taken_over_warm_here_and_the_run_completes()
{
    if !available(
        "a_killed_host_daemon_under_on_failure_has_its_agents_taken_over_warm_here_and_the_run_completes",
    ) {
        return;
    }
    let r = run_and_kill_the_remote_daemon(
        "lost-recover",
        &[
            "--set",
            "simulation.duration_s=22",
            "--restart",
            "on-failure",
            "--restart-state",
            "warm",
        ],
        // Mid-run, past the start-up transient: once agent 4 has checkpointed t = 8 s.
        KillAt::Checkpoint(8000),
    );
    assert_eq!(r.code, Some(0), "{}", r.err);
    assert!(
        r.named_after.as_secs_f64() * 1e3 < KILLED_DAEMON_DETECTED_WITHIN_MS,
        "named {:?} after the kill",
        r.named_after
    );
    assert!(
        r.err
            .contains("host h1 lost; its agents 4, 5 are taken over on local"),
        "the lost host and its agents are named: {}",
        r.err
    );
    for a in [4, 5] {
        let line = r
            .err
            .lines()
            .find(|l| l.contains(&format!("formation run: agent {a} taken over at step")))
            .unwrap_or_else(|| panic!("agent {a} is taken over: {}", r.err));
        assert!(line.contains("(warm,"), "agent {a} restarts warm: {line}");
    }
    let s = formation_tests::summary(&r.out);
    let agents = s["agents"].as_array().unwrap();
    for (i, a) in agents.iter().enumerate() {
        let moved = i >= 3;
        assert_eq!(a["host"], "local", "agent {} ends on the launcher", i + 1);
        assert_eq!(a["restarts"], u64::from(moved), "agent {}", i + 1);
        assert_eq!(a["checkpoints_refused"], 0);
    }
    let mut events: Vec<&serde_json::Value> = s["events"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|e| e["kind"] == "host_lost")
        .collect();
    // The two agents may be detected at different steps, in either order.
    events.sort_by_key(|e| e["agent"].as_u64());
    assert_eq!(
        events.len(),
        2,
        "one event per agent lost: {:?}",
        s["events"]
    );
    for (e, a) in events.iter().zip([4, 5]) {
        assert_eq!(e["agent"], a);
        assert_eq!(e["host"], "h1");
        let detected = e["detected_after_ms"].as_f64().unwrap();
        assert!(
            (0.0..KILLED_DAEMON_DETECTED_WITHIN_MS).contains(&detected),
            "agent {a}: detected after {detected} ms"
        );
        let restarted = e["restarted_after_ms"].as_f64().unwrap();
        assert!(restarted > 0.0, "agent {a}: its successor said hello");
        let peak = e["peak_error_m"].as_f64().unwrap();
        assert!(
            peak.is_finite() && peak < HOST_LOSS_PEAK_ERROR_M,
            "agent {a}: peak formation error {peak} m"
        );
        assert!(
            e["recovered_after_s"].is_number(),
            "the formation recovers: {e}"
        );
        eprintln!(
            "host_lost agent {a} at {} s: named {:.0} ms after the kill, detected after {detected:.1} ms, restarted after {restarted:.0} ms, peak {peak:.3} m, recovered after {} s, min separation {} m",
            e["at_s"],
            r.named_after.as_secs_f64() * 1e3,
            e["recovered_after_s"],
            e["min_separation_during_m"]
        );
    }
    assert_eq!(s["diverged"], false, "{s}");
    assert_no_residue("the launcher", &r.residue);
    formation_tests::host::assert_gone(&r.remote_pids);
    let _ = std::fs::remove_dir_all(&r.dir);
}

/// Sim time between two checkpoints in the runs whose host is lost before the first one, s: far
/// beyond the step the loss falls at.
const LATE_FIRST_CHECKPOINT_S: &str = "runtime.checkpoint_every_s=5";

/// Asserts that a run whose host h1 (agents 4 and 5) was lost under on-failure took both agents
/// over here (cold where no checkpoint had come yet) and completed: exit 0, both named, both on the
/// launcher at the end with one restart each, one `host_lost` event each, nothing left behind.
/// Returns the step each was down from.
fn assert_taken_over_here(r: &LostHost) -> Vec<u64> {
    assert_eq!(r.code, Some(0), "{}", r.err);
    let named = r.err.contains("its agents 4, 5 are taken over on local")
        || r.err.contains("host h1 held agents 4, 5");
    assert!(
        named,
        "the lost host and both its agents are named: {}",
        r.err
    );
    let mut down = Vec::new();
    for a in [4, 5] {
        let line = r
            .err
            .lines()
            .find(|l| l.contains(&format!("formation run: agent {a} taken over at step")))
            .unwrap_or_else(|| panic!("agent {a} is taken over: {}", r.err));
        // Cold where no checkpoint had come from h1 (the agents checkpoint step 0 at once, and
        // their daemon forwards it within some tens of ms), else warm from it.
        assert!(
            line.contains("(cold") || line.contains("(warm"),
            "agent {a}: {line}"
        );
        down.push(
            line.split("down from step ")
                .nth(1)
                .and_then(|x| x.trim_end_matches(')').parse().ok())
                .unwrap_or(0),
        );
    }
    let s = formation_tests::summary(&r.out);
    for (i, a) in s["agents"].as_array().unwrap().iter().enumerate() {
        assert_eq!(a["host"], "local", "agent {} ends on the launcher", i + 1);
        assert_eq!(a["restarts"], u64::from(i >= 3), "agent {}", i + 1);
    }
    let lost: Vec<u64> = s["events"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|e| e["kind"] == "host_lost")
        .filter_map(|e| e["agent"].as_u64())
        .collect();
    assert_eq!(lost.len(), 2, "one event per agent lost: {}", s["events"]);
    assert!(lost.contains(&4) && lost.contains(&5), "{lost:?}");
    assert_no_residue("the launcher", &r.residue);
    formation_tests::host::assert_gone(&r.remote_pids);
    eprintln!(
        "taken over from steps {down:?}; run ended {:.0} ms after the kill",
        r.ended_after.as_secs_f64() * 1e3
    );
    down
}

/// A host lost as the run starts (its daemon SIGKILLed as soon as every process is started, before
/// or at the first step): its agents start afresh here from the scenario's initial state.
fn host_lost_at_launch(tag: &str, realtime: bool) {
    let mut args = vec![
        "--set",
        "simulation.duration_s=3",
        "--restart",
        "on-failure",
    ];
    if realtime {
        args.push("--realtime");
    }
    let r = run_and_kill_the_remote_daemon(tag, &args, KillAt::After(Duration::ZERO));
    assert_taken_over_here(&r);
    let _ = std::fs::remove_dir_all(&r.dir);
}

/// A host lost before its agents' first periodic checkpoint (only the one of step 0 exists): they are
/// taken over here, warm from step 0 when it had been forwarded, else cold.
fn host_lost_before_the_first_checkpoint(tag: &str, realtime: bool) {
    let mut args = vec![
        "--set",
        "simulation.duration_s=8",
        "--set",
        LATE_FIRST_CHECKPOINT_S,
        "--restart",
        "on-failure",
    ];
    if realtime {
        args.push("--realtime");
    }
    let r = run_and_kill_the_remote_daemon(tag, &args, KillAt::Written(1 << 20));
    for d in assert_taken_over_here(&r) {
        assert!(
            d > 0 && d < 5000,
            "down from step {d}: mid-run, before step 5000"
        );
    }
    let _ = std::fs::remove_dir_all(&r.dir);
}

#[test]
fn a_host_whose_link_goes_down_early_is_taken_over_here_after_its_lease() {
    if !available("a_host_whose_link_goes_down_early_is_taken_over_here_after_its_lease") {
        return;
    }
    let r = run_and_lose_the_remote_host(
        "lost-link",
        &[
            "--set",
            "simulation.duration_s=8",
            "--set",
            LATE_FIRST_CHECKPOINT_S,
            "--restart",
            "on-failure",
        ],
        KillAt::Written(1 << 20),
        true,
    );
    for d in assert_taken_over_here(&r) {
        assert!(d > 0 && d < 5000, "down from step {d}");
    }
    let _ = std::fs::remove_dir_all(&r.dir);
}

/// A host cut off past its lease and then back (a partition that heals): the orchestrator
/// declares it lost after the daemon's 1 s lease and takes its agents over here, each once; the
/// daemon, told a 20 s lease by the orchestrator, has not noticed the cut, and learns when the
/// link is back that the orchestrator dropped it (its link to it is closed): it ends its agents.
/// The run exits 0. A frame it would still send is refused by the launcher's bridge, re-planned
/// without the host, and counted as fenced (`formation run: N frame(s) from lost hosts refused
/// after they were fenced`, printed when N > 0).
#[test]
fn a_host_cut_off_past_its_lease_and_back_ends_its_agents_and_the_run_goes_on() {
    if !available("a_host_cut_off_past_its_lease_and_back_ends_its_agents_and_the_run_goes_on") {
        return;
    }
    let dir = work_dir("lost-back");
    let mut hosts = Hosts::new(2, &dir);
    let ep = format!("tcp/{}:7447", hosts.addrs[1]);
    let auth = hosts.auth.display().to_string();
    hosts.start_daemon_with(
        1,
        &dir,
        &["--listen", &ep, "--auth", &auth, "--lease-ms", "1000"],
        &[],
    );
    let residue = dir.join("residue-launcher.txt");
    let out = dir.join("run");
    let err_path = dir.join("run.err");
    let args = [
        "--set",
        "simulation.duration_s=120",
        "--restart",
        "on-failure",
        "--lease-ms",
        "20000",
    ];
    let mut run = spawn_split_paper_run(&hosts, &residue, &args, &out, &err_path, None);
    until_written(&mut run, &out, 1 << 20, Duration::from_secs(120));
    let veth = hosts.names[0].replace("h0", "a1");
    ip(&["-n", &hosts.names[0], "link", "set", &veth, "down"]);
    let cut = Instant::now();
    let err = || std::fs::read_to_string(&err_path).unwrap_or_default();
    while !err().contains("lost with host h1") {
        assert!(
            cut.elapsed() < Duration::from_secs(30),
            "h1 not declared lost: {}",
            err()
        );
        assert!(
            run.try_wait().unwrap().is_none(),
            "the run ended: {}",
            err()
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    std::thread::sleep(Duration::from_millis(1500));
    ip(&["-n", &hosts.names[0], "link", "set", &veth, "up"]);
    let t1 = Instant::now();
    let st = loop {
        if let Some(st) = run.try_wait().unwrap() {
            break st;
        }
        assert!(
            t1.elapsed() < Duration::from_secs(180),
            "the run hangs: {}",
            err()
        );
        std::thread::sleep(Duration::from_millis(50));
    };
    let err = err();
    assert_eq!(st.code(), Some(0), "{err}");
    for a in [4, 5] {
        let started = err
            .lines()
            .filter(|l| l.contains(&format!("formation run: agent {a} taken over at step")));
        assert_eq!(started.count(), 1, "agent {a} is started once: {err}");
    }
    let log = dir.join("daemon-1.log");
    let daemon_log = || std::fs::read_to_string(&log).unwrap_or_default();
    let back = Instant::now();
    while !daemon_log().contains("its orchestrator is gone; ending it") {
        assert!(
            back.elapsed() < Duration::from_secs(30),
            "the daemon did not end the run once back: {}",
            daemon_log()
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    let start = err
        .lines()
        .find(|l| l.contains("formation run: id"))
        .unwrap();
    let pids = formation_tests::run::start_line_pids(start);
    formation_tests::host::assert_gone(&pids[5..]);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_host_lost_while_another_hosts_takeover_is_under_way_is_taken_over_in_its_turn() {
    if !available("a_host_lost_while_another_hosts_takeover_is_under_way_is_taken_over_in_its_turn")
    {
        return;
    }
    let dir = work_dir("lost-two");
    let mut hosts = Hosts::new(3, &dir);
    hosts.start_daemon(1, &dir, &[]);
    hosts.start_daemon(2, &dir, &[]);
    let residue = dir.join("residue-launcher.txt");
    let out = dir.join("run");
    let err_path = dir.join("run.err");
    let mut v: Vec<String> = [
        "run",
        "paper",
        "--set",
        "simulation.duration_s=8",
        "--restart",
        "on-failure",
        "--hosts",
        "h1,h2",
        "--place",
        "4@h1",
        "--place",
        "5@h2",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    v.extend(hosts.connect_args());
    v.extend(["--auth".to_string(), hosts.auth.display().to_string()]);
    v.extend(["--out".to_string(), out.display().to_string()]);
    let refs: Vec<&str> = v.iter().map(String::as_str).collect();
    let mut run = hosts
        .command(0, Some(&residue), &refs)
        .stdout(Stdio::null())
        .stderr(std::fs::File::create(&err_path).unwrap())
        .spawn()
        .expect("formation run starts");
    // Mid-run, after the first checkpoints (the first MiB of trajectory.csv is some hundreds of
    // steps; wait for several).
    until_written(&mut run, &out, 4 << 20, Duration::from_secs(120));
    // h1 first; h2 while agent 4's takeover is under way (its successor is started tens of
    // steps after the take-down and says hello some hundreds of ms later).
    let mut d1 = hosts.daemons.remove(0);
    // SAFETY: kill(2) on our own child.
    unsafe { libc::kill(d1.id() as libc::pid_t, libc::SIGKILL) };
    let _ = d1.wait();
    let t_kill = Instant::now();
    while !std::fs::read_to_string(&err_path)
        .unwrap_or_default()
        .contains("host h1 lost")
    {
        assert!(
            t_kill.elapsed() < Duration::from_secs(10),
            "h1's loss is not named"
        );
        std::thread::sleep(Duration::from_millis(2));
    }
    let mut d2 = hosts.daemons.remove(0);
    // SAFETY: kill(2) on our own child.
    unsafe { libc::kill(d2.id() as libc::pid_t, libc::SIGKILL) };
    let _ = d2.wait();
    let st = run.wait().unwrap();
    let err = std::fs::read_to_string(&err_path).unwrap();
    assert_eq!(st.code(), Some(0), "{err}");
    for (a, h) in [(4, "h1"), (5, "h2")] {
        assert!(
            err.contains(&format!(
                "host {h} lost; its agents {a} are taken over on local"
            )),
            "{h} and agent {a} named: {err}"
        );
        assert!(
            err.contains(&format!("formation run: agent {a} taken over at step")),
            "agent {a} taken over: {err}"
        );
    }
    let s = formation_tests::summary(&out);
    for (i, a) in s["agents"].as_array().unwrap().iter().enumerate() {
        assert_eq!(a["host"], "local", "agent {} ends on the launcher", i + 1);
    }
    assert_no_residue(
        "the launcher",
        &std::fs::read_to_string(&residue).unwrap_or_default(),
    );
    eprintln!("two hosts lost one after the other, stderr:\n{err}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_stopped_remote_agent_is_named_stopped_with_its_host_when_the_run_stalls() {
    if !available("a_stopped_remote_agent_is_named_stopped_with_its_host_when_the_run_stalls") {
        return;
    }
    let dir = work_dir("stopped-remote");
    let mut hosts = Hosts::new(2, &dir);
    hosts.start_daemon(1, &dir, &[]);
    let residue = dir.join("residue-launcher.txt");
    let out = dir.join("run");
    let err_path = dir.join("run.err");
    let args = [
        "--set",
        "simulation.duration_s=60",
        "--stall-timeout-ms",
        "1000",
    ];
    let mut run = spawn_split_paper_run(&hosts, &residue, &args, &out, &err_path, None);
    until_written(&mut run, &out, 1 << 20, START_BOUND);
    let err = std::fs::read_to_string(&err_path).unwrap();
    let start = err
        .lines()
        .find(|l| l.contains("formation run: id"))
        .unwrap();
    let pid = formation_tests::run::start_line_pids(start)[5];
    // Agent 4, on h1 (same pid namespace: the namespaces split network and mounts only).
    // SAFETY: kill(2) with SIGSTOP on a process of this test's run.
    unsafe { libc::kill(pid as libc::pid_t, libc::SIGSTOP) };
    let st = run.wait().unwrap();
    let err = std::fs::read_to_string(&err_path).unwrap();
    assert_eq!(st.code(), Some(1), "{err}");
    assert!(
        err.contains(&format!(
            "agent 4 (--agent 3) on h1 (pid {pid} on host h1) made no progress for"
        )) && err.contains("(stopped)"),
        "the stopped remote agent is named with its host: {err}"
    );
    assert_no_residue(
        "the launcher",
        &std::fs::read_to_string(&residue).unwrap_or_default(),
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_host_lost_at_launch_under_on_failure_has_its_agents_started_afresh_here_lockstep() {
    if !available(
        "a_host_lost_at_launch_under_on_failure_has_its_agents_started_afresh_here_lockstep",
    ) {
        return;
    }
    host_lost_at_launch("lost-launch", false);
}

#[test]
fn a_host_lost_at_launch_under_on_failure_has_its_agents_started_afresh_here_realtime() {
    if !available(
        "a_host_lost_at_launch_under_on_failure_has_its_agents_started_afresh_here_realtime",
    ) {
        return;
    }
    host_lost_at_launch("lost-launch-rt", true);
}

#[test]
fn a_host_lost_before_its_first_periodic_checkpoint_is_taken_over_here_lockstep() {
    if !available("a_host_lost_before_its_first_periodic_checkpoint_is_taken_over_here_lockstep") {
        return;
    }
    host_lost_before_the_first_checkpoint("lost-early", false);
}

#[test]
fn a_host_lost_before_its_first_periodic_checkpoint_is_taken_over_here_realtime() {
    if !available("a_host_lost_before_its_first_periodic_checkpoint_is_taken_over_here_realtime") {
        return;
    }
    host_lost_before_the_first_checkpoint("lost-early-rt", true);
}

/// Runs `formation run ARGS --out OUT` in the launcher namespace without any host (one machine);
/// (exit code, stderr).
fn run_one_host(hosts: &Hosts, dir: &Path, args: &[&str], out: &Path) -> (i32, String) {
    let residue = dir.join("residue-one-host.txt");
    let mut v: Vec<&str> = vec!["run"];
    v.extend_from_slice(args);
    let o = out.display().to_string();
    v.extend_from_slice(&["--out", &o]);
    let r = hosts
        .command(0, Some(&residue), &v)
        .stdout(Stdio::null())
        .output()
        .expect("formation run starts");
    (
        r.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&r.stderr).into_owned(),
    )
}

/// Mean over the agents of the whole-run RMS formation error, m.
fn mean_rms(s: &serde_json::Value) -> f64 {
    let a = s["agents"].as_array().expect("agents");
    a.iter()
        .map(|x| x["rms_formation_error_m"]["whole"].as_f64().unwrap())
        .sum::<f64>()
        / a.len() as f64
}

/// How much worse (mean whole-run RMS formation error) the split realtime run may be than the
/// one-host realtime run of the same test. The goal of issue 19 is 1.1; realtime on a loaded
/// 2-core machine varies from run to run by more than that (docs/multi-host.md, "Realtime across
/// hosts", gives the measured ratios), so the test pins a bound that catches a broken split run
/// (4-8x before the late-command policy) without failing on the machine's noise.
const SPLIT_RMS_FACTOR: f64 = 1.5;

/// Each thread of process `pid`: (name, scheduling policy, realtime priority), from
/// `/proc/<pid>/task/*/stat` (fields 41 and 40, counted after the parenthesised name).
fn thread_policies(pid: u32) -> Vec<(String, u32, u32)> {
    let mut v = Vec::new();
    let Ok(tasks) = std::fs::read_dir(format!("/proc/{pid}/task")) else {
        return v;
    };
    for t in tasks.flatten() {
        let comm = std::fs::read_to_string(t.path().join("comm")).unwrap_or_default();
        let stat = std::fs::read_to_string(t.path().join("stat")).unwrap_or_default();
        let Some(rest) = stat.rsplit_once(") ").map(|(_, r)| r) else {
            continue;
        };
        let f: Vec<&str> = rest.split_whitespace().collect();
        // `rest` starts at field 3 (state): field n is f[n - 3].
        if let (Some(prio), Some(policy)) = (f.get(37), f.get(38)) {
            v.push((
                comm.trim().to_string(),
                policy.parse().unwrap_or(u32::MAX),
                prio.parse().unwrap_or(u32::MAX),
            ));
        }
    }
    v
}

/// The pid of the `formation run` whose command line names `out`.
fn run_pid(out: &Path) -> Option<u32> {
    let out = out.display().to_string();
    std::fs::read_dir("/proc").ok()?.flatten().find_map(|e| {
        let pid: u32 = e.file_name().to_str()?.parse().ok()?;
        let cmd = std::fs::read_to_string(e.path().join("cmdline")).ok()?;
        let args: Vec<&str> = cmd.split('\0').collect();
        (args.get(1) == Some(&"run") && args.contains(&out.as_str())).then_some(pid)
    })
}

/// Whether a process's message path is under `SCHED_FIFO` `prio` (policy 1): its bridge's sending
/// thread and every Zenoh runtime thread (`tx-*`, `rx-*`, `acc-*`, `net-*`, `app-*`; at least
/// three).
fn message_path_raised(threads: &[(String, u32, u32)], prio: u32) -> bool {
    let link = |n: &str| {
        ["tx-", "rx-", "acc-", "net-", "app-"].iter().any(|p| {
            n.strip_prefix(p)
                .is_some_and(|d| d.bytes().all(|b| b.is_ascii_digit()))
        })
    };
    let bridge = threads
        .iter()
        .any(|(n, p, r)| n == "bridge-out" && *p == 1 && *r == prio);
    let raised = threads
        .iter()
        .filter(|(n, _, _)| link(n))
        .collect::<Vec<_>>();
    bridge && raised.len() >= 3 && raised.iter().all(|(_, p, r)| *p == 1 && *r == prio)
}

#[test]
fn a_realtime_split_run_carries_its_messages_under_its_fifo_priority_on_both_hosts_and_the_daemon_drops_it_after(
) {
    const TEST: &str = "a_realtime_split_run_carries_its_messages_under_its_fifo_priority_on_both_hosts_and_the_daemon_drops_it_after";
    if !available(TEST) {
        return;
    }
    // Root (needed for the namespaces) has CAP_SYS_NICE: `--rt-priority auto` and the daemon's
    // `--max-rt-priority auto` both come to SCHED_FIFO 10.
    let dir = work_dir("rt-sched");
    let mut hosts = Hosts::new(2, &dir);
    hosts.start_daemon(1, &dir, &[]);
    let daemon = hosts.daemons[0].id();
    let out = dir.join("split");
    let log = dir.join("run.log");
    let mut v: Vec<String> = [
        "run",
        "paper",
        "--realtime",
        "--set",
        "simulation.duration_s=6",
        "--hosts",
        "h1",
        "--place",
        "4,5@h1",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    v.extend(hosts.connect_args());
    v.extend(["--auth".into(), hosts.auth.display().to_string()]);
    v.extend(["--out".into(), out.display().to_string()]);
    let refs: Vec<&str> = v.iter().map(String::as_str).collect();
    let residue = dir.join("residue-launcher.txt");
    let mut run = hosts
        .command(0, Some(&residue), &refs)
        .stdout(Stdio::null())
        .stderr(std::fs::File::create(&log).unwrap())
        .spawn()
        .expect("formation run starts");
    // Both message paths raised at one moment of the run (each bridge raises its threads when it
    // starts, before any role process does).
    let t0 = Instant::now();
    let mut seen = (Vec::new(), Vec::new());
    let raised = loop {
        let orchestrator = run_pid(&out).map(thread_policies).unwrap_or_default();
        let host = thread_policies(daemon);
        if message_path_raised(&orchestrator, 10) && message_path_raised(&host, 10) {
            break true;
        }
        if !orchestrator.is_empty() {
            seen = (orchestrator, host);
        }
        if t0.elapsed() > START_BOUND || run.try_wait().unwrap().is_some() {
            break false;
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    let code = run.wait().unwrap().code().unwrap_or(-1);
    let err = std::fs::read_to_string(&log).unwrap_or_default();
    assert!(
        raised,
        "threads (name, policy, priority), launcher: {:?}\nhost h1: {:?}\n{err}",
        seen.0, seen.1
    );
    assert_eq!(code, 0, "realtime split run failed:\n{err}");
    assert!(
        err.contains("formation run: the bridge and")
            && err.contains("Zenoh link threads under SCHED_FIFO 10"),
        "the run says what its message path runs under:\n{err}"
    );
    // The run over, the daemon's link threads go back to the normal policy.
    let t0 = Instant::now();
    let back = loop {
        let host = thread_policies(daemon);
        if host.iter().all(|(_, p, _)| *p == 0) {
            break None;
        }
        if t0.elapsed() > Duration::from_secs(20) {
            break Some(host);
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    let daemon_log = std::fs::read_to_string(dir.join("daemon-1.log")).unwrap_or_default();
    assert!(
        back.is_none(),
        "threads of h1 after the run: {back:?}\n{daemon_log}"
    );
    assert!(
        daemon_log.contains("get at most SCHED_FIFO 10")
            && daemon_log.contains("Zenoh link threads under SCHED_FIFO 10"),
        "the daemon says what it grants and what the run's message path got:\n{daemon_log}"
    );
    let left = hosts.stop_daemons();
    assert_no_residue("host h1", &left[0]);
}

#[test]
fn a_realtime_split_run_measures_every_cross_host_link_and_flies_as_well_as_on_one_host() {
    if !available(
        "a_realtime_split_run_measures_every_cross_host_link_and_flies_as_well_as_on_one_host",
    ) {
        return;
    }
    let dir = work_dir("realtime");
    let mut hosts = Hosts::new(2, &dir);
    hosts.start_daemon(1, &dir, &[]);
    let common = ["paper", "--realtime", "--set", "simulation.duration_s=12"];
    let one = dir.join("one");
    let (code, err) = run_one_host(&hosts, &dir, &common, &one);
    assert_eq!(code, 0, "one-host realtime run failed:\n{err}");
    let split = dir.join("split");
    let mut args = common.to_vec();
    args.extend_from_slice(&["--hosts", "h1", "--place", "4,5@h1"]);
    let (code, err, residue) = run_in(&hosts, &dir, &args, &split, true);
    assert_eq!(code, 0, "realtime split run failed:\n{err}");
    assert!(
        !err.contains("no timing statistics") && !err.contains("timing statistics of the other"),
        "every agent's timing is collected: {err}"
    );
    assert_no_residue("the launcher", &residue);
    let left = hosts.stop_daemons();
    assert_no_residue("host h1", &left[0]);

    let s = formation_tests::summary(&split);
    let t = &s["timing"];
    // Both directions of the one cross-host link, measured on every step's messages.
    let links = t["links"].as_array().expect("timing.links");
    let names: Vec<&str> = links.iter().map(|l| l["link"].as_str().unwrap()).collect();
    assert!(
        names.contains(&"local->h1") && names.contains(&"h1->local"),
        "links named: {names:?}"
    );
    let steps = t["timed_steps"].as_u64().unwrap();
    for l in links {
        let q = |k: &str| l[k].as_f64().unwrap_or(f64::NAN);
        let (p50, p99, max) = (q("p50"), q("p99"), q("max"));
        assert!(
            p50.is_finite() && p50 > 0.0 && p50 <= p99 && p99 <= max && max < 1e6,
            "plausible one-way delays, µs: {l}"
        );
        assert!(
            l["samples"].as_u64().unwrap() >= steps,
            "at least one stamped message a step: {l}"
        );
    }
    // One kernel, one CLOCK_MONOTONIC: the estimate is within its own uncertainty of 0.
    let c = &t["clocks"][0];
    assert_eq!(c["host"], "h1");
    assert!(
        c["offset_us"].as_f64().unwrap().abs() <= c["uncertainty_us"].as_f64().unwrap() + 1.0,
        "{c}"
    );
    // Every agent's timing and delays, the remote ones included.
    let per_agent = t["delays"]["per_agent"].as_array().unwrap();
    assert_eq!(per_agent.len(), 5);
    for a in per_agent {
        let e = &a["effective_us"];
        assert!(e["samples"].as_u64().unwrap() > 0, "{a}");
        assert!(
            e["p50"].as_f64().unwrap() >= a["injected_us"]["p50"].as_f64().unwrap(),
            "the effective delay is at least the injected one: {a}"
        );
    }
    for a in t["state_to_command_latency_us"]["per_agent"]
        .as_array()
        .unwrap()
    {
        assert!(a["samples"].as_u64().unwrap() > 0, "{a}");
    }
    let (rms_one, rms_split) = (mean_rms(&formation_tests::summary(&one)), mean_rms(&s));
    eprintln!(
        "mean RMS formation error: one host {rms_one:.4} m, split {rms_split:.4} m (ratio {:.3}); links {}",
        rms_split / rms_one,
        serde_json::to_string(&t["links"]).unwrap()
    );
    assert!(
        rms_split <= SPLIT_RMS_FACTOR * rms_one,
        "split {rms_split} m vs one host {rms_one} m"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// `formation ps --json` read from outside the launcher's namespace (the runs folder is outside
/// its private /tmp; /proc is shared): the first run listed, once all its processes are.
fn listed_run(runs: &Path, run: &mut Child, err_path: &Path) -> serde_json::Value {
    let t0 = Instant::now();
    loop {
        let o = formation_tests::formation_in(runs, &["ps", "--json"]);
        let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap_or_default();
        if v["runs"][0]["processes"]
            .as_array()
            .is_some_and(|p| p.len() == 8)
        {
            return v["runs"][0].clone();
        }
        assert!(
            run.try_wait().unwrap().is_none() && t0.elapsed() < Duration::from_secs(60),
            "the run was never listed: {}",
            std::fs::read_to_string(err_path).unwrap_or_default()
        );
        std::thread::sleep(Duration::from_millis(50));
    }
}

#[test]
fn ps_and_inspect_show_the_agents_placed_on_another_host_with_that_host_and_its_pid() {
    if !available(
        "ps_and_inspect_show_the_agents_placed_on_another_host_with_that_host_and_its_pid",
    ) {
        return;
    }
    let dir = work_dir("ps");
    let mut hosts = Hosts::new(2, &dir);
    hosts.start_daemon(1, &dir, &[]);
    let runs = dir.join("runs");
    use std::os::unix::fs::DirBuilderExt;
    std::fs::DirBuilder::new()
        .mode(0o700)
        .create(&runs)
        .unwrap();
    let residue = dir.join("residue-launcher.txt");
    let out = dir.join("run");
    let err_path = dir.join("run.err");
    let mut run = spawn_split_paper_run(
        &hosts,
        &residue,
        &["--set", "simulation.duration_s=20"],
        &out,
        &err_path,
        Some(&runs),
    );
    let listed = listed_run(&runs, &mut run, &err_path);
    let procs = listed["processes"].as_array().unwrap();
    let orchestrator = procs[0]["pid"].as_u64().unwrap() as u32;
    for p in procs {
        let remote = matches!(p["agent"].as_u64(), Some(4 | 5));
        if remote {
            // On h1: its pid there (no pid namespace here, so it is this machine's too: the
            // agent process its daemon started), nothing read from this machine's /proc.
            assert_eq!(p["host"], "h1", "{p}");
            for k in ["alive", "cpu_percent", "cpu_percent_since_start"] {
                assert!(p[k].is_null(), "{k} of a remote process: {p}");
            }
            let pid = p["pid"].as_u64().unwrap();
            let index = p["agent"].as_u64().unwrap() - 1;
            let cmdline = std::fs::read(format!("/proc/{pid}/cmdline")).unwrap_or_default();
            assert!(
                String::from_utf8_lossy(&cmdline).contains(&format!("--agent\u{0}{index}\u{0}")),
                "pid {pid} is agent {}'s process on h1",
                index + 1
            );
        } else {
            assert_eq!(p["host"], "local", "{p}");
            assert_eq!(p["alive"], true, "{p}");
        }
    }
    // The table: a HOST column, `-` for what cannot be read here.
    let o = formation_tests::formation_in(&runs, &["ps"]);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(text.contains("HOST"), "{text}");
    let row = text
        .lines()
        .find(|l| l.split_whitespace().take(2).eq(["agent", "4"]))
        .unwrap_or_else(|| panic!("agent 4's row: {text}"));
    let cols: Vec<&str> = row.split_whitespace().collect();
    assert_eq!((cols[2], &cols[4..]), ("h1", &["-", "-", "-"][..]), "{row}");
    // `inspect` in the launcher's namespace (its /dev/shm): agent 4's host and pid there.
    let inspect = |agent: &str| {
        let o = Command::new("nsenter")
            .args([
                "--target",
                &orchestrator.to_string(),
                "--mount",
                "--net",
                "--",
            ])
            .arg(bin("formation"))
            .args(["inspect", "--agent", agent, "--json"])
            .env("FORMATION_RUNS_DIR", &runs)
            .env_remove("CARGO")
            .output()
            .expect("nsenter runs");
        assert!(
            o.status.success(),
            "inspect --agent {agent}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
        serde_json::from_slice::<serde_json::Value>(&o.stdout).expect("inspect prints JSON")
    };
    let four = inspect("4");
    let listed_four = procs.iter().find(|p| p["agent"] == 4).unwrap();
    assert_eq!(
        (&four["host"], &four["pid"]),
        (&listed_four["host"], &listed_four["pid"])
    );
    assert_eq!(four["agent"], 4);
    let one = inspect("1");
    assert_eq!(one["host"], "local", "{one}");
    let st = run.wait().unwrap();
    assert_eq!(
        st.code(),
        Some(0),
        "{}",
        std::fs::read_to_string(&err_path).unwrap_or_default()
    );
    assert_no_residue(
        "the launcher",
        &std::fs::read_to_string(&residue).unwrap_or_default(),
    );
    let left = hosts.stop_daemons();
    assert_no_residue("host h1", &left[0]);
    let _ = std::fs::remove_dir_all(&dir);
}

/// Moves the calling thread into network namespace `name` (`ip netns add` made it).
fn enter_netns(name: &str) {
    use std::os::fd::AsRawFd;
    let f = std::fs::File::open(format!("/var/run/netns/{name}")).expect("the namespace exists");
    // SAFETY: setns on an open namespace file, for this thread only.
    let r = unsafe { libc::setns(f.as_raw_fd(), libc::CLONE_NEWNET) };
    assert_eq!(r, 0, "setns {name}: {}", std::io::Error::last_os_error());
}

/// A TCP relay on a link of the test, recording every byte both ways (what a sniffer sees): it
/// listens on `ip` in namespace `from` and connects each connection on to `to` from namespace
/// `into`. Its threads end with the connections (the listener with the test process).
struct Relay {
    port: u16,
    captured: std::sync::Arc<std::sync::Mutex<Vec<u8>>>,
}

impl Relay {
    fn start(from: &str, ip: &str, into: &str, to: std::net::SocketAddr) -> Relay {
        use std::io::Write;
        let captured = std::sync::Arc::new(std::sync::Mutex::new(Vec::new()));
        let cap = captured.clone();
        let (tx, rx) = std::sync::mpsc::channel();
        let (from, ip, into) = (from.to_string(), ip.to_string(), into.to_string());
        std::thread::spawn(move || {
            enter_netns(&from);
            let l = std::net::TcpListener::bind((ip.as_str(), 0)).expect("the relay listens");
            tx.send(l.local_addr().unwrap().port()).unwrap();
            // Sockets made from now on are in the daemon's namespace; the listener stays.
            enter_netns(&into);
            for c in l.incoming() {
                let Ok(a) = c else { break };
                let Ok(b) = std::net::TcpStream::connect(to) else {
                    continue;
                };
                // As Zenoh's own sockets: no Nagle delay (a lockstep step is a few small frames).
                let _ = a.set_nodelay(true);
                let _ = b.set_nodelay(true);
                for (mut r, mut w) in [(a.try_clone().unwrap(), b.try_clone().unwrap()), (b, a)] {
                    let cap = cap.clone();
                    std::thread::spawn(move || {
                        let mut buf = [0u8; 65536];
                        while let Ok(n) = r.read(&mut buf) {
                            if n == 0 || w.write_all(&buf[..n]).is_err() {
                                break;
                            }
                            cap.lock().unwrap().extend_from_slice(&buf[..n]);
                        }
                        let _ = w.shutdown(std::net::Shutdown::Write);
                    });
                }
            }
        });
        Relay {
            port: rx.recv().expect("the relay's port"),
            captured,
        }
    }

    fn bytes(&self) -> Vec<u8> {
        self.captured.lock().unwrap().clone()
    }
}

fn contains(hay: &[u8], needle: &[u8]) -> bool {
    hay.windows(needle.len()).any(|w| w == needle)
}

/// `formation certs ARGS` (exit 0 asserted).
fn certs(args: &[&str]) {
    let o = formation_tests::formation(&[&["certs"][..], args].concat());
    assert!(
        o.status.success(),
        "formation certs {args:?}: {}",
        formation_tests::stderr_of(&o)
    );
}

/// The daemon's address on the link of host 1 and the launcher's (where a relay listens).
fn relay_addrs(hosts: &Hosts) -> (String, String) {
    let daemon_ip = hosts.addrs[1].clone();
    let relay_ip = format!("{}.1", daemon_ip.rsplit_once('.').unwrap().0);
    (daemon_ip, relay_ip)
}

/// A CA in `dir`, the folder of daemon h1 (certified for its address and the relay's, which the
/// orchestrator dials) and the launcher's: (h1's folder, the launcher's).
fn split_certificates(dir: &Path, daemon_ip: &str, relay_ip: &str) -> (PathBuf, PathBuf) {
    let (ca, h1, a) = (dir.join("ca"), dir.join("h1-tls"), dir.join("a-tls"));
    let s = |p: &Path| p.display().to_string();
    certs(&["init", "--dir", &s(&ca)]);
    certs(&[
        "issue",
        "--dir",
        &s(&ca),
        "--name",
        "h1",
        "--addr",
        daemon_ip,
        "--addr",
        relay_ip,
        "--out",
        &s(&h1),
    ]);
    certs(&["issue", "--dir", &s(&ca), "--name", "a", "--out", &s(&a)]);
    (h1, a)
}

/// A UDP relay on a link of the test, recording every datagram's bytes both ways (what a sniffer
/// sees): it receives on `ip` in namespace `from` and sends each client's datagrams on to `to`
/// from a socket of its own in namespace `into`, and the answers back to that client. Its
/// threads end with the test process.
struct UdpRelay {
    port: u16,
    captured: std::sync::Arc<std::sync::Mutex<Vec<u8>>>,
}

impl UdpRelay {
    fn start(from: &str, ip: &str, into: &str, to: std::net::SocketAddr) -> UdpRelay {
        use std::collections::HashMap;
        use std::net::UdpSocket;
        let captured = std::sync::Arc::new(std::sync::Mutex::new(Vec::new()));
        let cap = captured.clone();
        let (tx, rx) = std::sync::mpsc::channel();
        let (from, ip, into) = (from.to_string(), ip.to_string(), into.to_string());
        std::thread::spawn(move || {
            enter_netns(&from);
            let front = UdpSocket::bind((ip.as_str(), 0)).expect("the relay binds");
            tx.send(front.local_addr().unwrap().port()).unwrap();
            // Sockets made from now on are in the daemon's namespace; the front one stays.
            enter_netns(&into);
            let mut backs: HashMap<std::net::SocketAddr, UdpSocket> = HashMap::new();
            let mut buf = [0u8; 65536];
            while let Ok((n, client)) = front.recv_from(&mut buf) {
                cap.lock().unwrap().extend_from_slice(&buf[..n]);
                let back = backs.entry(client).or_insert_with(|| {
                    let b = UdpSocket::bind("0.0.0.0:0").expect("a relay socket");
                    b.connect(to).expect("the relay connects");
                    let (r, f, cap) = (
                        b.try_clone().unwrap(),
                        front.try_clone().unwrap(),
                        cap.clone(),
                    );
                    std::thread::spawn(move || {
                        let mut buf = [0u8; 65536];
                        while let Ok(n) = r.recv(&mut buf) {
                            cap.lock().unwrap().extend_from_slice(&buf[..n]);
                            if f.send_to(&buf[..n], client).is_err() {
                                break;
                            }
                        }
                    });
                    b
                });
                let _ = back.send(&buf[..n]);
            }
        });
        UdpRelay {
            port: rx.recv().expect("the relay's port"),
            captured,
        }
    }

    fn bytes(&self) -> Vec<u8> {
        self.captured.lock().unwrap().clone()
    }
}

/// The password of [`Hosts`]'s `--auth` file, which must never cross a link.
const SECRET: &[u8] = b"tests-only-secret";

/// A capture of an encrypted link: it carried the runs (over 100 kB), and none of `formation`
/// (every key expression, the user name), `VehicleState`, `ControlCommand` or the password is
/// readable in it.
fn assert_no_plaintext(wire: &[u8], link: &str) {
    assert!(
        wire.len() > 100_000,
        "the runs crossed the relay: {} bytes",
        wire.len()
    );
    for plain in [
        &b"formation"[..],
        b"VehicleState",
        b"ControlCommand",
        SECRET,
    ] {
        assert!(
            !contains(wire, plain),
            "'{}' is readable on the {link} link",
            String::from_utf8_lossy(plain)
        );
    }
}

/// Starts daemon h1 on `TRANSPORT/DAEMON_IP:7447` with `--tls` (its folder `h1`) and `--auth`;
/// returns the arguments of a split run of `scenario` (agents 4-5 on h1) connecting to `connect`
/// with the launcher's folder `a` and `--auth`.
fn start_encrypted_split(
    hosts: &mut Hosts,
    dir: &Path,
    transport: &str,
    (daemon_ip, h1, a): (&str, &Path, &Path),
    scenario: &[&str],
    connect: &str,
) -> Vec<String> {
    let auth = hosts.auth.display().to_string();
    let listen = format!("{transport}/{daemon_ip}:7447");
    let h1 = h1.display().to_string();
    hosts.start_daemon_with(
        1,
        dir,
        &["--listen", &listen, "--tls", &h1, "--auth", &auth],
        &[],
    );
    let a = a.display().to_string();
    scenario
        .iter()
        .chain(&["--hosts", "h1", "--place", "4,5@h1"])
        .chain(&["--connect", connect, "--tls", &a, "--auth", &auth])
        .map(|s| s.to_string())
        .collect()
}

/// How many split runs the QUIC test makes over one daemon: every one must complete, no retry
/// (Zenoh's QUIC link has none of its TLS link's drops: docs/multi-host.md).
const QUIC_RUNS: usize = 3;

#[test]
fn a_quic_split_run_is_byte_identical_to_sim_run_after_run_and_its_datagrams_show_no_plaintext() {
    if !available(
        "a_quic_split_run_is_byte_identical_to_sim_run_after_run_and_its_datagrams_show_no_plaintext",
    ) {
        return;
    }
    let dir = work_dir("quic");
    let mut hosts = Hosts::new(2, &dir);
    let (daemon_ip, relay_ip) = relay_addrs(&hosts);
    let (h1, a) = split_certificates(&dir, &daemon_ip, &relay_ip);
    let scenario = ["paper", "--set", "simulation.duration_s=2"];
    // The relay's port is known before the daemon listens: UDP needs no listener to bind to.
    let relay = UdpRelay::start(
        &hosts.names[0],
        &relay_ip,
        &hosts.names[1],
        format!("{daemon_ip}:7447").parse().unwrap(),
    );
    let connect = format!("quic/{relay_ip}:{}", relay.port);
    let args = start_encrypted_split(
        &mut hosts,
        &dir,
        "quic",
        (&daemon_ip, &h1, &a),
        &scenario,
        &connect,
    );
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    for run in 1..=QUIC_RUNS {
        let out = dir.join(format!("run-quic-{run}"));
        let (code, err, residue) = run_in_with(&hosts, &dir, &args, &out);
        assert_eq!(
            code, 0,
            "QUIC split run {run} of {QUIC_RUNS} failed:\n{err}"
        );
        assert_no_residue("the launcher", &residue);
        if run == 1 {
            formation_tests::assert_trajectory_is_sims(&out, &scenario, &dir.join("sim"));
        } else {
            let first = std::fs::read(dir.join("run-quic-1/trajectory.csv")).unwrap();
            let this = std::fs::read(out.join("trajectory.csv")).expect("the run's trajectory");
            assert!(
                this == first,
                "QUIC split run {run} differs from run 1 (and sim)"
            );
        }
    }
    for left in hosts.stop_daemons() {
        assert_no_residue("host h1", &left);
    }
    assert_no_plaintext(&relay.bytes(), "QUIC");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_tls_split_run_is_byte_identical_to_sim_and_its_link_shows_no_plaintext_unlike_tcp() {
    if !available(
        "a_tls_split_run_is_byte_identical_to_sim_and_its_link_shows_no_plaintext_unlike_tcp",
    ) {
        return;
    }
    let dir = work_dir("tls");
    let mut hosts = Hosts::new(2, &dir);
    let (daemon_ip, relay_ip) = relay_addrs(&hosts);
    let (h1, a) = split_certificates(&dir, &daemon_ip, &relay_ip);
    let auth = hosts.auth.display().to_string();
    let scenario = ["paper", "--set", "simulation.duration_s=2"];

    // TLS (with a user and password inside it): byte-identical, and nothing readable on the wire.
    let relay = Relay::start(
        &hosts.names[0],
        &relay_ip,
        &hosts.names[1],
        format!("{daemon_ip}:7447").parse().unwrap(),
    );
    let connect = format!("tls/{relay_ip}:{}", relay.port);
    let args = start_encrypted_split(
        &mut hosts,
        &dir,
        "tls",
        (&daemon_ip, &h1, &a),
        &scenario,
        &connect,
    );
    /// Tries of the TLS split run when its link drops (Zenoh 1.10.2's TLS race, nothing else).
    const TLS_TRIES: u32 = 5;
    // Zenoh 1.10.2's TLS link can drop mid-run (docs/multi-host.md, the known problem of its
    // TLS link): such a run names its host as lost, and the daemon whose link dropped may answer
    // no more. Up to five tries, each with a fresh daemon, for that cause alone (three all
    // dropped in one CI run on an idle machine); any other failure fails at once.
    let mut args = args;
    let mut attempt = 0;
    let (out, code, err, residue) = loop {
        attempt += 1;
        let out = dir.join(format!("run-tls-{attempt}"));
        let argv: Vec<&str> = args.iter().map(String::as_str).collect();
        let (code, err, residue) = run_in_with(&hosts, &dir, &argv, &out);
        let dropped = err.contains("lost with host") || err.contains("did not answer within");
        if code == 0 || attempt == TLS_TRIES || !dropped {
            break (out, code, err, residue);
        }
        eprintln!("TLS split run {attempt} lost its host (the known race of zenoh-link-tls 1.10.2):\n{err}");
        // The race can corrupt the daemon's memory and abort it: nothing of it is read here.
        hosts.end_daemons();
        args = start_encrypted_split(
            &mut hosts,
            &dir,
            "tls",
            (&daemon_ip, &h1, &a),
            &scenario,
            &connect,
        );
    };
    assert_eq!(code, 0, "the TLS split run failed:\n{err}");
    assert_no_residue("the launcher", &residue);
    for left in hosts.stop_daemons() {
        assert_no_residue("host h1", &left);
    }
    formation_tests::assert_trajectory_is_sims(&out, &scenario, &dir.join("sim"));
    assert_no_plaintext(&relay.bytes(), "TLS");

    // The control: the same run over TCP with a user and password shows keys and wire types in
    // clear (the password itself never crosses: Zenoh sends a keyed hash of it).
    let listen = format!("tcp/{daemon_ip}:7448");
    hosts.start_daemon_with(1, &dir, &["--listen", &listen, "--auth", &auth], &[]);
    let relay = Relay::start(
        &hosts.names[0],
        &relay_ip,
        &hosts.names[1],
        format!("{daemon_ip}:7448").parse().unwrap(),
    );
    let connect = format!("tcp/{relay_ip}:{}", relay.port);
    let args: Vec<&str> = scenario
        .iter()
        .chain(&["--hosts", "h1", "--place", "4,5@h1"])
        .copied()
        .chain(["--connect", &connect, "--auth", &auth])
        .collect();
    let (code, err, _) = run_in_with(&hosts, &dir, &args, &dir.join("run-tcp"));
    assert_eq!(code, 0, "the TCP split run failed:\n{err}");
    hosts.stop_daemons();
    let wire = relay.bytes();
    for plain in [&b"formation/"[..], b"VehicleState", b"formation"] {
        assert!(
            contains(&wire, plain),
            "'{}' is readable on the TCP link",
            String::from_utf8_lossy(plain)
        );
    }
    assert!(!contains(&wire, SECRET), "the password never crosses");
    let _ = std::fs::remove_dir_all(&dir);
}
