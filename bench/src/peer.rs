//! The agent side of a case, run in a child process (`formation bench-peer ...`).

use super::iox::{self, IoxLink, Ports, Services};
use super::link::{self, Wait, MAX_PAYLOAD, MIN_PAYLOAD};
use super::plan::Transport;
use super::procs;
use super::sock::{self, SockLink};
use crate::error::{CaseError, PeerError, ResultExt};
use formation_config::node::ipc as fipc;
use std::net::SocketAddr;
use std::time::Duration;

/// Arguments of the hidden `formation bench-peer` (started by `formation bench` only).
#[derive(clap::Args, Debug)]
pub struct PeerArgs {
    /// Transport name (`iox2-event`, `iox2-waitset`, `iox2-poll`, `uds-dgram`, `udp`, `zenoh`).
    #[arg(long)]
    pub transport: String,
    /// iceoryx2 prefix of the run (also names the Unix sockets).
    #[arg(long)]
    pub prefix: String,
    /// Case number (names the services and sockets of the case).
    #[arg(long)]
    pub case: usize,
    /// Agent index (0-based).
    #[arg(long)]
    pub index: u32,
    /// Size of the messages this agent sends (the plant's may differ), bytes.
    #[arg(long)]
    pub payload: usize,
    /// `block`, `spin-block` or `busy`.
    #[arg(long)]
    pub wait: String,
    /// Spin budget of `spin-block`, µs.
    #[arg(long, default_value_t = 50)]
    pub spin_us: u64,
    /// Pin this process to this CPU.
    #[arg(long)]
    pub cpu: Option<usize>,
    /// Run under SCHED_BATCH.
    #[arg(long)]
    pub batch: bool,
    /// UDP port of the plant on 127.0.0.1.
    #[arg(long)]
    pub plant_port: Option<u16>,
    /// Zenoh: the endpoint this peer listens on (`tcp/`, `tls/` or `quic/127.0.0.1:PORT`).
    #[arg(long)]
    pub endpoint: Option<String>,
    /// Zenoh over TCP: the `user:password` file.
    #[arg(long)]
    pub auth: Option<std::path::PathBuf>,
    /// Zenoh over TLS: this host's certificate folder.
    #[arg(long)]
    pub tls: Option<std::path::PathBuf>,
    /// Zenoh: `ping-pong` or `fan-out` (the frames of a split lockstep step).
    #[arg(long)]
    pub pattern: Option<String>,
}

/// Entry point of `formation bench-peer`: runs until STOP; fails on a bad argument or a failed
/// case.
pub fn main(a: PeerArgs) -> Result<(), PeerError> {
    let transport =
        Transport::parse(&a.transport).ok_or_else(|| PeerError::Transport(a.transport.clone()))?;
    let wait = match a.wait.as_str() {
        "block" => Wait::Block,
        "busy" => Wait::Busy,
        "spin-block" => Wait::SpinBlock(Duration::from_micros(a.spin_us)),
        w => return Err(PeerError::Wait(w.to_string())),
    };
    if !(MIN_PAYLOAD..=MAX_PAYLOAD).contains(&a.payload) {
        return Err(PeerError::Payload(a.payload));
    }
    if !fipc::is_valid_prefix(&a.prefix) {
        return Err(PeerError::Prefix(a.prefix.clone()));
    }
    if let Some(cpu) = a.cpu {
        procs::set_affinity(&[cpu]).map_err(|source| PeerError::Pin { cpu, source })?;
    }
    if a.batch {
        formation_config::node::sched::batch_policy().map_err(PeerError::Batch)?;
    }
    run(&a, transport, wait).map_err(|source| PeerError::Case {
        transport: a.transport.clone(),
        index: a.index,
        case: a.case,
        source,
    })
}

fn run(a: &PeerArgs, transport: Transport, wait: Wait) -> Result<(), CaseError> {
    match transport {
        Transport::IoxEvent | Transport::IoxWaitSet | Transport::IoxPoll => {
            let node = fipc::node(&a.prefix, &format!("bench-agent-{}", a.index))
                .map_err(CaseError::below)?;
            let services = Services::open(&node, a.case).map_err(CaseError::below)?;
            let notify = transport != Transport::IoxPoll;
            let ports = Ports::agent(&services, a.payload, notify).map_err(CaseError::below)?;
            if transport == Transport::IoxWaitSet {
                let ws = iox::waitset().map_err(CaseError::below)?;
                let _guard = ws
                    .attach_notification(&ports.listener)
                    .map_err(|e| CaseError::below(format!("attach listener: {e:?}")))?;
                link::run_agent(
                    &mut IoxLink::new(&ports, Some(&ws), a.index, a.payload),
                    wait,
                )
            } else {
                link::run_agent(&mut IoxLink::new(&ports, None, a.index, a.payload), wait)
            }
        }
        Transport::Uds => {
            let me = sock::uds_addr(&a.prefix, a.case, Some(a.index as usize))
                .map_err(CaseError::below)?;
            let plant = sock::uds_addr(&a.prefix, a.case, None).map_err(CaseError::below)?;
            let s = sock::bind_uds(&me).ctx("uds bind")?;
            let mut l =
                SockLink::agent(s, plant, a.index, a.payload, wait).map_err(CaseError::below)?;
            link::run_agent(&mut l, wait)
        }
        Transport::Udp => {
            let port = a
                .plant_port
                .ok_or(CaseError::Missing("--plant-port is required for udp"))?;
            let plant = SocketAddr::from(([127, 0, 0, 1], port));
            let s = sock::bind_udp(0).ctx("udp bind")?;
            let mut l =
                SockLink::agent(s, plant, a.index, a.payload, wait).map_err(CaseError::below)?;
            link::run_agent(&mut l, wait)
        }
        #[cfg(feature = "multihost")]
        Transport::Zenoh => super::zenoh::peer(a),
        #[cfg(not(feature = "multihost"))]
        Transport::Zenoh => Err(CaseError::Missing(super::ZENOH_NEEDS_MULTIHOST)),
    }
}
