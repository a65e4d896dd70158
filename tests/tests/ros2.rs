//! End to end, the ROS 2 view (docs/ros2.md), checked by outside readers that nobody here wrote
//! and that need no ROS 2 install:
//! - `--record rosbag2` writes a rosbag2 folder that PyPI `rosbags` opens, deserialising every
//!   message with the types and counts of `trajectory.csv`'s steps, and whose MCAP file PyPI
//!   `mcap-ros2-support` decodes; a lockstep run writes the same bytes as `formation sim`;
//! - `--ros2` publishes on the DDS wire: a subscriber on PyPI `cyclonedds` (another DDS
//!   implementation) receives every agent's poses, the last of each equal to `trajectory.csv` at
//!   its stamp, and the `/tf` frames, while the run stays byte-identical to `formation sim`.
//!
//! The interpreter is `$FORMATION_PYTHON` with `rosbags`, `mcap-ros2-support` and `cyclonedds`
//! (`.ci/run` installs them into `target/pyenv`). Without them the Python part is skipped with a
//! message, unless `FORMATION_REQUIRE_ROS2=1` (set by `.ci/run`): then it fails.

use formation_runtime::record::csv::Column;
use formation_runtime::record::table::Trajectory;
use formation_tests::ip;
use formation_tests::run::RunningRun;
use formation_tests::{bin, sim, temp_dir, workspace_root};
use serde_json::Value;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdout, Command, Stdio};
use std::time::Duration;

/// Long enough for any run here; a run that takes longer is a hang.
const RUN_TIMEOUT: Duration = Duration::from_secs(120);

/// Simulated seconds of each run here.
const DURATION: &str = "simulation.duration_s=2";

/// How `.ci/run` provides the readers.
const INSTALL: &str =
    "target/pyenv/bin/pip install rosbags mcap-ros2-support cyclonedds (see .ci/run)";

/// The interpreter with the ROS 2 readers, `None` (after saying why) when missing and not
/// required; a panic when `FORMATION_REQUIRE_ROS2=1`.
fn python_or_skip(test: &str) -> Option<PathBuf> {
    let found = (|| {
        let py = std::env::var_os("FORMATION_PYTHON")
            .filter(|p| !p.is_empty())
            .map(PathBuf::from)
            .ok_or("FORMATION_PYTHON is not set".to_string())?;
        let o = Command::new(&py)
            .args(["-c", "import rosbags, mcap_ros2, cyclonedds"])
            .output()
            .map_err(|e| format!("cannot start {}: {e}", py.display()))?;
        if o.status.success() {
            Ok(py)
        } else {
            Err(format!(
                "{} lacks a ROS 2 reader: {}",
                py.display(),
                String::from_utf8_lossy(&o.stderr).trim()
            ))
        }
    })();
    match found {
        Ok(py) => Some(py),
        Err(why) if std::env::var("FORMATION_REQUIRE_ROS2").as_deref() == Ok("1") => {
            panic!("{test}: FORMATION_REQUIRE_ROS2=1 but {why}; {INSTALL}")
        }
        Err(why) => {
            eprintln!(
                "{test}: skipped: {why}; {INSTALL}; FORMATION_REQUIRE_ROS2=1 makes this a failure"
            );
            None
        }
    }
}

fn script(name: &str) -> PathBuf {
    workspace_root().join("tests/python").join(name)
}

/// A DDS domain for one test, so that tests running at once do not hear each other.
fn random_domain() -> u16 {
    // Tests of this binary run side by side: two runs on one domain would hear each other (a
    // realtime run's subscriber read the lockstep run's poses). A per-process base (time, process)
    // plus a counter gives every test of this process its own domain.
    static NEXT: std::sync::atomic::AtomicU32 = std::sync::atomic::AtomicU32::new(0);
    static BASE: std::sync::OnceLock<u32> = std::sync::OnceLock::new();
    let base = *BASE.get_or_init(|| {
        let nanos = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map(|d| d.subsec_nanos())
            .unwrap_or(0);
        nanos ^ std::process::id().wrapping_mul(2_654_435_761)
    });
    let k = NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    // 1..=200: inside ROS 2's usable range, never the default domain 0.
    1 + ((base % 200 + k) % 200) as u16
}

