//! `formation bench`: IPC latency and jitter between processes, in one run: iceoryx2 (event
//! listener, WaitSet, busy-poll) vs Unix datagram sockets vs UDP loopback; ping-pong and fan-out;
//! blocking, spin-then-block, pinned and all-on-one-core.
//!
//! This process plays the plant (it measures); the agents are child processes running the hidden
//! `formation bench-peer` subcommand. Every run uses its own iceoryx2 prefix and removes its files
//! from /dev/shm and /tmp/iceoryx2 at the end; children are reaped, killed on failure or Ctrl-C,
//! and die with this process.
//!
//! * [`plan`]: which cases run (and which are skipped, and why).
//! * [`case`]: one case from the plant's side; [`peer`]: the agent side.
//! * [`link`]: message header, waiting strategies, the plant and agent loops.
//! * [`iox`], [`sock`]: the transports. [`procs`]: child processes and CPU pinning.
//! * [`report`]: percentiles, table, JSON.
//! * `zenoh`, `split` (cargo feature `multihost`; only with `--transports zenoh`): bare Zenoh
//!   ping-pong and the fan-out of a split lockstep step, and the split lockstep run itself (a
//!   `formation host` daemon on loopback); [`versus`]: the split step against that fan-out.

mod case;
pub mod error;
mod iox;
mod link;
mod lockstep;
mod peer;
mod plan;
mod procs;
mod report;
mod row;
#[cfg(feature = "multihost")]
mod secure;
mod sock;
#[cfg(feature = "multihost")]
mod split;
mod versus;
#[cfg(feature = "multihost")]
mod zenoh;

pub use peer::{main as peer_main, PeerArgs};

use error::{ArgError, BenchError};
use formation_config::node::ipc as fipc;
use formation_config::protocol::services::run_prefix;
use link::{Budget, Sizes, MAX_PAYLOAD, MIN_PAYLOAD};
use plan::{PlanInput, Transport};
use std::time::{Duration, SystemTime, UNIX_EPOCH};

/// Largest `--n` (agent processes).
pub const MAX_N: usize = 200;

/// Largest `--rounds`.
pub const MAX_ROUNDS: usize = 20;

/// Why `--transports zenoh` is refused by a build without Zenoh.
#[cfg(not(feature = "multihost"))]
const ZENOH_NEEDS_MULTIHOST: &str =
    "transport 'zenoh' needs the cargo feature `multihost` (this formation was built without it)";

/// Cases a round of `--transports zenoh` runs besides the split lockstep: ping-pong, fan-out.
const ZENOH_CASES: usize = 2;

