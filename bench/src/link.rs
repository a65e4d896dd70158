//! The transport-independent part of a bench case: the message header, the waiting strategies and
//! the two loops (plant: publish a step, wait for every reply, record the time; agent: wait for a
//! step, reply).

use super::procs;
use crate::error::{CaseError, ResultExt};
use hdrhistogram::Histogram;
use std::io;
use std::time::{Duration, Instant};

/// Sequence number of the handshake message an agent sends once its ports exist.
pub const HELLO: u64 = u64::MAX - 1;
/// Sequence number that tells agents to exit.
pub const STOP: u64 = u64::MAX;
/// Smallest payload: the header (sequence number u64 + sender index u32) plus padding.
pub const MIN_PAYLOAD: usize = 16;
/// Largest payload (fits one UDP datagram and the default Unix datagram buffer).
pub const MAX_PAYLOAD: usize = 60_000;
/// Message sizes of a case, bytes: `down` plant -> agents, `up` agents -> plant (in ping-pong the
/// plant side sends `down` and the peer answers `up`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Sizes {
    /// Plant -> agent message, bytes.
    pub down: usize,
    /// Agent -> plant message, bytes.
    pub up: usize,
}

impl Sizes {
    /// The sizes of the lockstep's per-step messages: the state the plant sends agent i
    /// (`VehicleState`) and the command agent i answers with (`ControlCommand`), so a fan-out with
    /// these sizes is the bare transport cost of a lockstep step.
    pub fn lockstep_wire() -> Sizes {
        Sizes {
            down: std::mem::size_of::<formation_config::protocol::wire::VehicleState>(),
            up: std::mem::size_of::<formation_config::protocol::wire::ControlCommand>(),
        }
    }

    /// `128/440`, or one number when both directions have the same size.
    pub fn label(&self) -> String {
        if self.down == self.up {
            self.down.to_string()
        } else {
            format!("{}/{}", self.down, self.up)
        }
    }
}

/// Longest a plant waits for the replies of one step, or for the handshake.
pub const STEP_TIMEOUT: Duration = Duration::from_secs(5);
/// Longest an agent waits for the next step before it gives up.
pub const AGENT_IDLE_TIMEOUT: Duration = Duration::from_secs(30);
/// Longest single blocking call, so that aborts and dead peers are noticed.
pub const BLOCK_SLICE: Duration = Duration::from_millis(100);

/// Header of every bench message (the rest of the payload is filler).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Msg {
    /// Step number, or [`HELLO`] / [`STOP`].
    pub seq: u64,
    /// Sender index (agents 0..n; the plant uses u32::MAX).
    pub from: u32,
}

impl Msg {
    /// Writes the header into the first bytes of `buf` (at least [`MIN_PAYLOAD`] long).
    pub fn encode(self, buf: &mut [u8]) {
        buf[..8].copy_from_slice(&self.seq.to_le_bytes());
        buf[8..12].copy_from_slice(&self.from.to_le_bytes());
    }

    /// Reads the header from a received payload; `None` if it is too short.
    pub fn decode(buf: &[u8]) -> Option<Msg> {
        if buf.len() < 12 {
            return None;
        }
        let seq = u64::from_le_bytes(buf[..8].try_into().ok()?);
        let from = u32::from_le_bytes(buf[8..12].try_into().ok()?);
        Some(Msg { seq, from })
    }
}

/// How a process waits for the next message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Wait {
    /// Block in the kernel (listener, WaitSet, blocking `recv`).
    Block,
    /// Poll without blocking for up to the given time, then block.
    SpinBlock(Duration),
    /// Poll forever (never enters the kernel while waiting).
    Busy,
}

/// One endpoint of a bench case: the plant side sends steps to all agents, an agent side sends
/// replies to the plant.
pub trait Link {
    /// Sends message `seq` (with the full payload) to the other side(s).
    fn send(&mut self, seq: u64) -> io::Result<()>;
    /// Returns a message if one is already there, without blocking.
    fn try_recv(&mut self) -> io::Result<Option<Msg>>;
    /// Blocks for at most `timeout` until a message may be there; returns it if it read one (a
    /// spurious wake-up returns `None`).
    fn block_recv(&mut self, timeout: Duration) -> io::Result<Option<Msg>>;
}

