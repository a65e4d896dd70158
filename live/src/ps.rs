//! `formation ps [--json]`: the running runs and their processes.

use crate::error::LiveError;
use formation_runtime::live::procstat::{self, ProcStat};
use formation_runtime::live::registry::{self, ProcessEntry, RunRecord, LOCAL_HOST};
use serde_json::{json, Value};
use std::time::{Duration, Instant};

/// Arguments of `formation ps`.
#[derive(clap::Args, Debug)]
pub struct PsArgs {
    /// Print `{"runs": [{"id", ..., "processes": [{"role", "agent", "host", "pid", "alive", ...}]}]}`
    /// (`alive` and the CPU shares are `null` for a process on another host).
    #[arg(long)]
    pub json: bool,
}

/// Interval over which the CPU share is measured.
const CPU_WINDOW: Duration = Duration::from_millis(300);

/// What `/proc` tells of one process between two readings `window_s` apart (`hz` clock ticks
/// per second, `uptime` seconds since boot).
#[derive(Debug, Clone, Copy)]
pub struct Sampled {
    /// Reading at the start of the window.
    pub before: Option<ProcStat>,
    /// Reading at its end.
    pub now: Option<ProcStat>,
    /// Clock ticks per second.
    pub hz: f64,
    /// Seconds since boot at the end of the window.
    pub uptime: Option<f64>,
    /// Length of the window, s.
    pub window_s: f64,
}

/// One process as `ps --json` lists it. Liveness and CPU shares come from this machine's
/// `/proc`, so a process on another host has them `null` (its pid there says nothing here):
/// never a number read from an unrelated local process with the same pid.
pub fn process_json(run: &RunRecord, p: &ProcessEntry, s: &Sampled) -> Value {
    let (alive, cpu_now, cpu_avg) = if p.is_local() {
        let alive = s.now.is_some_and(|n| n.alive());
        let cpu_now = match (s.before, s.now) {
            (Some(b), Some(n)) if alive => {
                Some(100.0 * n.cpu_ticks.saturating_sub(b.cpu_ticks) as f64 / s.hz / s.window_s)
            }
            _ => None,
        };
        let cpu_avg = match (s.now, s.uptime) {
            (Some(n), Some(up)) if alive => {
                let life = up - n.start_ticks as f64 / s.hz;
                (life > 0.0).then(|| 100.0 * n.cpu_ticks as f64 / s.hz / life)
            }
            _ => None,
        };
        (Some(alive), cpu_now, cpu_avg)
    } else {
        (None, None, None)
    };
    json!({
        "role": p.role, "agent": p.agent, "host": p.host, "pid": p.pid, "alive": alive,
        "cpu_percent": cpu_now, "cpu_percent_since_start": cpu_avg,
        "last_step": run.last_step, "steps_per_s": run.steps_per_s,
    })
}

/// `/proc` of a process of the record: read for a process on this machine only.
fn read_local(p: &ProcessEntry) -> Option<ProcStat> {
    p.is_local().then(|| procstat::read(p.pid)).flatten()
}

fn processes_json(run: &RunRecord, before: &[Option<ProcStat>], window_s: f64) -> Vec<Value> {
    let hz = procstat::ticks_per_second();
    let uptime = procstat::uptime_s();
    run.processes
        .iter()
        .zip(before)
        .map(|(p, b)| {
            let s = Sampled {
                before: *b,
                now: read_local(p),
                hz,
                uptime,
                window_s,
            };
            process_json(run, p, &s)
        })
        .collect()
}

/// Entry point of `formation ps`.
pub fn main(args: PsArgs) -> Result<(), LiveError> {
    let runs = registry::list()?;
    formation_runtime::live::reap_dead_prefixes(&runs);
    let before: Vec<Vec<Option<ProcStat>>> = runs
        .iter()
        .map(|r| r.processes.iter().map(read_local).collect())
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
                "started_unix_s": r.started_unix_s, "processes": processes_json(r, b, window),
            })
        })
        .collect();
    if args.json {
        println!("{}", json!({ "runs": out }));
        return Ok(());
    }
    if out.is_empty() {
        println!(
            "no runs (runs register in {})",
            registry::runs_dir().display()
        );
        return Ok(());
    }
    for r in &out {
        print_run(r);
    }
    Ok(())
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
    println!("  {}", header_row());
    let empty = Vec::new();
    for p in r["processes"].as_array().unwrap_or(&empty) {
        println!("  {}", process_row(p));
    }
}

