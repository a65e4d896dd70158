//! Realtime runs: merges the timing files the role processes wrote into `<run dir>/timing/` into
//! the `timing` object of `summary.json`, and prints it. On a multi-host run the files of the other
//! hosts' agents are brought into that folder first, with each host's bridge's link delays
//! (`bridge-<host>.json`, docs/multi-host.md).

use formation_config::node::timing::{self, NsHistogram, TimingReport};
use serde_json::{json, Value};
use std::path::Path;

/// How the plant waits for commands.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, Default)]
pub enum WaitMode {
    /// Sleep on the iceoryx2 event until a command arrives or the deadline passes.
    #[default]
    Block,
    /// Busy-poll the event for `--spin-us` first, then block.
    SpinBlock,
}

impl WaitMode {
    /// The name used on the command line and in `summary.json`.
    pub fn name(self) -> &'static str {
        match self {
            WaitMode::Block => "block",
            WaitMode::SpinBlock => "spin-block",
        }
    }
}

/// p50 / p99 / p99.9 / max of a histogram of ns, in µs (null when empty).
pub(super) fn quantiles(h: &NsHistogram) -> Value {
    if h.is_empty() {
        return json!({ "p50": null, "p99": null, "p999": null, "max": null, "samples": 0 });
    }
    let us = |ns: u64| (ns as f64 / 100.0).round() / 10.0;
    json!({
        "p50": us(h.quantile(0.5)),
        "p99": us(h.quantile(0.99)),
        "p999": us(h.quantile(0.999)),
        "max": us(h.max()),
        "samples": h.len(),
    })
}

/// The `links` array: one-way delay of every cross-host link, from the bridges' files
/// `bridge-<host>.json` (histograms `link/<from>-><to>`, counters `negative/<from>-><to>`).
fn links(reports: &[TimingReport]) -> Value {
    let mut out = Vec::new();
    for r in reports {
        for (k, h) in &r.histograms {
            let Some(name) = k.strip_prefix("link/") else {
                continue;
            };
            let (from, to) = name.split_once("->").unwrap_or((name, ""));
            let mut q = quantiles(h);
            q["link"] = json!(name);
            q["from"] = json!(from);
            q["to"] = json!(to);
            q["negative"] = json!(r
                .counters
                .get(&format!("negative/{name}"))
                .copied()
                .unwrap_or(0));
            out.push(q);
        }
    }
    Value::Array(out)
}

/// Agent i's delays in the summary: injected and effective (µs quantiles), steps over tau_M.
fn agent_delays(i: usize, r: &TimingReport) -> Value {
    let hist = |k: &str| r.histograms.get(k).cloned().unwrap_or_default();
    json!({
        "agent": i + 1,
        "injected_us": quantiles(&hist("injected_delay")),
        "effective_us": quantiles(&hist("effective_delay")),
        "steps_over_tau_m": r.counters.get("effective_over_tau_m").copied().unwrap_or(0),
    })
}

/// The agents (1-based) whose effective delay exceeded tau_M at some step, with the number of
/// such steps and the largest effective delay, µs.
pub fn over_tau_m(delays: &Value) -> Vec<(u64, u64, f64)> {
    delays["per_agent"]
        .as_array()
        .map(|v| {
            v.iter()
                .filter_map(|a| {
                    let steps = a["steps_over_tau_m"].as_u64().unwrap_or(0);
                    (steps > 0).then(|| {
                        (
                            a["agent"].as_u64().unwrap_or(0),
                            steps,
                            a["effective_us"]["max"].as_f64().unwrap_or(f64::NAN),
                        )
                    })
                })
                .collect()
        })
        .unwrap_or_default()
}

