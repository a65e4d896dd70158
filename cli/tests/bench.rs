//! End-to-end tests of `formation bench` with the real binary (tiny budgets, no timed assertions).

use std::process::Command;

fn formation() -> Command {
    Command::new(env!("CARGO_BIN_EXE_formation"))
}

fn prefix_from_stderr(stderr: &str) -> String {
    let line = stderr
        .lines()
        .find(|l| l.contains("iceoryx2 prefix "))
        .expect("bench names its iceoryx2 prefix on stderr");
    let rest = line.split("iceoryx2 prefix ").nth(1).unwrap();
    rest.split(',').next().unwrap().trim().to_string()
}

fn files_with_prefix(dir: &std::path::Path, prefix: &str, out: &mut Vec<String>) {
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

#[test]
fn tiny_bench_reports_every_transport_and_pattern_and_leaves_no_shared_memory() {
    let out = formation()
        .args(["bench", "--json", "--seconds", "0.2", "--n", "2"])
        .output()
        .expect("formation runs");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "bench failed: {stderr}");

    // stdout is exactly one JSON document.
    let v: serde_json::Value =
        serde_json::from_slice(&out.stdout).expect("stdout is only the JSON result");
    let results = v["results"].as_array().expect("results array");
    assert!(!results.is_empty());

    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let mut transports = vec!["iox2-event", "iox2-waitset", "uds-dgram", "udp"];
    if cores >= 2 {
        transports.push("iox2-poll"); // busy-poll ping-pong needs two cores
    }
    for t in &transports {
        for pattern in ["ping-pong", "fan-out"] {
            if *t == "iox2-poll" && pattern == "fan-out" {
                continue; // 3 spinning processes on 2 cores: skipped by design
            }
            assert!(
                results
                    .iter()
                    .any(|r| r["transport"] == *t && r["pattern"] == pattern),
                "missing {t} {pattern}"
            );
        }
    }
    let mut sizes = std::collections::BTreeSet::new();
    for r in results {
        let samples = r["samples"].as_u64().unwrap();
        let p50 = r["p50_us"].as_f64().unwrap();
        let p99 = r["p99_us"].as_f64().unwrap();
        let p999 = r["p999_us"].as_f64().unwrap();
        let max = r["max_us"].as_f64().unwrap();
        assert!(samples > 0, "{r}");
        assert!(p50 <= p99 && p99 <= p999 && p999 <= max, "{r}");
        // Every case (the real lockstep run included) uses the lockstep's message sizes by
        // default: the state down to an agent, the larger command back up.
        let (down, up) = (
            r["payload_bytes"].as_u64().unwrap(),
            r["payload_up_bytes"].as_u64().unwrap(),
        );
        assert!(16 <= down && down < up, "{r}");
        sizes.insert((down, up));
        let n = r["n"].as_u64().unwrap();
        assert_eq!(n, if r["pattern"] == "ping-pong" { 1 } else { 2 }, "{r}");
        for key in ["wait", "transport", "pattern"] {
            assert!(r[key].is_string(), "{r}");
        }
    }

    assert_eq!(
        sizes.len(),
        1,
        "one pair of message sizes for all cases: {sizes:?}"
    );

    // The lockstep case (a real `formation run` with 2 agents) is set against every blocking
    // fan-out of the same n, the fastest (smallest median) first.
    assert!(
        results
            .iter()
            .any(|r| r["pattern"] == "lockstep" && r["wait"] == "block/pinned/batch"),
        "missing the lockstep row"
    );
    let cases = v["lockstep_vs_fan_out_cases"]
        .as_array()
        .expect("comparisons");
    let waits: Vec<&str> = cases
        .iter()
        .map(|c| c["fan_out_wait"].as_str().unwrap())
        .collect();
    assert!(
        waits.contains(&"block") && waits.contains(&"block/batch"),
        "{waits:?}"
    );
    assert!(waits
        .iter()
        .all(|w| w.starts_with("block") && !w.contains("one-core")));
    let p50 = |c: &serde_json::Value| c["fan_out_p50_us"].as_f64().unwrap();
    assert!(
        cases.windows(2).all(|w| p50(&w[0]) <= p50(&w[1])),
        "fastest first"
    );
    let ratio = &v["lockstep_vs_fan_out"];
    assert_eq!(ratio, &cases[0], "the headline is the fastest fan-out");
    for (l, f, r) in [
        ("lockstep_p50_us", "fan_out_p50_us", "ratio"),
        ("lockstep_mean_us", "fan_out_mean_us", "ratio_mean"),
    ] {
        let (l, f, r) = (
            ratio[l].as_f64().unwrap(),
            ratio[f].as_f64().unwrap(),
            ratio[r].as_f64().unwrap(),
        );
        assert!(l > 0.0 && f > 0.0 && (r - l / f).abs() < 1e-3, "{ratio}");
    }

    let prefix = prefix_from_stderr(&stderr);
    let mut left = Vec::new();
    files_with_prefix(std::path::Path::new("/dev/shm"), &prefix, &mut left);
    files_with_prefix(std::path::Path::new("/tmp/iceoryx2"), &prefix, &mut left);
    assert!(left.is_empty(), "files of {prefix} left behind: {left:?}");
}