/// Arguments of `formation bench`.
#[derive(clap::Args, Debug)]
pub struct BenchArgs {
    /// Agent processes of the fan-out cases (and of the lockstep run); a comma-separated list
    /// (`--n 20,50,100,128`) measures every N in one run: each round runs the cases of every N in
    /// turn, and the lockstep / fan-out ratio is given per N.
    #[arg(long, default_value = "5", value_delimiter = ',', value_parser = formation_runtime::cli::whole_number::<usize>, allow_negative_numbers = true)]
    pub n: Vec<usize>,
    /// Message size, bytes (16..=60000), both directions, every transport. Default: the sizes of
    /// the lockstep's per-step messages, the state sent to an agent (`VehicleState`) and the
    /// command it answers with (`ControlCommand`), so the fan-out is comparable with the lockstep
    /// row.
    #[arg(long, value_parser = formation_runtime::cli::whole_number::<usize>, allow_negative_numbers = true)]
    pub payload: Option<usize>,
    /// Measured time per case, s (a warm-up of 10 %, at most 0.25 s, is discarded first).
    #[arg(long, default_value_t = 1.5, allow_negative_numbers = true)]
    pub seconds: f64,
    /// Pin processes round-robin to these CPUs (e.g. `0,1` or `0-1`); the plant gets the first.
    /// Without it processes are not pinned (except in the `/one-core` cases).
    #[arg(long)]
    pub cpu: Option<String>,
    /// Spin budget of the spin-then-block strategy, µs.
    #[arg(long, default_value_t = 50, value_parser = formation_runtime::cli::whole_number::<u64>, allow_negative_numbers = true)]
    pub spin_us: u64,
    /// Only these transports (comma-separated: iox2-event, iox2-waitset, iox2-poll, uds-dgram,
    /// udp, zenoh). `zenoh` is measured only when named: bare Zenoh ping-pong and the fan-out of
    /// a lockstep step of the paper scenario split over two hosts (agents 4, 5 on the second),
    /// each round alternated with that split run in lockstep (a `formation host` daemon started
    /// on a free loopback port, with its own /dev/shm), set against each other (N = 5 whatever
    /// `--n`; `--payload` sizes the ping-pong only).
    #[arg(long)]
    pub transports: Option<String>,
    /// How the two hosts of the Zenoh cases are linked: `tcp` (loopback, user/password), `tls`
    /// (loopback, mutual TLS over TCP) or `quic` (loopback, QUIC with the same mutual TLS); the
    /// bench makes the credentials. Compare them with alternated invocations
    /// (docs/multi-host.md).
    #[cfg(feature = "multihost")]
    #[arg(long, value_enum, default_value = "tcp")]
    pub zenoh_link: secure::ZenohLink,
    /// Skip the lockstep case (a real `formation run` in lockstep, timed per step and set against
    /// the iceoryx2 event fan-out; it runs for every N from 2 to MAX_AGENTS (128) whenever
    /// iox2-event is measured: the paper scenario for N = 5, a generated path formation
    /// otherwise).
    #[arg(long)]
    pub no_lockstep: bool,
    /// Run every case (and the lockstep) this many times, alternated: round 1 runs them all, then
    /// round 2, ... The table shows each case's median round, and each lockstep / fan-out ratio is
    /// the median of the ratios taken within each round, so that slow and fast phases of a shared
    /// machine cancel out (1..=20).
    #[arg(long, default_value_t = 1, value_parser = formation_runtime::cli::whole_number::<usize>, allow_negative_numbers = true)]
    pub rounds: usize,
    /// Print `{"results": [...]}` on stdout instead of the table.
    #[arg(long)]
    pub json: bool,
    /// Measure only the host's own timer noise and exit: a bare 1 ms timer loop (absolute
    /// sleeps, 1 ns timer slack, no work) for `--seconds` per round, under the normal policy and,
    /// when this process is allowed to (CAP_SYS_NICE or RLIMIT_RTPRIO, checked), under
    /// SCHED_FIFO 10 as a realtime run's plant; each round alternates the two. Prints the mean
    /// lateness and the fraction of wake-ups later than 500 µs (docs/realtime.md, "The host's own
    /// limit").
    #[arg(long)]
    pub host: bool,
}

/// `formation bench --host`: the bare timer loop, alternated normal / SCHED_FIFO per round.
fn host_main(args: &BenchArgs) -> Result<(), BenchError> {
    use formation_runtime::run::{host_probe, rt};
    if !(args.seconds > 0.0 && args.seconds <= 3600.0) {
        return Err(BenchError::HostSeconds(args.seconds));
    }
    let fifo = rt::decide(rt::Requested::Auto, false, rt::Privilege::of_this_process())
        .map(|s| s.priority)
        .unwrap_or(0);
    let policies: Vec<u32> = if fifo > 0 { vec![0, fifo] } else { vec![0] };
    let duration = std::time::Duration::from_secs_f64(args.seconds);
    let mut rows = Vec::new();
    for round in 1..=args.rounds {
        for &p in &policies {
            let s = host_probe::probe(p, duration);
            let policy = if p > 0 {
                format!("SCHED_FIFO {p}")
            } else {
                "normal".to_string()
            };
            if !args.json {
                println!(
                    "host round {round} {policy:<14} {} periods of {} µs: mean {:.1} µs late, max {:.0} µs, > {} µs late: {} ({:.4} %)",
                    s.periods,
                    host_probe::PERIOD.as_micros(),
                    s.mean_late_us,
                    s.max_late_us,
                    host_probe::LATE.as_micros(),
                    s.late,
                    s.late_fraction * 100.0
                );
            }
            rows.push(serde_json::json!({"round": round, "rt_priority": p, "probe": s}));
        }
    }
    if args.json {
        println!("{}", serde_json::json!({ "host": rows }));
    }
    Ok(())
}

