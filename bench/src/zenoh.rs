//! The bare Zenoh cases of `formation bench --transports zenoh` (cargo feature `multihost`): this
//! process is the launcher, one `formation bench-peer --transport zenoh` process the other host,
//! linked over loopback (TCP, TLS or QUIC, `--zenoh-link`) with the sessions, publishers and subscribers of a run across hosts
//! (`formation_net::bench`).
//!
//! * ping-pong: one message of the `--payload` sizes (default: the state down, the command up)
//!   each way per sample.
//! * fan-out: per step one frame launcher -> host with what a lockstep step of the paper's split
//!   placement sends there (the leader's reference, the remote agents' states and wake-ups, the
//!   share across the cut edge), answered by one frame host -> launcher (their commands, the share
//!   back, the plant's wake-up), in the bridges' frame format, each read back and checked as a
//!   bridge reads it.

use super::case::{measure_with, Ctx};
use super::link::{self, Link, Msg, Sizes, Wait, MIN_PAYLOAD};
use super::plan::Pattern;
use super::procs::Peers;
use super::row::Row;
use super::secure::Secured;
use super::PeerArgs;
use crate::error::{CaseError, ResultExt};
use formation_net::bench::{self as zb, Records, Side, StepPattern};
use formation_net::cluster::LAUNCHER;
use std::io;
use std::time::Duration;

/// Bytes before a frame's records: the bench header ([`Msg`], padded).
const HEADER: usize = MIN_PAYLOAD;

/// How often a peer repeats its hello until the launcher's first message arrives: a put before
/// the launcher's subscriber is known to the peer's session reaches no one.
const HELLO_AGAIN: Duration = Duration::from_millis(20);

/// How long the peer of a case gets to exit after the stop message.
const EXIT_GRACE: Duration = Duration::from_secs(5);

use super::versus::ZENOH as TRANSPORT;

/// The pattern named `s` (`ping-pong`, `fan-out`).
fn parse_pattern(s: &str) -> Option<Pattern> {
    [Pattern::PingPong, Pattern::FanOut]
        .into_iter()
        .find(|p| p.name() == s)
}

/// What one end sends after the header.
enum Body {
    /// Filler up to this many bytes in all.
    Filler(usize),
    /// These records, from this host.
    Frame(Records, &'static str),
}

/// One end of a bare Zenoh case as a bench [`Link`].
struct ZenohLink {
    link: zb::Link,
    body: Body,
    /// The records every frame received must hold (fan-out).
    expect: Option<Records>,
    from: u32,
    /// Peer side: repeat the hello until the first message comes.
    hello: bool,
}

fn other(e: impl Into<crate::error::Source>) -> io::Error {
    io::Error::other(e)
}

impl ZenohLink {
    fn read(&mut self, frame: Option<Vec<u8>>) -> io::Result<Option<Msg>> {
        let Some(f) = frame else { return Ok(None) };
        self.hello = false;
        let m = Msg::decode(&f).ok_or_else(|| other("a message shorter than its header"))?;
        if let (Some(expect), true) = (&self.expect, m.seq < link::HELLO) {
            expect
                .check(f.get(HEADER..).unwrap_or_default())
                .map_err(other)?;
        }
        Ok(Some(m))
    }
}

impl Link for ZenohLink {
    fn send(&mut self, seq: u64) -> io::Result<()> {
        let mut header = [0u8; HEADER];
        Msg {
            seq,
            from: self.from,
        }
        .encode(&mut header);
        let frame = match &self.body {
            Body::Filler(size) => {
                let mut v = vec![0u8; (*size).max(HEADER)];
                v[..HEADER].copy_from_slice(&header);
                v
            }
            Body::Frame(records, from) if seq < link::HELLO => records.frame(from, &header),
            Body::Frame(..) => header.to_vec(),
        };
        self.link.send(frame).map_err(other)
    }

    fn try_recv(&mut self) -> io::Result<Option<Msg>> {
        let f = self.link.try_recv().map_err(other)?;
        self.read(f)
    }