/// Rows of `trajectory.csv`: (agent id 1-based, t, position) in file order.
fn trajectory(dir: &Path) -> Vec<(usize, f64, [f64; 3])> {
    let tr = Trajectory::read(&dir.join("trajectory.csv")).expect("trajectory.csv");
    let v = |r: &[f64], c: Column| tr.value(r, c);
    tr.rows()
        .iter()
        .map(|r| {
            (
                v(r, Column::Agent) as usize,
                v(r, Column::T),
                [v(r, Column::Px), v(r, Column::Py), v(r, Column::Pz)],
            )
        })
        .collect()
}

/// Asserts that `last` (the reader's last pose of agent `id`) is `trajectory.csv`'s last row of
/// that agent: same stamp (t in ns), same position to the bit.
fn assert_last_pose_is_trajectorys(rows: &[(usize, f64, [f64; 3])], id: usize, last: &Value) {
    let (_, t, p) = rows
        .iter()
        .rev()
        .find(|(a, _, _)| *a == id)
        .expect("rows of every agent");
    let stamp = last["stamp_ns"].as_u64().expect("a stamp");
    assert_eq!(
        stamp,
        (t * 1e9).round() as u64,
        "agent {id}: stamp of the last pose"
    );
    assert_eq!(last["frame_id"], "world", "agent {id}: frame");
    let got: Vec<f64> = last["position"]
        .as_array()
        .expect("a position")
        .iter()
        .map(|v| v.as_f64().expect("a number"))
        .collect();
    assert_eq!(got, p.to_vec(), "agent {id}: last position");
}

fn n_agents(rows: &[(usize, f64, [f64; 3])]) -> usize {
    rows.iter().map(|r| r.0).max().expect("rows")
}

