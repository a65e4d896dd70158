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
