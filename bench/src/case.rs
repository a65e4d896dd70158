//! Runs one case from the plant's side (this process): pins itself, creates the transport, spawns
//! the agent processes, measures, stops and reaps them.

use super::iox::{self, IoxLink, Ports, Services};
use super::link::{self, Budget, Link, Sizes, Wait};
use super::plan::{Case, Transport};
use super::procs::{self, Peers};
use super::sock::{self, SockLink};
use crate::error::{CaseError, ResultExt};
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
pub fn run(ctx: &Ctx, idx: usize, case: &Case) -> Result<Histogram<u64>, CaseError> {
    if let Some(cpu) = case.placement.cpu_of(0) {
        procs::set_affinity(&[cpu]).ctx(format!("pin to cpu {cpu}"))?;
    }
    if case.batch {
        formation_config::node::sched::batch_policy().map_err(CaseError::below)?;
    }
    let result = run_pinned(ctx, idx, case);
    let _ = procs::set_affinity(ctx.allowed);
    if case.batch {
        let _ = formation_config::node::sched::other_policy();
    }
    result
}

fn run_pinned(ctx: &Ctx, idx: usize, case: &Case) -> Result<Histogram<u64>, CaseError> {
    match case.transport {
        Transport::IoxEvent | Transport::IoxWaitSet | Transport::IoxPoll => {
            let services = Services::create(ctx.node, idx, case.n).ctx("iceoryx2")?;
            let notify = case.transport != Transport::IoxPoll;
            let ports = Ports::plant(&services, ctx.sizes.down, notify).ctx("iceoryx2")?;
            let peers = spawn(ctx, idx, case, None)?;
            if case.transport == Transport::IoxWaitSet {
                let ws = iox::waitset().ctx("iceoryx2")?;
                let _guard = ws
                    .attach_notification(&ports.listener)
                    .map_err(|e| CaseError::op("iceoryx2", format!("attach listener: {e:?}")))?;
                let mut link = IoxLink::new(&ports, Some(&ws), u32::MAX, ctx.sizes.down);
                measure(ctx, case, &mut link, peers)
            } else {
                let mut link = IoxLink::new(&ports, None, u32::MAX, ctx.sizes.down);
                measure(ctx, case, &mut link, peers)
            }
        }
        Transport::Uds => {
            let addr = sock::uds_addr(ctx.prefix, idx, None).ctx("uds")?;
            let s = sock::bind_uds(&addr).ctx("uds bind")?;
            let mut link = SockLink::plant(s, case.n, ctx.sizes.down, case.wait).ctx("uds")?;
            let peers = spawn(ctx, idx, case, None)?;
            measure(ctx, case, &mut link, peers)
        }
        Transport::Udp => {
            let s = sock::bind_udp(0).ctx("udp bind")?;
            let port = s.local_addr().ctx("udp")?.port();
            let mut link = SockLink::plant(s, case.n, ctx.sizes.down, case.wait).ctx("udp")?;
            let peers = spawn(ctx, idx, case, Some(port))?;
            measure(ctx, case, &mut link, peers)
        }
        Transport::Zenoh => Err(CaseError::ZenohCase),
    }
}

fn spawn(ctx: &Ctx, idx: usize, case: &Case, udp_port: Option<u16>) -> Result<Peers, CaseError> {
    Peers::spawn(agent_args(ctx, idx, case, udp_port)).ctx("spawn peer processes")
}

fn measure(
    ctx: &Ctx,
    case: &Case,
    link: &mut dyn Link,
    peers: Peers,
) -> Result<Histogram<u64>, CaseError> {
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
) -> Result<Histogram<u64>, CaseError> {
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
    peers.into_inner().finish(grace).ctx("peers")?;
    Ok(hist)
}