    fn block_recv(&mut self, timeout: Duration) -> io::Result<Option<Msg>> {
        if !self.hello {
            let f = self.link.recv_timeout(timeout).map_err(other)?;
            return self.read(f);
        }
        let f = self
            .link
            .recv_timeout(timeout.min(HELLO_AGAIN))
            .map_err(other)?;
        if f.is_none() {
            self.send(link::HELLO)?;
        }
        self.read(f)
    }
}

/// The key-safe name of case `idx`'s link.
fn tag(prefix: &str, idx: usize) -> String {
    format!("{prefix}c{idx}")
}

/// The step pattern of the paper's split placement.
fn split_step() -> Result<StepPattern, CaseError> {
    StepPattern::of(&zb::paper_split(), zb::SPLIT_HOST).map_err(CaseError::below)
}

/// Measures bare Zenoh case number `idx`; its row (`n`: 1 for ping-pong, the split run's N for
/// the fan-out; sizes: the frames' for the fan-out).
pub fn run(ctx: &Ctx, idx: usize, pattern: Pattern, sec: &Secured) -> Result<Row, CaseError> {
    let endpoint = sec.free_endpoint()?;
    let (body, expect, sizes, n) = match pattern {
        Pattern::PingPong => (Body::Filler(ctx.sizes.down), None, ctx.sizes, 1),
        Pattern::FanOut => {
            let step = split_step()?;
            let sizes = Sizes {
                down: HEADER + step.out.frame_bytes(LAUNCHER),
                up: HEADER + step.back.frame_bytes(zb::SPLIT_HOST),
            };
            let n = zb::paper_split().agent_hosts.len();
            (Body::Frame(step.out, LAUNCHER), Some(step.back), sizes, n)
        }
    };
    let args: Vec<String> = vec![
        "--transport".to_string(),
        TRANSPORT.into(),
        "--prefix".into(),
        ctx.prefix.into(),
        "--case".into(),
        idx.to_string(),
        "--index".into(),
        "0".into(),
        "--payload".into(),
        ctx.sizes.up.to_string(),
        "--wait".into(),
        "block".into(),
        "--endpoint".into(),
        endpoint.clone(),
        "--pattern".into(),
        pattern.name().into(),
    ]
    .into_iter()
    .chain(sec.args(zb::SPLIT_HOST))
    .collect();
    let peers = Peers::spawn(vec![args]).ctx("spawn the peer process")?;
    let mut l = ZenohLink {
        link: {
            let (auth, tls) = sec.of(LAUNCHER);
            zb::Link::open(Side::Launcher, &endpoint, &tag(ctx.prefix, idx), auth, tls)
                .map_err(CaseError::below)?
        },
        body,
        expect,
        from: u32::MAX,
        hello: false,
    };
    let hist = measure_with(ctx, (1, Wait::Block), &mut l, peers, EXIT_GRACE)?;
    Ok(Row::of(
        (TRANSPORT, pattern.name(), "block"),
        n,
        sizes,
        &hist,
    ))
}

/// The peer side (`formation bench-peer --transport zenoh`): the other host of the case.
pub fn peer(a: &PeerArgs) -> Result<(), CaseError> {
    let endpoint = a
        .endpoint
        .as_deref()
        .ok_or(CaseError::Missing("--endpoint is required for zenoh"))?;
    let pattern = a
        .pattern
        .as_deref()
        .and_then(parse_pattern)
        .ok_or(CaseError::Missing(
            "--pattern ping-pong or fan-out is required for zenoh",
        ))?;
    let (body, expect) = match pattern {
        Pattern::PingPong => (Body::Filler(a.payload), None),
        Pattern::FanOut => {
            let step = split_step()?;
            (Body::Frame(step.back, zb::SPLIT_HOST), Some(step.out))
        }
    };
    let mut l = ZenohLink {
        link: zb::Link::open(
            Side::Host,
            endpoint,
            &tag(&a.prefix, a.case),
            a.auth.clone(),
            a.tls.clone(),
        )
        .map_err(CaseError::below)?,
        body,
        expect,
        from: a.index,
        hello: true,
    };
    link::run_agent(&mut l, Wait::Block)
}
