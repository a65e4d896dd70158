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
    for r in results {
        let samples = r["samples"].as_u64().unwrap();
        let p50 = r["p50_us"].as_f64().unwrap();
        let p99 = r["p99_us"].as_f64().unwrap();
        let p999 = r["p999_us"].as_f64().unwrap();
        let max = r["max_us"].as_f64().unwrap();
        assert!(samples > 0, "{r}");
        assert!(p50 <= p99 && p99 <= p999 && p999 <= max, "{r}");
        if r["pattern"] == "lockstep" {
            // The real run: its payload is the largest message of a step (the command).
            assert!(r["payload_bytes"].as_u64().unwrap() > 256, "{r}");
        } else {
            assert_eq!(r["payload_bytes"], 256);
        }
        let n = r["n"].as_u64().unwrap();
        assert_eq!(n, if r["pattern"] == "ping-pong" { 1 } else { 2 }, "{r}");
        for key in ["wait", "transport", "pattern"] {
            assert!(r[key].is_string(), "{r}");
        }
    }

    // The lockstep case (a real `formation run` with 2 agents) is set against the fan-out with the
    // same transport and scheduling.
    assert!(
        results
            .iter()
            .any(|r| r["pattern"] == "lockstep" && r["wait"] == "block/batch"),
        "missing the lockstep row"
    );
    assert!(results
        .iter()
        .any(|r| r["pattern"] == "fan-out" && r["wait"] == "block/batch"));
    let ratio = &v["lockstep_vs_fan_out"];
    let lock = ratio["lockstep_mean_us"].as_f64().expect("lockstep mean");
    let fan = ratio["fan_out_mean_us"].as_f64().expect("fan-out mean");
    let r = ratio["ratio"].as_f64().expect("ratio");
    assert!(
        lock > 0.0 && fan > 0.0 && (r - lock / fan).abs() < 1e-3,
        "{ratio}"
    );

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
