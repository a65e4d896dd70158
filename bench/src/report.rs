//! Result rows: percentiles from the HDR histograms, printed as a table or as JSON.

use super::link::Sizes;
use super::plan::Pattern;
use super::row::Row;
use super::versus::{realtime_factor, SplitComparison};

/// The comparison with the fastest blocking fan-out of each N (`all` holds, per N in order, the
/// comparisons fastest first).
fn fastest_per_n(all: &[super::lockstep::Comparison]) -> Vec<&super::lockstep::Comparison> {
    let mut out: Vec<&super::lockstep::Comparison> = Vec::new();
    for c in all {
        if !out.iter().any(|o| o.n == c.n) {
            out.push(c);
        }
    }
    out
}

/// `{"results": [...]}`, plus, when both were measured, `lockstep_vs_fan_out` (against the
/// fastest blocking fan-out, of the first N), `lockstep_vs_fan_out_by_n` (the same for every N)
/// and `lockstep_vs_fan_out_cases` (against each fan-out of each N), and
/// `zenoh_split_vs_fan_out` (the split lockstep against the bare Zenoh fan-out).
pub fn json(
    rows: &[Row],
    all: &[super::lockstep::Comparison],
    rounds: usize,
    split: Option<&SplitComparison>,
) -> String {
    let mut v = serde_json::json!({ "results": rows, "rounds": rounds });
    if let Some(fastest) = all.first() {
        v["lockstep_vs_fan_out"] = serde_json::json!(fastest);
        v["lockstep_vs_fan_out_by_n"] = serde_json::json!(fastest_per_n(all));
        v["lockstep_vs_fan_out_cases"] = serde_json::json!(all);
    }
    if let Some(c) = split {
        v["zenoh_split_vs_fan_out"] = serde_json::json!(c);
    }
    v.to_string()
}

/// A fixed-width table, with a note on what a sample is.
pub fn table(
    rows: &[Row],
    all: &[super::lockstep::Comparison],
    rounds: usize,
    split: Option<&SplitComparison>,
    skipped: &[(String, String)],
) -> String {
    let mut s = format!(
        "{:<13} {:<9} {:<18} {:>3} {:>7} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9} {:>8}\n",
        "transport",
        "pattern",
        "wait",
        "n",
        "payload",
        "p50 µs",
        "mean µs",
        "p99 µs",
        "p99.9 µs",
        "max µs",
        "1-way p50",
        "samples"
    );
    for r in rows {
        let one_way = if r.pattern == Pattern::PingPong.name() {
            format!("{:.1}", r.p50_us / 2.0)
        } else {
            "-".to_string()
        };
        s.push_str(&format!(
            "{:<13} {:<9} {:<18} {:>3} {:>7} {:>9.1} {:>9.1} {:>9.1} {:>9.1} {:>9.1} {:>9} {:>8}\n",
            r.transport,
            r.pattern,
            r.wait,
            r.n,
            Sizes {
                down: r.payload_bytes,
                up: r.payload_up_bytes
            }
            .label(),
            r.p50_us,
            r.mean_us,
            r.p99_us,
            r.p999_us,
            r.max_us,
            one_way,
            r.samples
        ));
    }
    s.push_str(
        "ping-pong: full round trip per sample (one-way = RTT/2); fan-out: time per step \
         (publish to n agents, wait for all n replies); lockstep: wall time per step of `formation \
         run` in steady state (plant + leader + n agents with the control laws).\n",
    );
    if rows.iter().any(|r| r.transport == "zenoh") {
        s.push_str(
            "zenoh fan-out: one frame each way per step holding what a lockstep step of the split \
             placement sends between the two hosts (n = the run's agents, payload = the frames); \
             zenoh lockstep: that split run (`wait` names the placement).\n",
        );
    }
    if rounds > 1 {
        s.push_str(&format!(
            "{rounds} rounds: each row is the case's round with the median p50.\n"
        ));
    }
    push_comparisons(&mut s, all);
    if let Some(c) = split {
        s.push_str(&super::versus::text(c));
    }
    for (what, why) in skipped {
        s.push_str(&format!("skipped {what}: {why}\n"));
    }
    s
}

/// The lockstep step against the bare fan-out: one line per comparison, then the fastest per n.
fn push_comparisons(s: &mut String, all: &[super::lockstep::Comparison]) {
    for (k, c) in all.iter().enumerate() {
        let fastest = k == 0 || all[k - 1].n != c.n;
        let what = if fastest { "fastest bare" } else { "bare" };
        if c.rounds > 1 {
            // Over rounds the ratio is the median of the ratios taken within each round, not the
            // quotient of the two median steps shown.
            s.push_str(&format!(
                "n={}: lockstep step / {what} iox2-event fan-out ({}, same n and message sizes), \
                 over {} rounds: median steps {:.1} / {:.1} µs; ratio of the medians within a \
                 round: {:.2}x (median; range {:.2}-{:.2}x), of the means: {:.2}x\n",
                c.n,
                c.fan_out_wait,
                c.rounds,
                c.lockstep_p50_us,
                c.fan_out_p50_us,
                c.ratio_p50,
                c.ratio_min,
                c.ratio_max,
                c.ratio_mean
            ));
            continue;
        }
        s.push_str(&format!(
            "n={}: lockstep step / {what} iox2-event fan-out ({}, same n and message sizes): \
             medians {:.1} / {:.1} µs = {:.2}x, means {:.1} / {:.1} µs = {:.2}x\n",
            c.n,
            c.fan_out_wait,
            c.lockstep_p50_us,
            c.fan_out_p50_us,
            c.ratio_p50,
            c.lockstep_mean_us,
            c.fan_out_mean_us,
            c.ratio_mean
        ));
    }
    let fastest = fastest_per_n(all);
    if !fastest.is_empty() {
        s.push_str(&format!(
            "\n{:>4} {:>14} {:>14} {:<20} {:>7} {:>13} {:>10}\n",
            "n", "lockstep µs", "fan-out µs", "(fastest fan-out)", "ratio", "range", "real time"
        ));
        for c in fastest {
            s.push_str(&format!(
                "{:>4} {:>14.1} {:>14.1} {:<20} {:>6.2}x {:>5.2}-{:<5.2}x {:>9.2}x\n",
                c.n,
                c.lockstep_p50_us,
                c.fan_out_p50_us,
                c.fan_out_wait,
                c.ratio_p50,
                c.ratio_min,
                c.ratio_max,
                realtime_factor(c.lockstep_p50_us)
            ));
        }
        s.push_str(
            "per n: median steps over the rounds, ratio = median of the ratios taken within each \
             round (range over the rounds), real time = simulated / wall time of a lockstep step \
             (1 ms steps).\n",
        );
    }
}