/// Waits for the next message with strategy `wait` until `deadline`; `Ok(None)` on timeout or when
/// `give_up` says so (checked at least every [`BLOCK_SLICE`]).
pub fn recv(
    link: &mut dyn Link,
    wait: Wait,
    deadline: Instant,
    give_up: &dyn Fn() -> bool,
) -> io::Result<Option<Msg>> {
    let start = Instant::now();
    let mut polls: u32 = 0;
    loop {
        let spinning = match wait {
            Wait::Block => false,
            Wait::Busy => true,
            Wait::SpinBlock(budget) => polls < 64 || start.elapsed() < budget,
        };
        if spinning {
            if let Some(m) = link.try_recv()? {
                return Ok(Some(m));
            }
            polls = polls.wrapping_add(1);
            std::hint::spin_loop();
            if !polls.is_multiple_of(4096) {
                continue;
            }
        } else {
            let now = Instant::now();
            let slice = deadline.saturating_duration_since(now).min(BLOCK_SLICE);
            if let Some(m) = link.block_recv(slice)? {
                return Ok(Some(m));
            }
        }
        if Instant::now() >= deadline || give_up() {
            return Ok(None);
        }
    }
}

/// How long a plant measures and how much of it is warm-up.
#[derive(Debug, Clone, Copy)]
pub struct Budget {
    /// Measured time (after the warm-up).
    pub measure: Duration,
    /// Warm-up time whose samples are discarded.
    pub warmup: Duration,
    /// Samples discarded at least, whatever the warm-up time.
    pub min_warmup_samples: u64,
}

/// Plant side of a case: waits for the `n` agents' HELLO, then repeats "send step k, wait for the
/// n replies of step k" and records each step's time in ns; finally sends STOP.
pub fn run_plant(
    link: &mut dyn Link,
    n: usize,
    wait: Wait,
    budget: Budget,
    peers_alive: &dyn Fn() -> bool,
) -> Result<Histogram<u64>, CaseError> {
    let give_up = || procs::aborted() || !peers_alive();
    collect(
        link,
        HELLO,
        n,
        wait,
        Instant::now() + STEP_TIMEOUT * 4,
        &give_up,
    )
    .ctx("handshake")?;
    let mut hist = Histogram::<u64>::new_with_bounds(1, 60_000_000_000, 3).ctx("histogram")?;
    let start = Instant::now();
    let mut seq: u64 = 0;
    let mut measuring_since: Option<Instant> = None;
    loop {
        let t0 = Instant::now();
        link.send(seq).ctx(format!("send step {seq}"))?;
        collect(link, seq, n, wait, t0 + STEP_TIMEOUT, &give_up).ctx(format!("step {seq}"))?;
        let dt = t0.elapsed();
        let now = Instant::now();
        match measuring_since {
            Some(since) => {
                hist.record((dt.as_nanos() as u64).max(1))
                    .ctx("histogram")?;
                if now.duration_since(since) >= budget.measure {
                    break;
                }
            }
            None => {
                if now.duration_since(start) >= budget.warmup
                    && seq + 1 >= budget.min_warmup_samples
                {
                    measuring_since = Some(now);
                }
            }
        }
        seq += 1;
    }
    link.send(STOP).ctx("send stop")?;
    Ok(hist)
}

/// Receives until `n` messages with sequence number `seq` arrived (others are dropped).
fn collect(
    link: &mut dyn Link,
    seq: u64,
    n: usize,
    wait: Wait,
    deadline: Instant,
    give_up: &dyn Fn() -> bool,
) -> Result<(), CaseError> {
    let mut got = 0;
    while got < n {
        match recv(link, wait, deadline, give_up).ctx("receive")? {
            Some(m) if m.seq == seq => got += 1,
            Some(_) => {}
            None if procs::aborted() => return Err(CaseError::Interrupted),
            None => return Err(CaseError::Replies { got, n }),
        }
    }
    Ok(())
}

/// Agent side of a case: sends HELLO, then replies to every step until STOP, until the parent
/// process is gone, or until no step came for [`AGENT_IDLE_TIMEOUT`].
pub fn run_agent(link: &mut dyn Link, wait: Wait) -> Result<(), CaseError> {
    let parent = procs::parent_pid();
    let orphaned = move || procs::parent_pid() != parent;
    link.send(HELLO).ctx("send hello")?;
    loop {
        let deadline = Instant::now() + AGENT_IDLE_TIMEOUT;
        match recv(link, wait, deadline, &orphaned).ctx("receive")? {
            Some(m) if m.seq == STOP => return Ok(()),
            Some(m) if m.seq == HELLO => {}
            Some(m) => link.send(m.seq).ctx(format!("reply {}", m.seq))?,
            None if orphaned() => return Err(CaseError::Orphaned),
            None => return Err(CaseError::Idle),
        }
    }
}
