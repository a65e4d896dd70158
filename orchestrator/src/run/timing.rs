//! Realtime runs: merges the timing files the role processes wrote into `<run dir>/timing/` into
//! the `timing` object of `summary.json`, and prints it.

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

/// Reads `<run dir>/timing/{plant,agent-i}.json` and builds the `timing` object.
pub fn collect(
    run_dir: &Path,
    n: usize,
    wait: WaitMode,
    spin_us: u32,
    rt_priority: u32,
) -> Result<Value, String> {
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
    Ok(json!({
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
        "skipped_states": skipped,
    }))
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
        "  deadline misses: {} of {} steps ({:.4} %), late commands: {}",
        t["deadline_misses"],
        t["timed_steps"],
        t["deadline_miss_fraction"].as_f64().unwrap_or(0.0) * 100.0,
        t["late_commands"]
    );
}
