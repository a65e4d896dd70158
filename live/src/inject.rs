//! `formation inject fault|delay`: validated against the run's scenario here (exit code 2 and
//! nothing sent on a bad value), then sent to the run's orchestrator, which picks the apply step,
//! forwards it and confirms by writing it to `DIR/events.jsonl`.

use crate::error::{ConfirmError, LiveError, RequestError};
use formation_config::node::ports::{notifier, poke, publisher, send};
use formation_config::protocol::messages::{
    InjectRequest, INJECT_ASAP, INJECT_CRASH, INJECT_DELAY, INJECT_FAULT, INJECT_HANG,
    INJECT_LINK_DOWN, INJECT_LINK_UP,
};
use formation_config::protocol::services;
use formation_runtime::live::registry::{self, RunRecord};
use formation_runtime::live::validate;
use std::time::{Duration, Instant};

/// Arguments of `formation inject`.
#[derive(clap::Args, Debug)]
pub struct InjectArgs {
    /// What to inject.
    #[command(subcommand)]
    pub what: InjectWhat,
    /// Print the applied injection as one JSON object on standard output: the run's line of
    /// `DIR/events.jsonl` (`event`, `agent` 1-based, `step` and `t` it applies at,
    /// `requested_step`, `after_end`, the values) plus `run` (the run id).
    #[arg(long, global = true)]
    pub json: bool,
}

/// The injection kinds.
#[derive(clap::Subcommand, Debug)]
pub enum InjectWhat {
    /// Actuator fault of one agent: Gamma (multiplicative, each in (0, 1]) and delta (additive, N m).
    Fault(FaultArgs),
    /// Communication delay profile of one agent: tau(t), within [0, tau_M] of the run.
    Delay(DelayArgs),
    /// Crash of one agent's process: killed at a step, a new one takes over `--down` s later.
    Crash(DownArgs),
    /// Hang of one agent's process: stopped at a step, replaced `--down` s later.
    Hang(DownArgs),
    /// A communication link (a graph edge) goes down or comes back.
    Link(LinkArgs),
}

/// Arguments of `formation inject crash|hang`.
#[derive(clap::Args, Debug)]
pub struct DownArgs {
    /// Agent id, 1-based (1..=N).
    #[arg(long, value_parser = formation_runtime::cli::whole_number::<usize>, allow_negative_numbers = true)]
    pub agent: usize,
    /// How long the agent is down, s of simulation time.
    #[arg(long, allow_negative_numbers = true)]
    pub down: f64,
    /// Simulation time to apply at, s (if still ahead of the run; else a few steps from now).
    #[arg(long, allow_negative_numbers = true)]
    pub at: Option<f64>,
    /// Run id (see `formation ps`); may be omitted when exactly one run is running.
    #[arg(long)]
    pub run: Option<String>,
}

/// `formation inject link --state`.
#[derive(clap::ValueEnum, Debug, Clone, Copy, PartialEq, Eq)]
pub enum LinkState {
    /// The edge carries nothing.
    Down,
    /// The edge carries shares again.
    Up,
}

/// Arguments of `formation inject link`.
#[derive(clap::Args, Debug)]
pub struct LinkArgs {
    /// The edge, 1-based agent ids, e.g. 2,3.
    #[arg(long, value_delimiter = ',', required = true)]
    pub agents: Vec<usize>,
    /// Down or up.
    #[arg(long, value_enum)]
    pub state: LinkState,
    /// Simulation time to apply at, s (if still ahead of the run; else a few steps from now).
    #[arg(long, allow_negative_numbers = true)]
    pub at: Option<f64>,
    /// Run id (see `formation ps`); may be omitted when exactly one run is running.
    #[arg(long)]
    pub run: Option<String>,
}

/// Arguments of `formation inject fault`.
#[derive(clap::Args, Debug)]
pub struct FaultArgs {
    /// Agent id, 1-based (1..=N).
    #[arg(long, value_parser = formation_runtime::cli::whole_number::<usize>, allow_negative_numbers = true)]
    pub agent: usize,
    /// Gamma per axis, e.g. 0.5,0.5,0.5.
    #[arg(
        long,
        value_delimiter = ',',
        required = true,
        allow_hyphen_values = true
    )]
    pub gamma: Vec<f64>,
    /// delta per axis in N m, e.g. 0,0,0.
    #[arg(
        long,
        value_delimiter = ',',
        required = true,
        allow_hyphen_values = true
    )]
    pub delta: Vec<f64>,
    /// Simulation time to apply at, s (if still ahead of the run; else a few steps from now).
    #[arg(long, allow_negative_numbers = true)]
    pub at: Option<f64>,
    /// Run id (see `formation ps`); may be omitted when exactly one run is running.
    #[arg(long)]
    pub run: Option<String>,
}

/// Arguments of `formation inject delay`.
#[derive(clap::Args, Debug)]
pub struct DelayArgs {
    /// Agent id, 1-based (1..=N).
    #[arg(long, value_parser = formation_runtime::cli::whole_number::<usize>, allow_negative_numbers = true)]
    pub agent: usize,
    /// tau(t) in s: a constant (0.03) or base+amp*sin(w*t) (0.02+0.01*sin(0.5*t)).
    #[arg(long, allow_hyphen_values = true)]
    pub tau: String,
    /// Simulation time to apply at, s (if still ahead of the run; else a few steps from now).
    #[arg(long, allow_negative_numbers = true)]
    pub at: Option<f64>,
    /// Run id (see `formation ps`); may be omitted when exactly one run is running.
    #[arg(long)]
    pub run: Option<String>,
}

/// How long to wait for the orchestrator's confirmation.
const CONFIRM: Duration = Duration::from_secs(10);

