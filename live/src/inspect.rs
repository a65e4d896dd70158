//! `formation inspect --agent I [--run ID] [--follow] [--json]`: one agent's live telemetry.

use crate::error::{InspectError, LiveError};
use formation_config::node::ports::{subscriber, Input};
use formation_config::protocol::services;
use formation_config::protocol::wire::AgentTelemetry;
use formation_runtime::live::registry::{self, ProcessEntry};
use serde_json::{json, Value};
use std::io::Write;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Arguments of `formation inspect`.
#[derive(clap::Args, Debug)]
pub struct InspectArgs {
    /// Agent id, 1-based (1..=N) as in the CSV, the figures and the paper.
    #[arg(long, value_parser = formation_runtime::cli::whole_number::<usize>, allow_negative_numbers = true)]
    pub agent: usize,
    /// Run id (see `formation ps`); may be omitted when exactly one run is running.
    #[arg(long)]
    pub run: Option<String>,
    /// Keep refreshing until Ctrl-C (or the end of the run): in place on a terminal, else (a pipe,
    /// a file, or `NO_COLOR` set) one block per sample, separated by a blank line, without escape
    /// sequences.
    #[arg(long)]
    pub follow: bool,
    /// One JSON object per sample.
    #[arg(long)]
    pub json: bool,
}

/// How long to wait for the first sample.
const FIRST_SAMPLE: Duration = Duration::from_secs(10);
/// Refresh interval of `--follow`.
const REFRESH: Duration = Duration::from_millis(250);

/// The newest sample in the subscriber's queue, if any.
fn newest(sub: &Input<AgentTelemetry>) -> Result<Option<AgentTelemetry>, InspectError> {
    let mut last = None;
    while let Some(s) = sub.receive().map_err(InspectError::Telemetry)? {
        last = Some(*s);
    }
    Ok(last)
}

/// The process of agent `agent` (1-based) in the run's record.
pub fn agent_process(run: &registry::RunRecord, agent: usize) -> Option<&ProcessEntry> {
    run.processes
        .iter()
        .find(|p| p.role == "agent" && p.agent == Some(agent))
}

/// The sample as JSON (agent 1-based), with the host and pid of the agent's process (`null` when
/// the record does not list it).
pub fn to_json(run: &str, process: Option<&ProcessEntry>, s: &AgentTelemetry) -> Value {
    let c = &s.controller;
    json!({
        "run": run, "agent": s.agent + 1,
        "host": process.map(|p| p.host.as_str()), "pid": process.map(|p| p.pid),
        "step": s.step, "t": s.t,
        "formation_error_m": s.formation_error_m,
        "e_p": c.e_p, "e_v": c.e_v, "tau_s": c.tau_s,
        "attitude": s.attitude, "attitude_norm": norm(s.attitude),
        "attitude_limit_rad": s.attitude_limit_rad,
        "rate": s.rate, "rate_norm": norm(s.rate), "rate_limit_rad_s": s.rate_limit_rad_s,
        "attitude_cmd": c.attitude_cmd, "z1": c.z1, "z2": c.z2, "c1": c.c1, "c2": c.c2,
        "blf1": c.blf1, "blf2": c.blf2,
        "u_p": c.u_p, "f_hat": c.f_hat, "nn_weight_norm": c.nn_weight_norm,
        "gamma_hat": c.gamma_hat, "delta_hat": c.delta_hat, "d_hat": c.d_hat,
        "model_hat_dev": c.model_hat_dev, "e1": c.e1, "e2": c.e2,
        "loop_latency_us": s.loop_latency_us,
        "separation": {
            "correction": c.sep_correction,
            "predicted_m": finite(c.sep_predicted_m),
            "active_s": s.sep_active_s,
            "min_predicted_m": finite(s.sep_min_predicted_m),
        },
    })
}

/// A distance that may be infinite (none in range) as JSON: `null` then.
fn finite(v: f64) -> Option<f64> {
    v.is_finite().then_some(v)
}

