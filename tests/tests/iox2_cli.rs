//! End to end: iceoryx2's own command-line tool `iox2` (crate iceoryx2-cli 0.10), started in
//! `DIR/iox2` of a live `formation run --out DIR` (where the run writes its iceoryx2 config), lists
//! the run's nodes and services; started elsewhere (default config, no run prefix) it does not see
//! them. Looking does not leave anything behind: the run still removes every file of its prefix.
//!
//! The tool is looked up in `$FORMATION_IOX2_BIN_DIR`, then on `PATH` (`iox2` dispatches
//! `iox2 node ...` to `iox2-node` found on `PATH`, so all its binaries must be in one directory).
//! Without it the test is skipped with a message on stderr, unless `FORMATION_REQUIRE_IOX2=1`
//! (set by `.ci/run`, which installs the tool): then it fails.

use formation_tests::run::RunningRun;
use formation_tests::temp_dir;
use serde_json::Value;
use std::collections::BTreeSet;
use std::ffi::OsString;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::{Duration, Instant};

/// How to get the tool (the version must match the iceoryx2 of the workspace: 0.10).
const INSTALL: &str = "cargo install iceoryx2-cli --version 0.10.0 --locked";

/// The binaries `iox2 node list` and `iox2 service list` need.
const TOOLS: [&str; 3] = ["iox2", "iox2-node", "iox2-service"];

/// Generous bound for the run to start or stop; reaching it means a hang.
const TIMEOUT: Duration = Duration::from_secs(120);

/// The directory holding the iceoryx2 0.10 CLI binaries, or why there is none.
fn find_iox2() -> Result<PathBuf, String> {
    let has_tools = |dir: &Path| TOOLS.iter().all(|t| dir.join(t).is_file());
    let dir = match std::env::var_os("FORMATION_IOX2_BIN_DIR") {
        Some(dir) => {
            let dir = PathBuf::from(dir);
            if !has_tools(&dir) {
                return Err(format!(
                    "FORMATION_IOX2_BIN_DIR={} does not hold all of {TOOLS:?}",
                    dir.display()
                ));
            }
            dir
        }
        None => std::env::split_paths(&std::env::var_os("PATH").unwrap_or_default())
            .find(|dir| has_tools(dir))
            .ok_or_else(|| format!("none of the PATH directories holds all of {TOOLS:?}"))?,
    };
    let version = Command::new(dir.join("iox2"))
        .arg("--version")
        .output()
        .map_err(|e| format!("cannot start {}: {e}", dir.join("iox2").display()))?;
    let version = String::from_utf8_lossy(&version.stdout).trim().to_string();
    if !version.starts_with("iox2 0.10.") {
        return Err(format!(
            "{} is `{version}`, not iceoryx2-cli 0.10",
            dir.join("iox2").display()
        ));
    }
    Ok(dir)
}

/// The tool's directory; `None` (after saying so on stderr) when it is missing and not required.
fn iox2_or_skip() -> Option<PathBuf> {
    match find_iox2() {
        Ok(dir) => Some(dir),
        Err(why) if std::env::var("FORMATION_REQUIRE_IOX2").as_deref() == Ok("1") => panic!(
            "FORMATION_REQUIRE_IOX2=1 but the iceoryx2 CLI is missing: {why}. Install it with \
             `{INSTALL} --root <dir>` and set FORMATION_IOX2_BIN_DIR=<dir>/bin (.ci/run does both)"
        ),
        Err(why) => {
            // Straight to the process's stderr: the test harness would swallow `eprintln!`.
            let _ = writeln!(
                std::io::stderr(),
                "SKIPPED iox2_cli: the iceoryx2 CLI is missing ({why}); install it with `{INSTALL}` \
                 and put it on PATH or set FORMATION_IOX2_BIN_DIR; FORMATION_REQUIRE_IOX2=1 makes \
                 this a failure"
            );
            None
        }
    }
}