#[test]
fn a_rosbag2_of_a_sim_is_read_back_by_rosbags_with_the_right_types_and_counts() {
    let dir = temp_dir("rosbag2");
    let args = ["--set", DURATION, "--record", "rosbag2"];
    sim(&args, &dir.join("sim"));
    let bag = dir.join("sim/rosbag2");
    let meta = std::fs::read_to_string(bag.join("metadata.yaml")).expect("metadata.yaml");
    assert!(meta.contains("storage_identifier: mcap"), "{meta}");
    let mut run = RunningRun::start(&args, &dir.join("lockstep"));
    let (st, _) = run.wait(RUN_TIMEOUT).expect("the run ends");
    assert!(st.success(), "formation run failed: {}", run.stderr());
    for f in ["metadata.yaml", "rosbag2_0.mcap"] {
        let a = std::fs::read(dir.join("lockstep/rosbag2").join(f)).expect("the run's bag");
        let b = std::fs::read(bag.join(f)).expect("sim's bag");
        assert!(a == b, "{f} differs between the lockstep run and sim");
    }

    let Some(python) = python_or_skip("rosbag2") else {
        return;
    };
    let o = Command::new(python)
        .arg(script("ros2_bag_check.py"))
        .arg(&bag)
        .output()
        .expect("python starts");
    assert!(
        o.status.success(),
        "ros2_bag_check.py failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    let found: Value = serde_json::from_slice(&o.stdout).expect("JSON from the checker");
    let rows = trajectory(&dir.join("sim"));
    let n = n_agents(&rows);
    let steps = rows.len() / n;
    let topics = &found["topics"];
    let expect = |topic: &str, ty: &str, count: usize| {
        assert_eq!(topics[topic]["type"], ty, "{topic}: type");
        assert_eq!(
            topics[topic]["count"].as_u64(),
            Some(count as u64),
            "{topic}: message count"
        );
    };
    expect("/clock", "rosgraph_msgs/msg/Clock", steps);
    expect("/tf", "tf2_msgs/msg/TFMessage", steps);
    expect(
        "/formation/markers",
        "visualization_msgs/msg/MarkerArray",
        steps,
    );
    expect("/formation/reference", "geometry_msgs/msg/PoseArray", steps);
    expect("/formation/events", "std_msgs/msg/String", 0);
    for id in 1..=n {
        let topic = format!("/formation/agent_{id}/pose");
        expect(&topic, "geometry_msgs/msg/PoseStamped", steps);
        assert_last_pose_is_trajectorys(&rows, id, &found["last_pose"][&topic]);
    }
    let total = steps * (4 + n);
    assert_eq!(found["deserialised"].as_u64(), Some(total as u64));
    assert_eq!(found["mcap_ros2_decoded"].as_u64(), Some(total as u64));
    let frames = found["tf_frames"].to_string();
    for id in 1..=n {
        assert!(
            frames.contains(&format!("[\"world\",\"agent_{id}\"]")),
            "{frames}"
        );
    }
    assert!(
        frames.contains("[\"world\",\"virtual_leader\"]"),
        "{frames}"
    );
}

/// A subscriber of tests/python/ros2_subscriber.py.
struct Subscriber;

impl Subscriber {
    /// Starts `cmd` (a Python interpreter, or a command that runs one) on the subscriber script
    /// for `n` agents: it reads until a pose stamped `end_ns` or later of each agent, or for
    /// `listen_s`, in DDS domain `domain` with Cyclone DDS configured by `cyclone`. Returns once
    /// its readers exist.
    fn start(
        mut cmd: Command,
        n: usize,
        end_ns: u64,
        listen_s: u32,
        domain: &str,
        cyclone: &str,
    ) -> (Child, BufReader<ChildStdout>) {
        let mut sub = cmd
            .arg(script("ros2_subscriber.py"))
            .args([n.to_string(), end_ns.to_string(), listen_s.to_string()])
            .env("ROS_DOMAIN_ID", domain)
            .env("CYCLONEDDS_URI", cyclone)
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("python starts");
        let mut out = BufReader::new(sub.stdout.take().expect("piped"));
        let mut line = String::new();
        out.read_line(&mut line).expect("the subscriber speaks");
        assert_eq!(line.trim(), "ready", "the subscriber's first line");
        (sub, out)
    }

    /// What it received (its JSON report), once it is done.
    fn report(sub: &mut Child, out: &mut BufReader<ChildStdout>) -> Value {
        let mut line = String::new();
        out.read_line(&mut line).expect("the subscriber's report");
        let _ = sub.wait();
        serde_json::from_str(&line).expect("JSON from the subscriber")
    }
}

/// A Cyclone DDS configuration on interface `iface` that also discovers by unicast at `peer`,
/// with or without `multicast`.
fn cyclone_config(iface: &str, peer: &str, multicast: bool) -> String {
    format!(
        "<CycloneDDS><Domain Id=\"any\"><General><Interfaces>\
         <NetworkInterface name=\"{iface}\"/></Interfaces><AllowMulticast>{multicast}</AllowMulticast>\
         </General><Discovery><ParticipantIndex>auto</ParticipantIndex>\
         <MaxAutoParticipantIndex>64</MaxAutoParticipantIndex><Peers><Peer address=\"{peer}\"/>\
         </Peers></Discovery></Domain></CycloneDDS>"
    )
}

/// Runs `formation run --ros2` (with `extra` arguments) while a cyclonedds subscriber listens;
/// checks what it received against the run's `trajectory.csv`, and that the run's trajectory is
/// `formation sim`'s when `lockstep`.
fn cyclonedds_receives_the_run(tag: &str, extra: &[&str], lockstep: bool) {
    let dir = temp_dir(tag);
    let Some(python) = python_or_skip(tag) else {
        return;
    };
    let domain = random_domain().to_string();
    let n = 5;
    // The last step `trajectory.csv` records: t = 2 s less one output period (100 Hz).
    let end_ns = 1_990_000_000u64;
    // Cyclone DDS on the loopback interface, discovering by unicast on this machine: ROS 2's
    // localhost-only setting, the range the run discovers in by default.
    let (mut sub, mut out) = Subscriber::start(
        Command::new(python),
        n,
        end_ns,
        90,
        &domain,
        &cyclone_config("lo", "127.0.0.1", false),
    );

    let mut args = vec!["--set", DURATION];
    args.extend_from_slice(extra);
    args.extend_from_slice(&["--ros2", "--ros2-wait", "30"]);
    let run_dir = dir.join("run");
    let mut run =
        RunningRun::start_with_env(&args, &run_dir, &[("ROS_DOMAIN_ID", Path::new(&domain))]);
    let (st, _) = run.wait(RUN_TIMEOUT).expect("the run ends");
    let stderr = run.stderr();
    assert!(st.success(), "formation run --ros2 failed: {stderr}");
    assert!(stderr.contains("a subscriber joined"), "{stderr}");
    assert!(
        stderr.contains(&format!(
            "DDS domain {domain} (discovery on this machine only)"
        )),
        "{stderr}"
    );
    let got = Subscriber::report(&mut sub, &mut out);
    let rows = trajectory(&run_dir);
    assert_eq!(n_agents(&rows), n);
    for id in 1..=n {
        assert!(
            got["pose_counts"][id - 1].as_u64().unwrap_or(0) > 0,
            "agent {id}: no pose received: {got}"
        );
        assert_last_pose_is_trajectorys(&rows, id, &got["last_pose"][id - 1]);
    }
    let frames = got["tf_frames"].to_string();
    for id in 1..=n {
        assert!(
            frames.contains(&format!("[\"world\",\"agent_{id}\"]")),
            "{frames}"
        );
    }
    assert!(
        frames.contains("[\"world\",\"virtual_leader\"]"),
        "{frames}"
    );
    assert!(
        got["clock_count"].as_u64().unwrap_or(0) > 0,
        "no /clock: {got}"
    );
    if lockstep {
        formation_tests::assert_trajectory_is_sims(
            &run_dir,
            &["--set", DURATION],
            &dir.join("sim"),
        );
    }
}

#[test]
fn a_cyclonedds_subscriber_receives_every_agents_poses_and_tf_of_a_lockstep_run() {
    cyclonedds_receives_the_run("ros2-lockstep", &[], true);
}

#[test]
fn a_cyclonedds_subscriber_receives_every_agents_poses_and_tf_of_a_realtime_run() {
    cyclonedds_receives_the_run("ros2-realtime", &["--realtime"], false);
}

#[test]
fn a_bad_ros_domain_id_is_refused_naming_the_variable() {
    let dir = temp_dir("ros2-env");
    let o = Command::new(bin("formation"))
        .args(["sim", "--set", DURATION, "--ros2", "--out"])
        .arg(dir.join("sim"))
        .env("ROS_DOMAIN_ID", "999")
        .env_remove("CARGO")
        .output()
        .expect("formation starts");
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("ROS_DOMAIN_ID"), "{err}");
}