fn three(v: &[f64], name: &'static str) -> Result<[f64; 3], RequestError> {
    <[f64; 3]>::try_from(v).map_err(|_| RequestError::Three(name))
}

/// Validates and builds the request (agent id 1-based on the command line, 0-based on the wire).
fn request(what: &InjectWhat) -> Result<(RunRecord, InjectRequest), RequestError> {
    let (run_id, agent, at) = match what {
        InjectWhat::Fault(a) => (a.run.as_deref(), a.agent, a.at),
        InjectWhat::Delay(a) => (a.run.as_deref(), a.agent, a.at),
        InjectWhat::Crash(a) | InjectWhat::Hang(a) => (a.run.as_deref(), a.agent, a.at),
        InjectWhat::Link(a) => (
            a.run.as_deref(),
            a.agents.first().copied().unwrap_or(0),
            a.at,
        ),
    };
    if let Some(t) = at {
        // What can be checked without the run is checked before looking for it.
        validate::at_sign(t)?;
    }
    let run = registry::find(run_id)?;
    formation_runtime::live::check_access(&run, "inject into")?;
    let s = formation_runtime::live::run_scenario(&run)?;
    validate::agent(agent, run.n_agents)?;
    let at_step = match at {
        Some(t) => {
            validate::at(&s, t)?;
            (t / s.simulation.dt_s).round() as u64
        }
        None => INJECT_ASAP,
    };
    let mut r = InjectRequest {
        nonce: nonce(),
        at_step,
        agent: (agent - 1) as u32,
        ..InjectRequest::default()
    };
    match what {
        InjectWhat::Fault(a) => {
            r.kind = INJECT_FAULT;
            r.gamma = three(&a.gamma, "gamma")?;
            r.delta = three(&a.delta, "delta")?;
            validate::fault(&s, r.gamma, r.delta)?;
        }
        InjectWhat::Delay(a) => {
            let d = validate::parse_tau(&a.tau)?;
            validate::delay(&s, &d)?;
            r.kind = INJECT_DELAY;
            r.base_s = d.base_s;
            r.amplitude_s = d.amplitude_s;
            r.angular_rate_rad_s = d.angular_rate_rad_s;
        }
        InjectWhat::Crash(a) | InjectWhat::Hang(a) => {
            r.kind = if matches!(what, InjectWhat::Crash(_)) {
                INJECT_CRASH
            } else {
                INJECT_HANG
            };
            validate::down(a.down)?;
            r.down_s = a.down;
        }
        InjectWhat::Link(a) => {
            let [_, b] =
                <[usize; 2]>::try_from(a.agents.as_slice()).map_err(|_| RequestError::Agents)?;
            validate::agent(b, run.n_agents)?;
            r.kind = if a.state == LinkState::Down {
                INJECT_LINK_DOWN
            } else {
                INJECT_LINK_UP
            };
            r.other = (b - 1) as u32;
        }
    }
    // The run checks the rest against its scenario and graph (the edge, down_s).
    if matches!(
        r.kind,
        INJECT_CRASH | INJECT_HANG | INJECT_LINK_DOWN | INJECT_LINK_UP
    ) {
        let e = formation_runtime::run::injections::event_of(&r, s.simulation.dt_s, 0);
        formation_config::scenario::validate::validate_event(&s, "inject", &e)?;
    }
    Ok((run, r))
}

fn nonce() -> u64 {
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as u64);
    nanos ^ ((std::process::id() as u64) << 40)
}

/// Entry point of `formation inject`.
pub fn main(args: InjectArgs) -> Result<(), LiveError> {
    let (run, req) = request(&args.what)?;
    let result = send_and_confirm(&run, &req);
    formation_runtime::live::tidy_after(&run);
    let line = result?;
    let mut v: serde_json::Value = serde_json::from_str(&line).unwrap_or_default();
    if args.json {
        if let Some(o) = v.as_object_mut() {
            o.insert("run".into(), run.id.clone().into());
        }
        println!("{v}");
        return Ok(());
    }
    println!(
        "{} injection for agent {} of run {} applies at step {} (t = {:.3} s){}",
        v["event"].as_str().unwrap_or("?"),
        req.agent + 1,
        run.id,
        v["step"],
        v["t"].as_f64().unwrap_or(f64::NAN),
        if v["after_end"].as_bool() == Some(true) {
            ", after the end of the run"
        } else {
            ""
        }
    );
    Ok(())
}

/// Sends the request and waits for its line in `events.jsonl` (the publisher stays alive until
/// then, so the sample cannot be lost).
fn send_and_confirm(run: &RunRecord, req: &InjectRequest) -> Result<String, ConfirmError> {
    let node = formation_runtime::live::client_node(run, "inject")?;
    let p = publisher::<InjectRequest>(&node, &services::INJECT_REQUEST.named())?;
    let wake = notifier(&node, &services::WAKE_ORCHESTRATOR.named())?;
    send(&p, *req)?;
    poke(&wake);
    let events = run.out_dir.join("events.jsonl");
    let needle = format!("\"nonce\":{}", req.nonce);
    let start = Instant::now();
    while start.elapsed() < CONFIRM {
        if let Ok(text) = std::fs::read_to_string(&events) {
            // Only a whole line: the orchestrator may be writing it right now.
            if let Some(line) = text
                .split_inclusive('\n')
                .filter_map(|l| l.strip_suffix('\n'))
                .find(|l| l.contains(&needle))
            {
                if line.contains("\"event\":\"rejected\"") {
                    return Err(ConfirmError::Rejected(line.to_string()));
                }
                return Ok(line.to_string());
            }
        }
        if !run.is_live() {
            return Err(ConfirmError::Ended(run.id.clone()));
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    Err(ConfirmError::Timeout {
        run: run.id.clone(),
        seconds: CONFIRM.as_secs(),
    })
}