fn parse_transports(s: &str) -> Result<Vec<Transport>, ArgError> {
    s.split(',')
        .map(str::trim)
        .filter(|p| !p.is_empty())
        .map(|p| Transport::parse(p).ok_or_else(|| ArgError::Transport(p.to_string())))
        .collect()
}

/// The plan input of each N of `--n`, in order (a repeated N counts once).
fn validate(a: &BenchArgs, allowed: &[usize]) -> Result<Vec<PlanInput>, ArgError> {
    if a.n.is_empty() {
        return Err(ArgError::NoN);
    }
    if let Some(&n) = a.n.iter().find(|&&n| n == 0 || n > MAX_N) {
        return Err(ArgError::N { n, max: MAX_N });
    }
    if let Some(got) = a
        .payload
        .filter(|p| !(MIN_PAYLOAD..=MAX_PAYLOAD).contains(p))
    {
        return Err(ArgError::Payload {
            got,
            min: MIN_PAYLOAD,
            max: MAX_PAYLOAD,
        });
    }
    if !a.seconds.is_finite() || a.seconds <= 0.0 || a.seconds > 3600.0 {
        return Err(ArgError::Seconds(a.seconds));
    }
    if !(1..=MAX_ROUNDS).contains(&a.rounds) {
        return Err(ArgError::Rounds {
            got: a.rounds,
            max: MAX_ROUNDS,
        });
    }
    if a.spin_us > 1_000_000 {
        return Err(ArgError::SpinUs(a.spin_us));
    }
    let cpus = a
        .cpu
        .as_deref()
        .map(|s| formation_runtime::cpus::parse_list(s, allowed))
        .transpose()
        .map_err(ArgError::Cpu)?;
    let only = match a.transports.as_deref() {
        Some(s) => parse_transports(s)?,
        None => Vec::new(),
    };
    #[cfg(not(feature = "multihost"))]
    if only.contains(&Transport::Zenoh) {
        return Err(ArgError::ZenohNeedsMultihost);
    }
    let mut ns: Vec<usize> = Vec::new();
    for &n in &a.n {
        if !ns.contains(&n) {
            ns.push(n);
        }
    }
    Ok(ns
        .into_iter()
        .map(|n| PlanInput {
            n,
            spin: Duration::from_micros(a.spin_us),
            cpus: cpus.clone(),
            allowed: allowed.to_vec(),
            lockstep: !a.no_lockstep
                && (2..=formation_config::MAX_AGENTS).contains(&n)
                && (only.is_empty() || only.contains(&Transport::IoxEvent)),
            only: only.clone(),
        })
        .collect())
}

/// The cases of every N in order and what is skipped; the ping-pong cases (one peer, whatever N)
/// run once, with the first N.
fn plan_all(inputs: &[PlanInput]) -> (Vec<plan::Case>, Vec<(String, String)>) {
    let mut cases = Vec::new();
    let mut skipped = Vec::new();
    for (k, input) in inputs.iter().enumerate() {
        let (c, s) = plan::plan(input);
        cases.extend(
            c.into_iter()
                .filter(|c| k == 0 || c.pattern != plan::Pattern::PingPong),
        );
        for s in s {
            if !skipped.contains(&s) {
                skipped.push(s);
            }
        }
    }
    (cases, skipped)
}

/// A prefix unique to this run: process id plus clock.
fn unique_prefix() -> String {
    let t = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_micros() as u64)
        .unwrap_or(0);
    run_prefix(&format!("b{}t{:x}", std::process::id(), t & 0xff_ffff))
}

