//! Runs one case from the plant's side (this process): pins itself, creates the transport, spawns
//! the agent processes, measures, stops and reaps them.

use super::iox::{self, IoxLink, Ports, Services};
use super::link::{self, Budget, Link, Sizes, Wait};
use super::plan::{Case, Transport};
use super::procs::{self, Peers};
use super::sock::{self, SockLink};
use hdrhistogram::Histogram;
use iceoryx2::prelude::*;
use std::cell::{Cell, RefCell};
use std::time::{Duration, Instant};

/// How long the peers of a case get to exit after the stop message, at least.
const EXIT_GRACE: Duration = Duration::from_secs(5);
/// And per peer: on a loaded 2-vCPU machine 100 peers waking, closing their iceoryx2 nodes and
/// exiting at once took more than 5 s (2026-12-02, load average 30).
const EXIT_GRACE_PER_PEER: Duration = Duration::from_millis(200);

/// Everything a case needs besides the case itself.
pub struct Ctx<'a> {
    /// The run's iceoryx2 node (under the run prefix).
    pub node: &'a Node<ipc::Service>,
    /// The run's iceoryx2 prefix (also names the Unix sockets).
    pub prefix: &'a str,
    /// Message sizes, bytes.
    pub sizes: Sizes,
    /// Measuring time and warm-up.
    pub budget: Budget,
    /// This process's CPUs before any pinning (restored after each case).
    pub allowed: &'a [usize],
}

fn wait_arg(w: Wait) -> Vec<String> {
    match w {
        Wait::Block => vec!["--wait".into(), "block".into()],
        Wait::Busy => vec!["--wait".into(), "busy".into()],
        Wait::SpinBlock(d) => vec![
            "--wait".into(),
            "spin-block".into(),
            "--spin-us".into(),
            d.as_micros().to_string(),
        ],
    }
}

/// Command lines of the `n` agents of case number `idx`.
fn agent_args(ctx: &Ctx, idx: usize, case: &Case, udp_port: Option<u16>) -> Vec<Vec<String>> {
    (0..case.n)
        .map(|i| {
            let mut a = vec![
                "--transport".into(),
                case.transport.name().into(),
                "--prefix".into(),
                ctx.prefix.into(),
                "--case".into(),
                idx.to_string(),
                "--index".into(),
                i.to_string(),
                "--payload".into(),
                ctx.sizes.up.to_string(),
            ];
            a.extend(wait_arg(case.wait));
            if let Some(cpu) = case.placement.cpu_of(i + 1) {
                a.extend(["--cpu".into(), cpu.to_string()]);
            }
            if case.batch {
                a.push("--batch".into());
            }
            if let Some(p) = udp_port {
                a.extend(["--plant-port".into(), p.to_string()]);
            }
            a
        })
        .collect()
}

/// Measures case number `idx`; the histogram holds one value (ns) per round trip or step.
pub fn run(ctx: &Ctx, idx: usize, case: &Case) -> Result<Histogram<u64>, String> {
    if let Some(cpu) = case.placement.cpu_of(0) {
        procs::set_affinity(&[cpu]).map_err(|e| format!("pin to cpu {cpu}: {e}"))?;
    }
    if case.batch {
        formation_config::node::sched::batch_policy()?;
    }
    let result = run_pinned(ctx, idx, case);
    let _ = procs::set_affinity(ctx.allowed);
    if case.batch {
        let _ = formation_config::node::sched::other_policy();
    }
    result
}

fn run_pinned(ctx: &Ctx, idx: usize, case: &Case) -> Result<Histogram<u64>, String> {
    match case.transport {
        Transport::IoxEvent | Transport::IoxWaitSet | Transport::IoxPoll => {
            let services =
                Services::create(ctx.node, idx, case.n).map_err(|e| format!("iceoryx2: {e}"))?;
            let notify = case.transport != Transport::IoxPoll;
            let ports = Ports::plant(&services, ctx.sizes.down, notify)
                .map_err(|e| format!("iceoryx2: {e}"))?;
            let peers = spawn(ctx, idx, case, None)?;
            if case.transport == Transport::IoxWaitSet {
                let ws = iox::waitset().map_err(|e| format!("iceoryx2: {e}"))?;
                let _guard = ws
                    .attach_notification(&ports.listener)
                    .map_err(|e| format!("iceoryx2: attach listener: {e:?}"))?;
                let mut link = IoxLink::new(&ports, Some(&ws), u32::MAX, ctx.sizes.down);
                measure(ctx, case, &mut link, peers)
            } else {
                let mut link = IoxLink::new(&ports, None, u32::MAX, ctx.sizes.down);
                measure(ctx, case, &mut link, peers)
            }
        }
        Transport::Uds => {
            let addr = sock::uds_addr(ctx.prefix, idx, None).map_err(|e| format!("uds: {e}"))?;
            let s = sock::bind_uds(&addr).map_err(|e| format!("uds bind: {e}"))?;
            let mut link = SockLink::plant(s, case.n, ctx.sizes.down, case.wait)
                .map_err(|e| format!("uds: {e}"))?;
            let peers = spawn(ctx, idx, case, None)?;
            measure(ctx, case, &mut link, peers)
        }
        Transport::Udp => {
            let s = sock::bind_udp(0).map_err(|e| format!("udp bind: {e}"))?;
            let port = s.local_addr().map_err(|e| format!("udp: {e}"))?.port();
            let mut link = SockLink::plant(s, case.n, ctx.sizes.down, case.wait)
                .map_err(|e| format!("udp: {e}"))?;
            let peers = spawn(ctx, idx, case, Some(port))?;
            measure(ctx, case, &mut link, peers)
        }
        Transport::Zenoh => Err("zenoh is measured by its own cases (bench::zenoh)".into()),
    }
}

fn spawn(ctx: &Ctx, idx: usize, case: &Case, udp_port: Option<u16>) -> Result<Peers, String> {
    Peers::spawn(agent_args(ctx, idx, case, udp_port))
        .map_err(|e| format!("spawn peer processes: {e}"))
}

fn measure(
    ctx: &Ctx,
    case: &Case,
    link: &mut dyn Link,
    peers: Peers,
) -> Result<Histogram<u64>, String> {
    let grace = EXIT_GRACE + EXIT_GRACE_PER_PEER * case.n as u32;
    measure_with(ctx, (case.n, case.wait), link, peers, grace)
}

/// Runs the plant loop on `link` waiting for `replies` per step with `wait`, while `peers` run
/// (checked at most every 20 ms), then gives them `grace` to exit.
pub fn measure_with(
    ctx: &Ctx,
    (replies, wait): (usize, Wait),
    link: &mut dyn Link,
    peers: Peers,
    grace: Duration,
) -> Result<Histogram<u64>, String> {
    let peers = RefCell::new(peers);
    let last_check = Cell::new(Instant::now());
    let alive = || {
        // waitpid for every peer at most every 20 ms (busy loops call this often).
        if last_check.get().elapsed() < Duration::from_millis(20) {
            return true;
        }
        last_check.set(Instant::now());
        peers.borrow_mut().all_alive()
    };
    let hist = link::run_plant(link, replies, wait, ctx.budget, &alive)?;
    peers
        .into_inner()
        .finish(grace)
        .map_err(|e| format!("peers: {e}"))?;
    Ok(hist)
}