fn norm(v: [f64; 3]) -> f64 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}

fn v3(v: [f64; 3]) -> String {
    format!("[{:+.4}, {:+.4}, {:+.4}]", v[0], v[1], v[2])
}

/// Whether `--follow` may redraw in place with escape sequences (clear screen, cursor home): only
/// when stdout is a terminal and `NO_COLOR` is unset or empty (https://no-color.org).
pub fn redraw_in_place(stdout_is_terminal: bool, no_color: Option<&std::ffi::OsStr>) -> bool {
    stdout_is_terminal && no_color.is_none_or(|v| v.is_empty())
}

/// Clears the terminal and moves the cursor home.
const CLEAR_SCREEN: &str = "\x1b[H\x1b[2J";

/// `host b  pid 4242`: where the agent's process runs (`-` when the record does not list it).
pub fn process_text(process: Option<&ProcessEntry>) -> String {
    match process {
        Some(p) => format!("host {}  pid {}", p.host, p.pid),
        None => "host -  pid -".to_string(),
    }
}

/// The sample as a readable block.
pub fn to_text(run: &str, n: usize, process: Option<&ProcessEntry>, s: &AgentTelemetry) -> String {
    let c = &s.controller;
    let mut o = String::new();
    o += &format!(
        "run {run}  agent {}/{n}  {}  step {}  t = {:.3} s  controller step {:.1} us\n",
        s.agent + 1,
        process_text(process),
        s.step,
        s.t,
        s.loop_latency_us
    );
    o += &format!("formation error   {:.4} m\n", s.formation_error_m);
    o += &format!("e_P (delayed)     {} m\n", v3(c.e_p));
    o += &format!("e_V (delayed)     {} m/s\n", v3(c.e_v));
    o += &format!("tau               {:.4} s\n", c.tau_s);
    o += &format!(
        "attitude |A|      {:.4} rad  limit {:.4}  A = {}  V1B = {:.3e} (C1 = {:.4})\n",
        norm(s.attitude),
        s.attitude_limit_rad,
        v3(s.attitude),
        c.blf1,
        c.c1
    );
    o += &format!(
        "rate |Omega|      {:.4} rad/s  limit {:.4}  Omega = {}  V2B = {:.3e} (C2 = {:.4})\n",
        norm(s.rate),
        s.rate_limit_rad_s,
        v3(s.rate),
        c.blf2,
        c.c2
    );
    o += &format!(
        "RBFNN |W|         {:.4}  F-hat = {} m/s^2\n",
        c.nn_weight_norm,
        v3(c.f_hat)
    );
    o += &format!("Gamma-hat         {}\n", v3(c.gamma_hat));
    o += &format!("delta-hat         {} N m\n", v3(c.delta_hat));
    o += &format!(
        "D-hat             {:.4} rad/s^2   |Delta F-hat - I| = {:.4}\n",
        c.d_hat, c.model_hat_dev
    );
    o += &format!("E1 {}  E2 {}\n", v3(c.e1), v3(c.e2));
    let dist = |v: f64| {
        if v.is_finite() {
            format!("{v:.3} m")
        } else {
            "- (none in range)".to_string()
        }
    };
    o += &format!(
        "separation        predicted {}  correction {} m/s^2  active {:.2} s  min predicted {}\n",
        dist(c.sep_predicted_m),
        v3(c.sep_correction),
        s.sep_active_s,
        dist(s.sep_min_predicted_m)
    );
    o
}

/// Entry point of `formation inspect`.
pub fn main(args: InspectArgs) -> Result<(), LiveError> {
    let run = registry::find(args.run.as_deref())?;
    formation_runtime::live::check_access(&run, "inspect")?;
    formation_runtime::live::validate::agent(args.agent, run.n_agents)?;
    let result = follow(&run, &args);
    formation_runtime::live::tidy_after(&run);
    Ok(result?)
}

