//! End-to-end test of `formation bench --transports zenoh` with the real binary: bare Zenoh
//! ping-pong and the fan-out of a split lockstep step, and the split lockstep run itself (a
//! `formation host` daemon started by the bench in its own mount namespace). A tiny budget and
//! no timing goal: the contract of the report, the exit code and what is left behind.
//!
//! Needs root (the daemon's private /dev/shm is a mount namespace): skipped with a message
//! otherwise, and a failure when `FORMATION_REQUIRE_ROOT=1` (CI runs as root).
#![cfg(feature = "multihost")]

use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;

/// `true`: run; `false`: skipped (panics instead when FORMATION_REQUIRE_ROOT=1).
fn available(test: &str) -> bool {
    // SAFETY: geteuid has no preconditions.
    if unsafe { libc::geteuid() } == 0 {
        return true;
    }
    let why = "not root (the host daemon's private /dev/shm needs a mount namespace)";
    if std::env::var("FORMATION_REQUIRE_ROOT").as_deref() == Ok("1") {
        panic!("{test}: FORMATION_REQUIRE_ROOT=1 but {why}");
    }
    eprintln!("skipping {test}: {why}");
    false
}

/// The iceoryx2 prefixes the bench names on stderr: its own, then the split run's.
fn prefixes(stderr: &str) -> Vec<String> {
    stderr
        .split("iceoryx2 prefix ")
        .skip(1)
        .filter_map(|rest| rest.split([',', ')', ' ', '\n']).next())
        .map(|p| p.trim().to_string())
        .filter(|p| !p.is_empty() && p != "?")
        .collect()
}

/// Files under `dir` (recursively) whose names start with `prefix`.
fn files_with_prefix(dir: &Path, prefix: &str, out: &mut Vec<String>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for e in entries.flatten() {
        let p = e.path();
        if p.is_dir() {
            files_with_prefix(&p, prefix, out);
        } else if e.file_name().to_string_lossy().starts_with(prefix) {
            out.push(p.display().to_string());
        }
    }
}

/// The iceoryx2 root of this user (as `formation_config::node::ipc::root_dir`).
fn iceoryx2_root() -> PathBuf {
    match std::env::var_os("XDG_RUNTIME_DIR").filter(|d| !d.is_empty()) {
        Some(d) if Path::new(&d).is_dir() => PathBuf::from(d).join("formation").join("iox2"),
        // SAFETY: getuid has no preconditions.
        _ => PathBuf::from(format!("/tmp/formation-iox2-{}", unsafe { libc::getuid() })),
    }
}

fn positive(v: &Value, key: &str) -> f64 {
    let x = v[key]
        .as_f64()
        .unwrap_or_else(|| panic!("{key} is a number: {v}"));
    assert!(x.is_finite() && x > 0.0, "{key} positive and finite: {v}");
    x
}

#[test]
fn zenoh_bench_sets_the_split_lockstep_step_against_the_bare_zenoh_fan_out_and_leaves_nothing() {
    if !available(
        "zenoh_bench_sets_the_split_lockstep_step_against_the_bare_zenoh_fan_out_and_leaves_nothing",
    ) {
        return;
    }
    let mut child = Command::new(env!("CARGO_BIN_EXE_formation"))
        .args([
            "bench",
            "--transports",
            "zenoh",
            "--json",
            "--seconds",
            "0.2",
        ])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("formation runs");
    let pid = child.id();
    let out = {
        use std::io::Read;
        let (mut so, mut se) = (Vec::new(), String::new());
        let mut e = child.stderr.take().unwrap();
        let mut o = child.stdout.take().unwrap();
        let t = std::thread::spawn(move || {
            let _ = e.read_to_string(&mut se);
            se
        });
        o.read_to_end(&mut so).unwrap();
        let stderr = t.join().unwrap();
        (child.wait().unwrap(), so, stderr)
    };
    let (status, stdout, stderr) = out;
    assert!(status.success(), "bench failed ({status}): {stderr}");

    let v: Value = serde_json::from_slice(&stdout).expect("stdout is only the JSON result");
    let results = v["results"].as_array().expect("results");
    let find = |pattern: &str| {
        results
            .iter()
            .find(|r| r["transport"] == "zenoh" && r["pattern"] == pattern)
            .unwrap_or_else(|| panic!("a zenoh {pattern} row: {v}"))
    };
    for (pattern, n) in [("ping-pong", 1), ("fan-out", 5), ("lockstep", 5)] {
        let r = find(pattern);
        assert_eq!(r["n"], n, "{r}");
        assert!(r["samples"].as_u64().unwrap() > 0, "{r}");
        let p50 = positive(r, "p50_us");
        let p99 = positive(r, "p99_us");
        positive(r, "mean_us");
        assert!(p50 <= p99 && p99 <= positive(r, "max_us"), "{r}");
    }
    assert_eq!(find("lockstep")["wait"], "split 4,5@b");
    // The fan-out's frame out carries the two remote agents' states (the ping-pong's message),
    // besides the share across and the wake-ups.
    let state = find("ping-pong")["payload_bytes"].as_u64().unwrap();
    let fan = find("fan-out");
    assert!(fan["payload_bytes"].as_u64().unwrap() > 2 * state, "{fan}");
    assert!(
        !results.iter().any(|r| r["transport"] != "zenoh"),
        "only the named transport: {v}"
    );
    assert!(
        v.get("lockstep_vs_fan_out").is_none(),
        "no iceoryx2 comparison without its rows: {v}"
    );

    let c = &v["zenoh_split_vs_fan_out"];
    let lock = positive(c, "lockstep_p50_us");
    let bare = positive(c, "fan_out_p50_us");
    assert_eq!(lock, find("lockstep")["p50_us"].as_f64().unwrap(), "{c}");
    assert_eq!(bare, fan["p50_us"].as_f64().unwrap(), "{c}");
    let ratio = positive(c, "ratio");
    assert!(
        (ratio - lock / bare).abs() < 1e-3,
        "ratio of the medians: {c}"
    );
    assert_eq!(c["ratios"].as_array().map(Vec::len), Some(1), "{c}");
    let rt = positive(c, "realtime_factor");
    assert!((rt - 1000.0 / lock).abs() < 0.01, "1 ms steps: {c}");
    positive(c, "realtime_factor_mean");
    assert_eq!(c["placement"], "4,5@b");
    assert!(
        c["measures"]
            .as_str()
            .is_some_and(|m| m.contains("/dev/shm")),
        "{c}"
    );

    let prefixes = prefixes(&stderr);
    assert_eq!(
        prefixes.len(),
        2,
        "the bench's and the split run's: {stderr}"
    );
    let mut left = Vec::new();
    for p in &prefixes {
        files_with_prefix(Path::new("/dev/shm"), p, &mut left);
        files_with_prefix(&iceoryx2_root(), p, &mut left);
    }
    assert!(left.is_empty(), "files left behind: {left:?}");
    let scratch = std::env::temp_dir().join(format!("formation-bench-{pid}"));
    assert!(!scratch.exists(), "{} left behind", scratch.display());
}