#[test]
fn without_record_rosbag2_a_stale_rosbag2_of_an_earlier_run_is_removed() {
    let dir = temp_dir("rosbag2-stale");
    let out = dir.join("sim");
    sim(&["--set", DURATION, "--record", "rosbag2"], &out);
    assert!(out.join("rosbag2/metadata.yaml").exists());
    sim(&["--set", DURATION], &out);
    assert!(
        !out.join("rosbag2").exists(),
        "a recording that is not this run's was left in {}",
        out.display()
    );
}

/// Why the discovery-range test cannot run here, if it cannot (it makes a network namespace, a
/// second "machine", joined to this one by a veth pair).
fn netns_unavailable() -> Option<String> {
    // SAFETY: geteuid has no preconditions.
    if unsafe { libc::geteuid() } != 0 {
        return Some("not root (a network namespace and a veth pair need CAP_NET_ADMIN)".into());
    }
    let ip_ok = Command::new("ip")
        .arg("-V")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    (!ip_ok).then(|| "the `ip` command (iproute2) is missing".into())
}

/// Another machine on this machine's network: a network namespace whose veth end has
/// 10.254.K.2/24, facing 10.254.K.1/24 here. Removed on drop, whatever happened.
struct Neighbour {
    ns: String,
    here: String,
    /// This machine's address on the shared link.
    addr_here: String,
    /// The veth end inside the namespace.
    iface: String,
}

impl Neighbour {
    fn new() -> Neighbour {
        let k = (std::process::id() % 200 + 20) as usize;
        let n = Neighbour {
            ns: format!("fmros{k}"),
            here: format!("fmros{k}a"),
            addr_here: format!("10.254.{k}.1"),
            iface: format!("fmros{k}b"),
        };
        n.remove();
        ip(&["netns", "add", &n.ns]);
        ip(&["-n", &n.ns, "link", "set", "lo", "up"]);
        ip(&[
            "link", "add", &n.here, "type", "veth", "peer", "name", &n.iface,
        ]);
        ip(&["link", "set", &n.iface, "netns", &n.ns]);
        ip(&[
            "addr",
            "add",
            &format!("{}/24", n.addr_here),
            "dev",
            &n.here,
        ]);
        ip(&["link", "set", &n.here, "up", "multicast", "on"]);
        ip(&[
            "-n",
            &n.ns,
            "addr",
            "add",
            &format!("10.254.{k}.2/24"),
            "dev",
            &n.iface,
        ]);
        ip(&[
            "-n",
            &n.ns,
            "link",
            "set",
            &n.iface,
            "up",
            "multicast",
            "on",
        ]);
        n
    }