fn follow(run: &registry::RunRecord, args: &InspectArgs) -> Result<(), InspectError> {
    let stop = Arc::new(AtomicBool::new(false));
    if args.follow {
        let flag = stop.clone();
        let _ = ctrlc::set_handler(move || flag.store(true, Ordering::SeqCst));
    }
    let node = formation_runtime::live::client_node(run, "inspect")?;
    let sub: Input<AgentTelemetry> = subscriber(&node, &services::TELEMETRY.at(args.agent - 1))?;
    let start = Instant::now();
    let mut last_step = None;
    let mut out = std::io::stdout();
    let in_place = redraw_in_place(
        std::io::IsTerminal::is_terminal(&out),
        std::env::var_os("NO_COLOR").as_deref(),
    );
    loop {
        if let Some(s) = newest(&sub)? {
            if last_step != Some(s.step) {
                last_step = Some(s.step);
                // The agent's process as the record lists it now (a replaced or moved agent has
                // a new pid or host).
                let now = registry::reload(&run.id);
                let process = agent_process(now.as_ref().unwrap_or(run), args.agent);
                let text = if args.json {
                    format!("{}\n", to_json(&run.id, process, &s))
                } else if args.follow && in_place {
                    format!(
                        "{CLEAR_SCREEN}{}",
                        to_text(&run.id, run.n_agents, process, &s)
                    )
                } else if args.follow {
                    format!("{}\n", to_text(&run.id, run.n_agents, process, &s))
                } else {
                    to_text(&run.id, run.n_agents, process, &s)
                };
                if out
                    .write_all(text.as_bytes())
                    .and_then(|_| out.flush())
                    .is_err()
                {
                    return Ok(()); // stdout closed (e.g. piped into head)
                }
                if !args.follow {
                    return Ok(());
                }
            }
        } else if last_step.is_none() && start.elapsed() > FIRST_SAMPLE {
            return Err(InspectError::NoSample {
                agent: args.agent,
                run: run.id.clone(),
                seconds: FIRST_SAMPLE.as_secs(),
            });
        }
        if stop.load(Ordering::SeqCst) {
            return Ok(());
        }
        if last_step.is_some() && !run.is_live() {
            eprintln!("run {} has ended", run.id);
            return Ok(());
        }
        std::thread::sleep(if last_step.is_some() {
            REFRESH
        } else {
            Duration::from_millis(20)
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::ffi::OsStr;

    #[test]
    fn follow_redraws_in_place_only_on_a_terminal_without_no_color() {
        assert!(redraw_in_place(true, None));
        assert!(redraw_in_place(true, Some(OsStr::new(""))));
        assert!(!redraw_in_place(true, Some(OsStr::new("1"))));
        assert!(!redraw_in_place(false, None));
        assert!(!redraw_in_place(false, Some(OsStr::new("1"))));
    }

    #[test]
    fn the_text_block_has_no_escape_sequence() {
        let text = to_text("r", 5, None, &AgentTelemetry::default());
        assert!(!text.contains('\x1b'), "{text}");
    }

    #[test]
    fn an_agent_on_another_host_is_shown_with_that_host_and_its_pid_there() {
        let p = ProcessEntry {
            role: "agent".into(),
            agent: Some(4),
            pid: 4242,
            host: "b".into(),
        };
        let s = AgentTelemetry {
            agent: 3,
            ..Default::default()
        };
        let first = to_text("r", 5, Some(&p), &s);
        assert!(
            first
                .lines()
                .next()
                .unwrap()
                .contains("agent 4/5  host b  pid 4242"),
            "{first}"
        );
        let j = to_json("r", Some(&p), &s);
        assert_eq!(
            (j["agent"].as_u64(), j["host"].as_str(), j["pid"].as_u64()),
            (Some(4), Some("b"), Some(4242))
        );
        let unknown = to_json("r", None, &s);
        assert!(unknown["host"].is_null() && unknown["pid"].is_null());
        assert!(to_text("r", 5, None, &s).contains("host -  pid -"));
    }
}