/// The column titles of the process table.
pub fn header_row() -> String {
    format!(
        "{:<13} {:>5} {:<12} {:>8} {:>6} {:>7} {:>10}",
        "ROLE", "AGENT", "HOST", "PID", "STATE", "CPU%", "CPU%(avg)"
    )
}

/// One line of the process table from its `ps --json` entry: `-` for what is not known (the
/// state and CPU of a process on another host).
pub fn process_row(p: &Value) -> String {
    let pct = |v: &Value| v.as_f64().map_or("-".to_string(), |x| format!("{x:.1}"));
    format!(
        "{:<13} {:>5} {:<12} {:>8} {:>6} {:>7} {:>10}",
        p["role"].as_str().unwrap_or(""),
        p["agent"]
            .as_u64()
            .map_or("-".to_string(), |a| a.to_string()),
        p["host"].as_str().unwrap_or(LOCAL_HOST),
        p["pid"],
        match p["alive"].as_bool() {
            Some(true) => "alive",
            Some(false) => "dead",
            None => "-",
        },
        pct(&p["cpu_percent"]),
        pct(&p["cpu_percent_since_start"]),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::PathBuf;

    fn run_of(processes: Vec<ProcessEntry>) -> RunRecord {
        RunRecord {
            format: registry::RECORD_FORMAT.into(),
            id: "r1".into(),
            prefix: "fmr1_".into(),
            out_dir: PathBuf::from("/nonexistent"),
            scenario: "paper".into(),
            variant: "proposed".into(),
            n_agents: 5,
            steps: 100,
            dt_s: 0.001,
            orchestrator_start_ticks: 0,
            started_unix_s: 0.0,
            processes,
            last_step: 10,
            steps_per_s: 100.0,
            owner_uid: 0,
        }
    }

    fn agent(id: usize, pid: u32, host: &str) -> ProcessEntry {
        ProcessEntry {
            role: "agent".into(),
            agent: Some(id),
            pid,
            host: host.into(),
        }
    }

    /// A busy, running process: 30 ticks over a 0.3 s window at 100 Hz is 100 % of a CPU.
    fn busy() -> Sampled {
        let st = |cpu| ProcStat {
            state: 'R',
            cpu_ticks: cpu,
            start_ticks: 100,
        };
        Sampled {
            before: Some(st(70)),
            now: Some(st(100)),
            hz: 100.0,
            uptime: Some(3.0),
            window_s: 0.3,
        }
    }

    #[test]
    fn a_local_process_shows_its_state_and_cpu_from_proc() {
        let p = agent(1, 10, LOCAL_HOST);
        let v = process_json(&run_of(vec![p.clone()]), &p, &busy());
        assert_eq!(v["host"], "local");
        assert_eq!(v["alive"], true);
        assert!((v["cpu_percent"].as_f64().unwrap() - 100.0).abs() < 1e-9);
        // 100 ticks of CPU over 2 s of life.
        assert!((v["cpu_percent_since_start"].as_f64().unwrap() - 50.0).abs() < 1e-9);
        let row = process_row(&v);
        assert!(
            row.contains(" local ") && row.contains("alive") && row.contains("100.0"),
            "{row}"
        );
    }

    #[test]
    fn a_process_on_another_host_has_no_state_or_cpu_even_when_its_pid_exists_here() {
        let p = agent(4, 10, "b");
        // The readings of an unrelated local process with the same pid must not be shown.
        let v = process_json(&run_of(vec![p.clone()]), &p, &busy());
        assert_eq!(
            (v["host"].as_str(), v["pid"].as_u64()),
            (Some("b"), Some(10))
        );
        for k in ["alive", "cpu_percent", "cpu_percent_since_start"] {
            assert!(v[k].is_null(), "{k}: {}", v[k]);
        }
        let row = process_row(&v);
        let cols: Vec<&str> = row.split_whitespace().collect();
        assert_eq!(cols, ["agent", "4", "b", "10", "-", "-", "-"], "{row}");
        assert!(read_local(&p).is_none());
    }

    #[test]
    fn the_host_column_sits_between_agent_and_pid() {
        let h: Vec<String> = header_row().split_whitespace().map(String::from).collect();
        assert_eq!(
            h,
            ["ROLE", "AGENT", "HOST", "PID", "STATE", "CPU%", "CPU%(avg)"]
        );
    }
}