    fn remove(&self) {
        for args in [
            vec!["link", "del", self.here.as_str()],
            vec!["netns", "del", self.ns.as_str()],
        ] {
            let _ = Command::new("ip")
                .args(&args)
                .stdout(Stdio::null())
                .stderr(Stdio::null())
                .status();
        }
    }

    /// What a cyclonedds subscriber on the neighbour receives while a run of `extra` arguments
    /// (in domain `domain`, discovery range `range` when given) flies here. The subscriber
    /// discovers the way a ROS 2 node on the subnet does: by multicast on its link, and by unicast
    /// to this machine's address.
    /// The subscriber listens for `listen_s` seconds at most.
    fn hears(
        &self,
        python: &Path,
        dir: &Path,
        range: Option<&str>,
        extra: &[&str],
        listen_s: u32,
    ) -> Value {
        let domain = random_domain().to_string();
        let mut in_namespace = Command::new("ip");
        in_namespace.args(["netns", "exec", &self.ns]).arg(python);
        // Reads until it has the last pose (t = duration less one 100 Hz output period), or
        // gives up after `listen_s`.
        let (mut sub, mut out) = Subscriber::start(
            in_namespace,
            5,
            1_990_000_000,
            listen_s,
            &domain,
            &cyclone_config(&self.iface, &self.addr_here, true),
        );

        let mut args = vec!["--set", DURATION, "--ros2"];
        args.extend_from_slice(extra);
        let mut env = vec![("ROS_DOMAIN_ID", Path::new(&domain))];
        if let Some(r) = range {
            env.push(("ROS_AUTOMATIC_DISCOVERY_RANGE", Path::new(r)));
        }
        let mut run = RunningRun::start_with_env(&args, &dir.join("run"), &env);
        let (st, _) = run.wait(RUN_TIMEOUT).expect("the run ends");
        assert!(
            st.success(),
            "formation run --ros2 failed: {}",
            run.stderr()
        );
        let said = run.stderr();
        let got = Subscriber::report(&mut sub, &mut out);
        serde_json::json!({ "got": got, "run": said })
    }
}

impl Drop for Neighbour {
    fn drop(&mut self) {
        self.remove();
    }
}

/// The whole count of poses a subscriber report holds.
fn poses_heard(report: &Value) -> u64 {
    report["got"]["pose_counts"]
        .as_array()
        .map(|c| c.iter().filter_map(Value::as_u64).sum())
        .unwrap_or(0)
}

#[test]
fn another_machine_on_the_network_hears_a_run_only_when_the_subnet_range_is_asked_for() {
    const TEST: &str =
        "another_machine_on_the_network_hears_a_run_only_when_the_subnet_range_is_asked_for";
    if let Some(why) = netns_unavailable() {
        if std::env::var("FORMATION_REQUIRE_NETNS").as_deref() == Ok("1") {
            panic!("{TEST}: FORMATION_REQUIRE_NETNS=1 but {why}");
        }
        eprintln!("skipping {TEST}: {why}");
        return;
    }
    let Some(python) = python_or_skip(TEST) else {
        return;
    };
    let dir = temp_dir("ros2-range");
    let neighbour = Neighbour::new();

    // The default range, a realtime run (2 s of wall clock, ample for discovery's first
    // announcements both ways), the neighbour listening 15 s from before the run starts: it
    // hears nothing.
    let default = neighbour.hears(&python, &dir.join("default"), None, &["--realtime"], 15);
    assert!(
        default["run"]
            .as_str()
            .unwrap_or("")
            .contains("discovery on this machine only"),
        "{}",
        default["run"]
    );
    assert_eq!(
        poses_heard(&default),
        0,
        "a run in the default (localhost) range reached another machine: {}",
        default["got"]
    );

    // The same neighbour with ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET (the run waits for it to
    // join): it hears every agent, so the silence above is the range's doing, not the link's.
    let subnet = neighbour.hears(
        &python,
        &dir.join("subnet"),
        Some("SUBNET"),
        &["--ros2-wait", "30"],
        60,
    );
    for (i, c) in subnet["got"]["pose_counts"]
        .as_array()
        .expect("counts")
        .iter()
        .enumerate()
    {
        assert!(
            c.as_u64().unwrap_or(0) > 0,
            "agent {}: the neighbour heard no pose in the SUBNET range: {}\n{}",
            i + 1,
            subnet["got"],
            subnet["run"]
        );
    }
}