/// Entry point of `formation bench`: measures every case and prints the table (or JSON); fails
/// on a bad argument, a failed case or Ctrl-C.
pub fn main(args: BenchArgs) -> Result<(), BenchError> {
    if args.host {
        return host_main(&args);
    }
    let allowed = procs::allowed_cpus();
    let inputs = validate(&args, &allowed)?;
    let (cases, skipped) = plan_all(&inputs);
    let zenoh = inputs
        .first()
        .is_some_and(|i| i.only.contains(&Transport::Zenoh));
    let sizes = args
        .payload
        .map_or_else(Sizes::lockstep_wire, |p| Sizes { down: p, up: p });
    procs::install_interrupt_handler();
    let prefix = unique_prefix();
    let warmup = Duration::from_secs_f64((args.seconds * 0.1).clamp(0.02, 0.25));
    let budget = Budget {
        measure: Duration::from_secs_f64(args.seconds),
        warmup,
        min_warmup_samples: 20,
    };
    let zenoh_cases = if zenoh { ZENOH_CASES } else { 0 };
    eprintln!(
        "formation bench: iceoryx2 prefix {prefix}, {} cases x {:.2} s (+{:.2} s warm-up), messages {} B{}",
        cases.len() + zenoh_cases,
        args.seconds,
        warmup.as_secs_f64(),
        sizes.label(),
        if zenoh {
            ", and the split lockstep run"
        } else {
            ""
        }
    );
    let node = fipc::node(&prefix, "bench-plant").map_err(|e| {
        let _ = fipc::remove_residue(&prefix);
        BenchError::Node(e)
    })?;
    let ctx = case::Ctx {
        node: &node,
        prefix: &prefix,
        sizes,
        budget,
        allowed: &allowed,
    };
    let mut rounds: Vec<Vec<row::Row>> = Vec::new();
    let mut failures = 0;
    for round in 1..=args.rounds {
        if procs::aborted() {
            break;
        }
        if args.rounds > 1 {
            eprintln!("round {round} of {}", args.rounds);
        }
        let mut rows = Vec::new();
        let first = (round - 1) * (cases.len() + zenoh_cases);
        failures += run_round(&ctx, &cases, first, &inputs, &args, &mut rows);
        if zenoh && !procs::aborted() {
            failures += run_zenoh(&ctx, first + cases.len(), &args, &mut rows);
        }
        rounds.push(rows);
    }
    drop(node);
    match fipc::remove_residue(&prefix) {
        Ok(_) => {}
        Err(e) => eprintln!("warning: could not remove iceoryx2 files of {prefix}: {e}"),
    }
    if procs::aborted() {
        return Err(BenchError::Interrupted);
    }
    let rows = lockstep::median_rows(&rounds);
    let comparisons = lockstep::across_rounds_per_n(&versus::without_zenoh(&rounds));
    let split = versus::split_vs_fan_out(&rounds);
    if args.json {
        println!(
            "{}",
            report::json(&rows, &comparisons, rounds.len(), split.as_ref())
        );
    } else {
        print!(
            "{}",
            report::table(&rows, &comparisons, rounds.len(), split.as_ref(), &skipped)
        );
    }
    if failures > 0 {
        return Err(BenchError::CasesFailed(failures));
    }
    Ok(())
}

/// One round: for each N in turn, its cases, then its lockstep run if planned. Appends the rows to
/// `rows` and returns the number of failed cases. Case numbers (which name services and sockets)
/// start at `first`, so that no round reuses a name of an earlier one.
fn run_round(
    ctx: &case::Ctx,
    cases: &[plan::Case],
    first: usize,
    inputs: &[PlanInput],
    args: &BenchArgs,
    rows: &mut Vec<row::Row>,
) -> usize {
    let mut failures = 0;
    for (k, input) in inputs.iter().enumerate() {
        // The ping-pong cases (n = 1) run with the first N.
        let of_n = |c: &plan::Case| match c.pattern {
            plan::Pattern::PingPong => k == 0,
            plan::Pattern::FanOut => c.n == input.n,
        };
        let mine: Vec<(usize, &plan::Case)> =
            cases.iter().enumerate().filter(|(_, c)| of_n(c)).collect();
        failures += run_cases(ctx, &mine, first, rows);
        if input.lockstep && !procs::aborted() {
            failures += run_lockstep(input.n, args.seconds, rows);
        }
    }
    failures
}

