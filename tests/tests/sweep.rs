//! End to end: `formation sweep` runs every sample with the in-process runner, writes one CSV row per
//! sample and the summary, and gives the same rows whatever the number of jobs.

use formation_tests::{bin, temp_dir};
use std::path::Path;
use std::process::Command;

fn sweep(out: &Path, jobs: &str) -> std::process::Output {
    Command::new(bin("formation"))
        .args([
            "sweep",
            "--samples",
            "4",
            "--seed",
            "5",
            "--jobs",
            jobs,
            "--vary",
            "delay.max=0..0.05",
            "--vary",
            "fault.gamma=0.4..1",
            "--vary",
            "start_offset=0..4",
            "--vary",
            "target_speed=1..3",
            "--set",
            "simulation.duration_s=2",
            "--out",
        ])
        .arg(out)
        .output()
        .expect("formation sweep starts")
}

/// sweep.csv without its wall-time column.
fn rows_without_wall_time(dir: &Path) -> Vec<String> {
    let text = std::fs::read_to_string(dir.join("sweep.csv")).expect("sweep.csv exists");
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().expect("header").split(',').collect();
    let wall = header
        .iter()
        .position(|c| *c == "wall_s")
        .expect("wall_s column");
    lines
        .map(|l| {
            let mut f: Vec<&str> = l.split(',').collect();
            f.remove(wall);
            f.join(",")
        })
        .collect()
}

#[test]
fn a_tiny_sweep_writes_a_row_per_sample_and_the_same_rows_with_one_or_two_jobs() {
    let dir = temp_dir("sweep");
    let out = sweep(&dir.join("two"), "2");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "sweep failed: {stderr}");
    let text = std::fs::read_to_string(dir.join("two/sweep.csv")).unwrap();
    let header = text.lines().next().unwrap();
    assert!(header.starts_with(
        "sample,delay.max,fault.gamma,start_offset,target_speed,rms_cover_worst_m,rms_enclose_worst_m,violations,min_separation_m"
    ), "{header}");
    let rows = rows_without_wall_time(&dir.join("two"));
    assert_eq!(rows.len(), 4, "{text}");
    for (k, r) in rows.iter().enumerate() {
        let f: Vec<&str> = r.split(',').collect();
        assert_eq!(f[0], k.to_string());
        let delay: f64 = f[1].parse().unwrap();
        assert!((0.0..0.05).contains(&delay), "{r}");
        let sep: f64 = f[8].parse().expect("min separation is a number");
        assert!(sep > 0.0, "{r}");
        assert_eq!(f.last(), Some(&""), "no error: {r}");
        let sample = dir.join(format!("two/samples/{k:04}"));
        assert!(sample.join("summary.json").is_file());
        assert!(sample.join("scenario.toml").is_file());
        assert!(
            !sample.join("trajectory.csv").exists(),
            "sweeps keep no trajectory"
        );
    }
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("two/sweep.json")).unwrap())
            .unwrap();
    assert_eq!(json["samples"], 4);
    assert_eq!(json["ran"], 4);
    assert_eq!(json["jobs"], 2);
    assert!(json["samples_per_s"].as_f64().unwrap() > 0.0);
    assert!(json["min_separation_m"].as_f64().unwrap() > 0.0);

    let out = sweep(&dir.join("one"), "1");
    assert!(out.status.success());
    assert_eq!(rows, rows_without_wall_time(&dir.join("one")));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_sweep_with_an_unknown_parameter_exits_2_naming_it() {
    let dir = temp_dir("sweep-unknown");
    let out = Command::new(bin("formation"))
        .args([
            "sweep",
            "--samples",
            "2",
            "--vary",
            "no_such.field=0..1",
            "--out",
        ])
        .arg(dir.join("out"))
        .output()
        .expect("formation sweep starts");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("no_such"), "{stderr}");
    let _ = std::fs::remove_dir_all(&dir);
}