/// Runs `iox2 <args>` in `cwd`, with the tool's directory first on `PATH`.
fn iox2(bin_dir: &Path, cwd: &Path, args: &[&str]) -> Output {
    let mut path = vec![bin_dir.to_path_buf()];
    path.extend(std::env::split_paths(
        &std::env::var_os("PATH").unwrap_or_default(),
    ));
    let path: OsString = std::env::join_paths(path).expect("PATH entries without ':'");
    let out = Command::new(bin_dir.join("iox2"))
        .args(args)
        .current_dir(cwd)
        .env("PATH", path)
        .output()
        .expect("iox2 starts");
    assert!(
        out.status.success(),
        "`iox2 {}` in {} failed: {}{}",
        args.join(" "),
        cwd.display(),
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// `iox2 <args> --format JSON` in `cwd`, parsed.
fn iox2_json(bin_dir: &Path, cwd: &Path, args: &[&str]) -> Value {
    let args: Vec<&str> = args.iter().copied().chain(["--format", "JSON"]).collect();
    let out = iox2(bin_dir, cwd, &args);
    serde_json::from_slice(&out.stdout).unwrap_or_else(|e| {
        panic!(
            "`iox2 {}` prints JSON ({e}): {}",
            args.join(" "),
            String::from_utf8_lossy(&out.stdout)
        )
    })
}

/// The nodes of `iox2 node list --format JSON`: (name, state, pid).
fn nodes(list: &Value) -> Vec<(String, String, u64)> {
    let details = list["details"].as_array().expect("node list has details");
    assert_eq!(list["num"].as_u64(), Some(details.len() as u64), "{list}");
    details
        .iter()
        .map(|n| {
            (
                n["name"].as_str().unwrap_or("").to_string(),
                n["state"].as_str().unwrap_or("").to_string(),
                n["pid"].as_u64().unwrap_or(0),
            )
        })
        .collect()
}

/// The services of `iox2 service list --format JSON`: (messaging pattern, name).
fn services(list: &Value) -> BTreeSet<(String, String)> {
    list.as_array()
        .expect("service list is an array")
        .iter()
        .flat_map(|s| s.as_object().expect("{pattern: name}"))
        .map(|(pattern, name)| (pattern.clone(), name.as_str().unwrap_or("").to_string()))
        .collect()
}

#[test]
fn iox2_cli_in_the_run_config_dir_lists_the_live_runs_nodes_and_services_and_nothing_elsewhere() {
    let Some(bin_dir) = iox2_or_skip() else {
        return;
    };
    let dir = temp_dir("iox2-cli");
    let mut run = RunningRun::start(&["--set", "simulation.duration_s=600"], &dir.join("run"));
    let prefix = run
        .prefix()
        .unwrap_or_else(|| panic!("the run did not announce its prefix: {}", run.stderr()));
    // Wait until steps are being recorded: every node and service exists by then.
    let csv = run.out.join("trajectory.csv");
    let start = Instant::now();
    while std::fs::metadata(&csv).map_or(0, |m| m.len()) < 4096 {
        assert!(start.elapsed() < TIMEOUT, "no progress: {}", run.stderr());
        std::thread::sleep(Duration::from_millis(20));
    }
    let role_pids: BTreeSet<u64> = run.role_processes().into_iter().map(u64::from).collect();
    assert_eq!(role_pids.len(), 7, "plant, leader and 5 agents");

    // The config the run wrote carries its prefix; iox2 reads it from ./config/iceoryx2.toml.
    let iox2_dir = run.out.join("iox2");
    let config = std::fs::read_to_string(iox2_dir.join("config/iceoryx2.toml"))
        .expect("the run writes DIR/iox2/config/iceoryx2.toml");
    assert!(
        config.contains(&format!("\"{prefix}\"")),
        "the config carries the prefix {prefix}: {config}"
    );

    // Nodes: the orchestrator and one per role process, all alive, with the processes' pids.
    let listed = nodes(&iox2_json(&bin_dir, &iox2_dir, &["node", "list"]));
    let mut expected: Vec<String> = ["fm-orchestrator", "fm-plant", "fm-leader"]
        .map(String::from)
        .to_vec();
    expected.extend((1..=5).map(|id| format!("fm-agent-{id}")));
    let names: BTreeSet<&str> = listed.iter().map(|(n, _, _)| n.as_str()).collect();
    assert_eq!(
        names,
        expected.iter().map(String::as_str).collect(),
        "nodes of the run: {listed:?}"
    );
    assert_eq!(listed.len(), 8, "one node per process: {listed:?}");
    for (name, state, _) in &listed {
        assert_eq!(state, "Alive", "node {name}: {listed:?}");
    }
    let pid_of = |name: &str| listed.iter().find(|(n, _, _)| n == name).unwrap().2;
    assert_eq!(pid_of("fm-orchestrator"), u64::from(run.pid()));
    let node_pids: BTreeSet<u64> = expected[1..].iter().map(|n| pid_of(n)).collect();
    assert_eq!(
        node_pids, role_pids,
        "role nodes belong to the role processes"
    );

    // Services: the lockstep protocol's, every one under formation/.
    let listed = services(&iox2_json(&bin_dir, &iox2_dir, &["service", "list"]));
    let mut expected: Vec<(&str, String)> = vec![
        ("PublishSubscribe", "formation/reference".into()),
        ("PublishSubscribe", "formation/run/control".into()),
        ("Event", "formation/wake/orchestrator".into()),
        ("Event", "formation/wake/plant".into()),
        ("Event", "formation/wake/leader".into()),
    ];
    for i in 0..5 {
        for topic in ["state", "share", "command", "telemetry"] {
            expected.push(("PublishSubscribe", format!("formation/agent/{i}/{topic}")));
        }
        expected.push(("Event", format!("formation/wake/agent/{i}")));
    }
    for (pattern, name) in &expected {
        assert!(
            listed.contains(&(pattern.to_string(), name.clone())),
            "{pattern}(\"{name}\") not listed: {listed:?}"
        );
    }
    assert!(
        listed
            .iter()
            .all(|(_, name)| name.starts_with("formation/")),
        "{listed:?}"
    );

    // The command README.md gives, with the tool's default (RON) output, says the same.
    let plain = |what: &str| {
        String::from_utf8_lossy(&iox2(&bin_dir, &iox2_dir, &[what, "list"]).stdout).into_owned()
    };
    assert!(plain("node").contains("\"fm-plant\""), "{}", plain("node"));
    assert!(
        plain("service").contains("\"formation/agent/0/state\""),
        "{}",
        plain("service")
    );

    // Elsewhere (no ./config/iceoryx2.toml: default config and prefix) the run is invisible.
    let elsewhere = dir.join("elsewhere");
    std::fs::create_dir_all(&elsewhere).unwrap();
    let other_nodes = nodes(&iox2_json(&bin_dir, &elsewhere, &["node", "list"]));
    assert!(
        other_nodes.iter().all(|(name, _, pid)| name != "fm-plant"
            && *pid != u64::from(run.pid())
            && !role_pids.contains(pid)),
        "the default config sees the run's nodes: {other_nodes:?}"
    );
    let other_services = services(&iox2_json(&bin_dir, &elsewhere, &["service", "list"]));
    assert!(
        !other_services
            .iter()
            .any(|(_, name)| name == "formation/wake/plant"),
        "the default config sees the run's services: {other_services:?}"
    );

    // Looking left nothing behind: Ctrl-C stops the run, which removes every file of its prefix.
    run.signal(libc::SIGINT);
    let (status, _) = run.wait(TIMEOUT).expect("the run stops");
    assert_eq!(status.code(), Some(130), "stderr: {}", run.stderr());
    assert!(run.role_processes().is_empty(), "role processes survived");
    let left = formation_config::node::ipc::residue(&prefix).expect("can list the iceoryx2 files");
    assert!(left.is_empty(), "residue of {prefix}: {left:?}");
    drop(run);
    let _ = std::fs::remove_dir_all(&dir);
}