/// The Zenoh cases of one round, case numbers from `first`: ping-pong, then the split step's
/// fan-out and the split lockstep run, one after the other; returns the number that failed.
#[cfg(feature = "multihost")]
fn run_zenoh(ctx: &case::Ctx, first: usize, args: &BenchArgs, rows: &mut Vec<row::Row>) -> usize {
    let seconds = args.seconds;
    let link = args.zenoh_link;
    let scratch = std::env::temp_dir().join(format!("formation-bench-{}", std::process::id()));
    let sec = match secure::Secured::make(link, &scratch.join("creds")) {
        Ok(s) => s,
        Err(e) => {
            eprintln!(
                "  zenoh over {}: FAILED: cannot make its credentials: {e}",
                link.name()
            );
            return 1;
        }
    };
    let mut failures = 0;
    for (k, pattern) in [plan::Pattern::PingPong, plan::Pattern::FanOut]
        .into_iter()
        .enumerate()
    {
        if procs::aborted() {
            return failures;
        }
        let what = format!("zenoh ({}) {} block", link.name(), pattern.name());
        match zenoh::run(ctx, first + k, pattern, &sec) {
            Ok(row) => {
                eprintln!(
                    "  {what}: p50 {:.1} µs, p99 {:.1} µs ({} samples)",
                    row.p50_us, row.p99_us, row.samples
                );
                rows.push(row);
            }
            Err(e) if procs::aborted() => eprintln!("  {what}: interrupted ({e})"),
            Err(e) => {
                eprintln!("  {what}: FAILED: {e}");
                failures += 1;
            }
        }
    }
    if procs::aborted() {
        return failures;
    }
    let what = format!(
        "zenoh ({}) lockstep split {}",
        link.name(),
        split::place_arg()
    );
    match split::run(seconds, &scratch, &sec) {
        Ok(s) => {
            eprintln!(
                "  {what}: p50 {:.1} µs, mean {:.1} µs per step ({} steps; iceoryx2 prefix {})",
                s.row.p50_us,
                s.row.mean_us,
                s.row.samples,
                s.prefix.as_deref().unwrap_or("?")
            );
            rows.push(s.row);
        }
        Err(e) if procs::aborted() => eprintln!("  {what}: interrupted ({e})"),
        Err(e) => {
            eprintln!("  {what}: FAILED: {e}");
            failures += 1;
        }
    }
    drop(sec);
    let _ = std::fs::remove_dir_all(&scratch);
    failures
}

/// Without Zenoh nothing runs (`--transports zenoh` is refused by [`validate`]).
#[cfg(not(feature = "multihost"))]
fn run_zenoh(_: &case::Ctx, _: usize, _: &BenchArgs, _: &mut Vec<row::Row>) -> usize {
    0
}

/// Runs `cases` (with their index in the round's list); returns the number that failed.
fn run_cases(
    ctx: &case::Ctx,
    cases: &[(usize, &plan::Case)],
    first: usize,
    rows: &mut Vec<row::Row>,
) -> usize {
    let mut failures = 0;
    for &(idx, c) in cases {
        if procs::aborted() {
            break;
        }
        let what = format!(
            "{} {} {} n={}",
            c.transport.name(),
            c.pattern.name(),
            c.wait_label(),
            c.n
        );
        match case::run(ctx, first + idx, c) {
            Ok(h) if h.is_empty() => {
                eprintln!("  {what}: no samples");
                failures += 1;
            }
            Ok(h) => {
                let row = row::Row::new(c, ctx.sizes, &h);
                eprintln!(
                    "  {what}: p50 {:.1} µs ({} samples)",
                    row.p50_us, row.samples
                );
                rows.push(row);
            }
            Err(e) if procs::aborted() => eprintln!("  {what}: interrupted ({e})"),
            Err(e) => {
                eprintln!("  {what}: FAILED: {e}");
                failures += 1;
            }
        }
    }
    failures
}

/// Runs the lockstep case with `n` agents; returns 1 if it failed.
fn run_lockstep(n: usize, seconds: f64, rows: &mut Vec<row::Row>) -> usize {
    let what = format!("lockstep (formation run) n={n}");
    let scratch = std::env::temp_dir().join(format!("formation-bench-{}", std::process::id()));
    let failed = match lockstep::run(n, seconds, &scratch) {
        Ok(row) => {
            eprintln!(
                "  {what}: p50 {:.1} µs, mean {:.1} µs per step ({} steps)",
                row.p50_us, row.mean_us, row.samples
            );
            rows.push(row);
            0
        }
        Err(e) if procs::aborted() => {
            eprintln!("  {what}: interrupted ({e})");
            0
        }
        Err(e) => {
            eprintln!("  {what}: FAILED: {e}");
            1
        }
    };
    let _ = std::fs::remove_dir_all(&scratch);
    failed
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unique_prefix_is_a_valid_iceoryx2_prefix() {
        assert!(fipc::is_valid_prefix(&unique_prefix()));
    }
}