/// Why a realtime run's timing statistics cannot be collected.
#[derive(Debug, thiserror::Error)]
pub enum TimingError {
    /// A process's timing report cannot be read (its file named).
    #[error("{0}")]
    Report(#[from] formation_config::node::error::NodeError),
    /// The timing folder cannot be listed.
    #[error("{}: {source}", dir.display())]
    List {
        /// The folder.
        dir: std::path::PathBuf,
        /// The file system's error.
        source: std::io::Error,
    },
}

/// Reads `<run dir>/timing/{plant,agent-i,bridge-*}.json` and builds the `timing` object;
/// `tau_m_s` is the paper's bound tau_M (`simulation.max_delay_s`).
pub fn collect(
    run_dir: &Path,
    n: usize,
    wait: WaitMode,
    spin_us: u32,
    rt_priority: u32,
    tau_m_s: f64,
) -> Result<Value, TimingError> {
    let dir = timing::dir(run_dir);
    let plant = TimingReport::read(&dir.join("plant.json"))?;
    let agents: Vec<TimingReport> = (0..n)
        .map(|i| TimingReport::read(&dir.join(format!("agent-{}.json", i + 1))))
        .collect::<Result<_, _>>()?;
    let hist = |r: &TimingReport, k: &str| r.histograms.get(k).cloned().unwrap_or_default();
    let count = |r: &TimingReport, k: &str| r.counters.get(k).copied().unwrap_or(0);

    let mut pooled = NsHistogram::new();
    let mut per_agent = Vec::with_capacity(n);
    for i in 0..n {
        let h = hist(&plant, &format!("state_to_command/{i}"));
        pooled.merge(&h);
        let mut q = quantiles(&h);
        q["agent"] = json!(i + 1);
        per_agent.push(q);
    }
    let mut latency = quantiles(&pooled);
    latency["per_agent"] = Value::Array(per_agent);

    let mut state_hop = NsHistogram::new();
    let mut share_hop = NsHistogram::new();
    let mut compute = NsHistogram::new();
    let mut skipped = 0;
    for a in &agents {
        state_hop.merge(&hist(a, "state_hop"));
        share_hop.merge(&hist(a, "share_hop"));
        compute.merge(&hist(a, "controller_step"));
        skipped += count(a, "skipped_states");
    }
    let command_hop = hist(&plant, "command_hop");
    // Pooled: the two hops a wake-up follows at once (plant -> agent, agent -> plant). Shares are
    // not followed by a wake-up after step 0 (the neighbour reads them at its next state), so their
    // "hop" includes up to a period of waiting and is reported apart.
    let mut hop = state_hop.clone();
    hop.merge(&command_hop);
    let mut ipc = quantiles(&hop);
    ipc["plant_to_agent"] = quantiles(&state_hop);
    ipc["agent_to_plant"] = quantiles(&command_hop);
    ipc["agent_to_agent"] = quantiles(&share_hop);

    let misses = count(&plant, "deadline_misses");
    let timed = count(&plant, "timed_steps");
    let bridges: Vec<TimingReport> = std::fs::read_dir(&dir)
        .map_err(|source| TimingError::List {
            dir: dir.clone(),
            source,
        })?
        .flatten()
        .filter(|e| e.file_name().to_string_lossy().starts_with("bridge-"))
        .map(|e| TimingReport::read(&e.path()))
        .collect::<Result<_, _>>()?;
    let mut delays = json!({
        "tau_m_us": (tau_m_s * 1e6).round(),
        "per_agent": agents.iter().enumerate().map(|(i, a)| agent_delays(i, a)).collect::<Vec<_>>(),
    });
    delays["over_tau_m"] = json!(over_tau_m(&delays).iter().map(|x| x.0).collect::<Vec<_>>());
    Ok(json!({
        "links": links(&bridges),
        "delays": delays,
        "wait": wait.name(),
        "spin_us": if wait == WaitMode::SpinBlock { spin_us } else { 0 },
        "rt_priority": rt_priority,
        "state_to_command_latency_us": latency,
        "ipc_hop_latency_us": ipc,
        "plant_period_jitter_us": quantiles(&hist(&plant, "jitter")),
        "controller_step_us": quantiles(&compute),
        "deadline_misses": misses,
        "deadline_miss_fraction": if timed > 0 { misses as f64 / timed as f64 } else { 0.0 },
        "timed_steps": timed,
        "late_commands": count(&plant, "late_commands"),
        "late_commands_applied": count(&plant, "late_commands_applied"),
        "skipped_states": skipped,
    }))
}

/// The `host_probe` object of a realtime run's timing: the bare timer loop before and after the
/// run (`super::host_probe`), pooled, and the run's deadline-miss fraction over the pooled late
/// fraction (`miss_ratio`; null when the loop never woke late).
pub fn host_probe_json(
    before: &super::host_probe::ProbeStats,
    after: &super::host_probe::ProbeStats,
    t: &Value,
) -> Value {
    use super::host_probe as hp;
    let both = hp::pooled(before, after);
    let misses = t["deadline_miss_fraction"].as_f64().unwrap_or(0.0);
    json!({
        "period_us": hp::PERIOD.as_micros() as u64,
        "late_over_us": hp::LATE.as_micros() as u64,
        "rt_priority": t["rt_priority"],
        "before": before,
        "after": after,
        "pooled": both,
        "miss_ratio": hp::miss_ratio(misses, &both),
    })
}

/// Prints the timing object as a small table.
pub fn print(t: &Value) {
    println!(
        "realtime timing (wait {}), µs:      p50      p99    p99.9      max",
        t["wait"].as_str().unwrap_or("?")
    );
    for (label, key) in [
        ("state -> command", "state_to_command_latency_us"),
        ("IPC hop", "ipc_hop_latency_us"),
        ("plant period jitter", "plant_period_jitter_us"),
        ("controller step", "controller_step_us"),
    ] {
        let v = &t[key];
        let f = |q: &str| v[q].as_f64().map_or("-".to_string(), |x| format!("{x:.1}"));
        println!(
            "  {label:<28} {:>8} {:>8} {:>8} {:>8}",
            f("p50"),
            f("p99"),
            f("p999"),
            f("max")
        );
    }
    println!(
        "  deadline misses: {} of {} steps ({:.4} %), late commands: {} ({} applied)",
        t["deadline_misses"],
        t["timed_steps"],
        t["deadline_miss_fraction"].as_f64().unwrap_or(0.0) * 100.0,
        t["late_commands"],
        t["late_commands_applied"]
    );
    let hp = &t["host_probe"];
    if !hp.is_null() {
        let f = |k: &str| hp["pooled"][k].as_f64().unwrap_or(0.0);
        println!(
            "  host: a bare {} µs timer loop woke > {} µs late in {:.4} % of {} periods (before {:.4} %, after {:.4} %; mean {:.0} µs late); deadline misses over it: {}",
            hp["period_us"],
            hp["late_over_us"],
            f("late_fraction") * 100.0,
            hp["pooled"]["periods"],
            hp["before"]["late_fraction"].as_f64().unwrap_or(0.0) * 100.0,
            hp["after"]["late_fraction"].as_f64().unwrap_or(0.0) * 100.0,
            f("mean_late_us"),
            hp["miss_ratio"]
                .as_f64()
                .map_or("- (no late wake-up)".to_string(), |r| format!("{r:.2}x")),
        );
    }
    for l in t["links"].as_array().into_iter().flatten() {
        let f = |q: &str| l[q].as_f64().map_or("-".to_string(), |x| format!("{x:.1}"));
        println!(
            "  link {:<20} one-way delay, µs: p50 {} p99 {} max {} ({} messages)",
            l["link"].as_str().unwrap_or("?"),
            f("p50"),
            f("p99"),
            f("max"),
            l["samples"]
        );
    }
    let d = &t["delays"];
    for a in d["per_agent"].as_array().into_iter().flatten() {
        let f = |k: &str, q: &str| {
            a[k][q]
                .as_f64()
                .map_or("-".to_string(), |x| format!("{:.1}", x / 1e3))
        };
        println!(
            "  agent {} delay, ms: injected p50 {} max {}; effective p50 {} p99 {} max {}",
            a["agent"],
            f("injected_us", "p50"),
            f("injected_us", "max"),
            f("effective_us", "p50"),
            f("effective_us", "p99"),
            f("effective_us", "max")
        );
    }
}

/// Warns on stderr for every agent whose effective delay exceeded tau_M.
pub fn warn_over_tau_m(t: &Value) {
    let tau_m_ms = t["delays"]["tau_m_us"].as_f64().unwrap_or(f64::NAN) / 1e3;
    let timed = t["timed_steps"].as_u64().unwrap_or(0);
    for (agent, steps, max_us) in over_tau_m(&t["delays"]) {
        eprintln!(
            "warning: agent {agent}'s effective delay exceeded the paper's bound tau_M = {tau_m_ms} ms at {steps} of {timed} steps (max {:.1} ms): Theorem 1's delay assumption does not hold for this run",
            max_us / 1e3
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn report(hists: &[(&str, &[u64])], counters: &[(&str, u64)]) -> TimingReport {
        let mut r = TimingReport::default();
        for (k, v) in hists {
            let mut h = NsHistogram::new();
            v.iter().for_each(|&x| h.record(x));
            r.histograms.insert(k.to_string(), h);
        }
        for (k, c) in counters {
            r.counters.insert(k.to_string(), *c);
        }
        r
    }

    #[test]
    fn every_cross_host_link_is_named_with_ordered_quantiles_in_microseconds() {
        let b = report(
            &[("link/local->b", &[100_000, 200_000, 5_000_000])],
            &[("negative/local->b", 2)],
        );
        let l = links(&[b, report(&[("link/b->local", &[300_000])], &[])]);
        let l = l.as_array().unwrap();
        assert_eq!(l.len(), 2);
        assert_eq!(l[0]["link"], "local->b");
        assert_eq!(
            (l[0]["from"].as_str(), l[0]["to"].as_str()),
            (Some("local"), Some("b"))
        );
        assert_eq!(l[0]["negative"], 2);
        assert_eq!(l[0]["samples"], 3);
        let q = |k: &str| l[0][k].as_f64().unwrap();
        assert!(q("p50") > 0.0 && q("p50") <= q("p99") && q("p99") <= q("max"));
        assert!((q("max") - 5000.0).abs() < 5.0, "µs");
        assert_eq!(l[1]["link"], "b->local");
    }

    #[test]
    fn an_agent_whose_effective_delay_passed_tau_m_is_named_and_the_others_are_not() {
        let ms = 1_000_000;
        let ok = report(
            &[
                ("injected_delay", &[30 * ms]),
                ("effective_delay", &[31 * ms]),
            ],
            &[("effective_over_tau_m", 0)],
        );
        let over = report(
            &[
                ("injected_delay", &[45 * ms]),
                ("effective_delay", &[45 * ms, 52 * ms]),
            ],
            &[("effective_over_tau_m", 1)],
        );
        let d = json!({ "per_agent": [agent_delays(0, &ok), agent_delays(3, &over)] });
        let o = over_tau_m(&d);
        assert_eq!(o.len(), 1);
        assert_eq!((o[0].0, o[0].1), (4, 1));
        assert!((o[0].2 - 52_000.0).abs() < 60.0);
    }
}