#[test]
fn bad_bench_arguments_exit_with_code_2_and_a_message() {
    for args in [
        vec!["bench", "--payload", "3"],
        vec!["bench", "--n", "0"],
        vec!["bench", "--seconds", "-1"],
        vec!["bench", "--cpu", "9999"],
        vec!["bench", "--transports", "carrier-pigeon"],
        vec!["bench", "--rounds", "0"],
        vec!["bench", "--rounds", "21"],
    ] {
        let out = formation().args(&args).output().expect("formation runs");
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        assert!(out.stdout.is_empty(), "{args:?}");
        assert!(
            String::from_utf8_lossy(&out.stderr).contains("error"),
            "{args:?}"
        );
    }
}

#[test]
fn over_several_rounds_every_case_is_reported_once_and_each_ratio_comes_from_its_own_round() {
    let out = formation()
        .args([
            "bench",
            "--json",
            "--seconds",
            "0.1",
            "--n",
            "2",
            "--transports",
            "iox2-event",
            "--rounds",
            "3",
        ])
        .output()
        .expect("formation runs");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "bench failed: {stderr}");
    assert_eq!(stderr.matches("round ").count(), 3, "{stderr}");
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).expect("JSON on stdout");
    assert_eq!(v["rounds"], 3);
    let results = v["results"].as_array().expect("results");
    let mut keys: Vec<String> = results
        .iter()
        .map(|r| {
            format!(
                "{} {} {} {}",
                r["transport"], r["pattern"], r["wait"], r["n"]
            )
        })
        .collect();
    let all = keys.len();
    keys.sort();
    keys.dedup();
    assert_eq!(keys.len(), all, "one row per case: {keys:?}");
    for c in v["lockstep_vs_fan_out_cases"]
        .as_array()
        .expect("comparisons")
    {
        let ratios: Vec<f64> = c["ratios"]
            .as_array()
            .expect("ratios")
            .iter()
            .map(|r| r.as_f64().unwrap())
            .collect();
        assert_eq!(ratios.len() as u64, c["rounds"].as_u64().unwrap(), "{c}");
        assert_eq!(ratios.len(), 3, "{c}");
        let (lo, mid, hi) = (
            c["ratio_min"].as_f64().unwrap(),
            c["ratio"].as_f64().unwrap(),
            c["ratio_max"].as_f64().unwrap(),
        );
        assert!(lo <= mid && mid <= hi && lo > 0.0, "{c}");
        let mut sorted = ratios.clone();
        sorted.sort_by(f64::total_cmp);
        assert_eq!(mid, sorted[1], "the median of the rounds: {c}");
    }
}

/// `formation bench --transports zenoh`: bare Zenoh ping-pong and the fan-out of a split lockstep
/// step, and the split lockstep run itself (a `formation host` daemon started by the bench in its
/// own mount namespace). A tiny budget and no timing goal: the contract of the report, the exit
/// code and what is left behind. Needs root (the daemon's private /dev/shm is a mount namespace):
/// skipped with a message otherwise, and a failure when `FORMATION_REQUIRE_ROOT=1` (CI runs as
/// root).
#[cfg(feature = "multihost")]
mod zenoh {
    use super::files_with_prefix;
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
    fn zenoh_bench_sets_the_split_lockstep_step_against_the_bare_zenoh_fan_out_and_leaves_nothing()
    {
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
}
