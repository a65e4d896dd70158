//! `formation ps [--json]`: the running runs and their processes.

use super::procstat::{self, ProcStat};
use super::registry::{self, RunRecord};
use serde_json::{json, Value};
use std::process::ExitCode;
use std::time::{Duration, Instant};

/// Arguments of `formation ps`.
#[derive(clap::Args, Debug)]
pub struct PsArgs {
    /// Print `{"runs": [{"id", ..., "processes": [{"role", "agent", "pid", "alive", ...}]}]}`.
    #[arg(long)]
    pub json: bool,
}

/// Interval over which the CPU share is measured.
const CPU_WINDOW: Duration = Duration::from_millis(300);

fn process_json(run: &RunRecord, before: &[Option<ProcStat>], window_s: f64) -> Vec<Value> {
    let hz = procstat::ticks_per_second();
    let uptime = procstat::uptime_s();
    run.processes
        .iter()
        .zip(before)
        .map(|(p, b)| {
            let now = procstat::read(p.pid);
            let alive = now.is_some_and(|s| s.alive());
            let cpu_now = match (b, now) {
                (Some(b), Some(n)) if alive => {
                    Some(100.0 * n.cpu_ticks.saturating_sub(b.cpu_ticks) as f64 / hz / window_s)
                }
                _ => None,
            };
            let cpu_avg = match (now, uptime) {
                (Some(n), Some(up)) if alive => {
                    let life = up - n.start_ticks as f64 / hz;
                    (life > 0.0).then(|| 100.0 * n.cpu_ticks as f64 / hz / life)
                }
                _ => None,
            };
            json!({
                "role": p.role, "agent": p.agent, "pid": p.pid, "alive": alive,
                "cpu_percent": cpu_now, "cpu_percent_since_start": cpu_avg,
                "last_step": run.last_step, "steps_per_s": run.steps_per_s,
            })
        })
        .collect()
}

/// Entry point of `formation ps`.
pub fn main(args: PsArgs) -> ExitCode {
    let runs = match registry::list() {
        Ok(r) => r,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::from(crate::cli::EXIT_INVALID);
        }
    };
    super::reap_dead_prefixes(&runs);
    let before: Vec<Vec<Option<ProcStat>>> = runs
        .iter()
        .map(|r| r.processes.iter().map(|p| procstat::read(p.pid)).collect())
        .collect();
    let t0 = Instant::now();
    if !runs.is_empty() {
        std::thread::sleep(CPU_WINDOW);
    }
    let window = t0.elapsed().as_secs_f64().max(1e-3);
    let out: Vec<Value> = runs
        .iter()
        .zip(&before)
        .map(|(r, b)| {
            json!({
                "id": r.id, "prefix": r.prefix, "out_dir": r.out_dir, "scenario": r.scenario,
                "variant": r.variant, "n_agents": r.n_agents, "steps": r.steps,
                "last_step": r.last_step, "t_s": r.last_step as f64 * r.dt_s,
                "steps_per_s": r.steps_per_s, "realtime_factor": r.steps_per_s * r.dt_s,
                "started_unix_s": r.started_unix_s, "processes": process_json(r, b, window),
            })
        })
        .collect();
    if args.json {
        println!("{}", json!({ "runs": out }));
        return ExitCode::SUCCESS;
    }
    if out.is_empty() {
        println!(
            "no runs (runs register in {})",
            registry::runs_dir().display()
        );
        return ExitCode::SUCCESS;
    }
    for r in &out {
        print_run(r);
    }
    ExitCode::SUCCESS
}

fn print_run(r: &Value) {
    let f = |k: &str| r[k].as_f64().unwrap_or(0.0);
    println!(
        "run {}  {} / {}  N = {}  step {}/{}  t = {:.2} s  {:.0} steps/s ({:.1}x real time)  out {}",
        r["id"].as_str().unwrap_or(""),
        r["scenario"].as_str().unwrap_or(""),
        r["variant"].as_str().unwrap_or(""),
        r["n_agents"],
        r["last_step"],
        r["steps"],
        f("t_s"),
        f("steps_per_s"),
        f("realtime_factor"),
        r["out_dir"].as_str().unwrap_or(""),
    );
    println!(
        "  {:<13} {:>5} {:>8} {:>6} {:>7} {:>10}",
        "ROLE", "AGENT", "PID", "STATE", "CPU%", "CPU%(avg)"
    );
    let empty = Vec::new();
    for p in r["processes"].as_array().unwrap_or(&empty) {
        let pct = |v: &Value| v.as_f64().map_or("-".to_string(), |x| format!("{x:.1}"));
        println!(
            "  {:<13} {:>5} {:>8} {:>6} {:>7} {:>10}",
            p["role"].as_str().unwrap_or(""),
            p["agent"]
                .as_u64()
                .map_or("-".to_string(), |a| a.to_string()),
            p["pid"],
            if p["alive"].as_bool() == Some(true) {
                "alive"
            } else {
                "dead"
            },
            pct(&p["cpu_percent"]),
            pct(&p["cpu_percent_since_start"]),
        );
    }
}
