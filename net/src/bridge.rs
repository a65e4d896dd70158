//! The per-host bridge: forwards exactly the services of a run that have a sender on this host and
//! a receiver on another ([`crate::plan`]), as the same `#[repr(C)]` bytes with their wire type name,
//! and re-raises the wake-up events on the receiving host so the lockstep pacing is unchanged.
//!
//! Two sides, each with its own iceoryx2 node under the run's prefix:
//!
//! * **out**, a thread, sleeps on a WaitSet of the local listeners of the forwarded events (and
//!   wakes every [`IDLE_WAKE`] for samples that come without a wake-up, such as telemetry, and to
//!   look for a stop or a re-plan). After a wake-up it drains the listeners *first*, then every
//!   forwarded subscriber, again until a pass finds nothing (at most [`DRAIN_PASSES`]), and sends
//!   one frame per destination host with each pass's samples before its events: a sample
//!   published before a notification is therefore always delivered before that notification is
//!   re-raised.
//! * **in** has no thread of its own: this host's frames are handled in Zenoh's subscriber
//!   callback ([`frame_callback_subscriber`]), in Zenoh's receiving thread, which publishes each
//!   sample into the local service, then notifies each event, as the frame lists them. A frame
//!   wakes no thread of the bridge on its way to a role process: handing it to one would add
//!   that thread's wake-up to every crossing (~50 µs across the cores of a 2-vCPU VM,
//!   docs/multi-host.md). The callback reaches the ports through a mutex
//!   (the ports of iceoryx2's `ipc` flavour are `!Send`; see the `Send` of `Inbound` for why they
//!   may move between threads); frames of one sending host come over one link, in order. On a
//!   host other than the launcher the bridge first creates every service of the run (limits as
//!   the orchestrator's).
//!
//! Frame (little endian), records back to back: `u8 kind` (0 sample, 1 event, 2 sending host),
//! `u16` name length, name; for a sample also `u8` type-name length, type name, `u32` size, bytes.
//! Every frame starts with the sending host's record and ends with the proof of the run's secret
//! for its destination ([`crate::auth`]: the sender's sequence number, an HMAC-SHA256 tag). The
//! receiver takes nothing from a frame longer than [`MAX_FRAME`], without a valid proof, repeating
//! a sequence number of its sender, or whose sender is not a host of the run; then it checks each
//! sample's type name and size against its own service before it publishes. Refusals are counted
//! and logged at most once a second per sender and reason ([`LogLimit`]).
//!
//! Realtime stamps: the in side translates the send stamp (`sent_ns`, the sender's
//! `CLOCK_MONOTONIC`) of every state, share and command into its own host's clock with the clock
//! offsets of the handshake ([`crate::clock`]) before it publishes, and records the one-way delay
//! of the link (sending host -> this host): its clock at the publish minus the translated stamp.
//! Lockstep messages carry no stamp (0) and are forwarded byte for byte.
//! Publishers use `CongestionControl::Block` (nothing is dropped), `express` (no batching delay:
//! the frame is the batch) and `Locality::Remote`; nothing is re-forwarded (see `plan`).

use crate::auth::{Purpose, Replay, RunKey};
use crate::clock::{self, LinkDelays};
use crate::error::ZenohError;
use crate::logs::LogLimit;
use crate::plan::PlanError;
use crate::plan::{agent_index, Placement};
use crate::priority::{LinkPriority, Raised};
use crate::proto;
use formation_config::node::clock::now_ns;
use formation_config::node::ipc::{self, event_with_limits, pubsub_with_limits, service_name};
use formation_config::node::ports::{self, RunNode, Svc};
use formation_config::node::timing::TimingReport;
use formation_config::protocol::services::{
    self, wire_type_name, Event, Limits, Message, Named, Sizing, Slice, Topic, Visitor,
};
use formation_config::protocol::wire::{ControlCommand, NeighbourState, VehicleState};
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::prelude::*;
use std::any::{Any, TypeId};
use std::collections::{BTreeMap, HashMap};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{mpsc, Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;
use zenoh::qos::{CongestionControl, Priority};
use zenoh::sample::Locality;
use zenoh::Wait;

/// How long the out thread sleeps at most without a wake-up (samples that come without one).
pub const IDLE_WAKE: Duration = Duration::from_millis(50);

/// Drain passes (listeners, then subscribers) whose records go into one frame per destination at
/// most: after a wake-up the out thread drains again until a pass finds nothing, so the commands
/// of two agents of a host finishing a step moments apart cross in one frame; bounded so that a
/// steady stream still goes out.
pub const DRAIN_PASSES: usize = 4;

/// The longest frame a bridge takes: every sample of a step of the largest run with room to spare
/// (a frame holds what one drain pass found, [`DRAIN_PASSES`] at most); anything longer is
/// refused unread.
pub const MAX_FRAME: usize = 4 << 20;

/// What a bridge is for.
#[derive(Debug, Clone)]
pub struct BridgeConfig {
    /// Run id.
    pub run_id: String,
    /// iceoryx2 prefix of the run.
    pub prefix: String,
    /// This host.
    pub me: String,
    /// Where every process lives.
    pub placement: Placement,
    /// What the services are sized for.
    pub sizing: Sizing,
    /// Create every service first (every host but the launcher, where the orchestrator does).
    pub create: bool,
    /// Every host's clock minus the launcher's, ns (a host not listed: 0).
    pub clock_offsets_ns: BTreeMap<String, i64>,
    /// The run's keys: every frame carries proof of the run's secret ([`crate::auth`]).
    pub key: RunKey,
    /// `SCHED_FIFO` priority of the message path in a realtime run (the run's granted
    /// `--rt-priority`; 0: the normal policy, always in lockstep): the bridge's sending thread
    /// and this process's Zenoh link threads ([`crate::priority`]).
    pub rt_priority: u32,
}

/// Counters of a bridge.
#[derive(Debug, Default)]
pub struct Stats {
    /// Frames sent.
    pub frames_out: AtomicU64,
    /// Samples sent.
    pub samples_out: AtomicU64,
    /// Events sent.
    pub events_out: AtomicU64,
    /// Frames received.
    pub frames_in: AtomicU64,
    /// Records refused (unknown service, type or size mismatch).
    pub refused: AtomicU64,
    /// Frames refused because their sender has left the run (a host declared lost: it is
    /// fenced, whatever keys it still holds; docs/multi-host.md "Fencing a lost host").
    pub fenced: AtomicU64,
}

/// A running bridge; stopped on drop (the subscriber undeclared, the receiving side's ports
/// dropped, the sending thread joined).
pub struct Bridge {
    stop: Arc<AtomicBool>,
    threads: Vec<JoinHandle<()>>,
    /// Its counters.
    pub stats: Arc<Stats>,
    /// Services it forwards out and receives in.
    pub forwarded: (usize, usize),
    /// Re-plans for the sending thread.
    replan: mpsc::Sender<Replan>,
    links: Arc<Mutex<BTreeMap<String, LinkDelays>>>,
    /// The receiving side, used by the subscriber's callback; `None` once stopped.
    inbound: Arc<Mutex<Option<Inbound>>>,
    /// This host's frames, handled in Zenoh's receiving thread; undeclared on drop.
    subscriber: Option<zenoh::pubsub::Subscriber<()>>,
    /// What the realtime message path's scheduling came to (priority 0 and no thread in lockstep).
    pub scheduling: Raised,
    /// Held while the bridge runs: the link threads' realtime priority (dropped after the
    /// sending thread is joined).
    _link_priority: Option<LinkPriority>,
}

impl Bridge {
    /// The one-way delays of the links into this host so far, as a timing report: histogram
    /// `link/<from>-><to>` (ns) and counter `negative/<from>-><to>` per link.
    pub fn link_report(&self) -> TimingReport {
        let mut r = TimingReport::default();
        for (name, l) in lock(&self.links).iter() {
            r.histograms
                .insert(format!("link/{name}"), l.delays.clone());
            r.counters.insert(format!("negative/{name}"), l.negative);
        }
        r
    }
}

/// A new placement for a thread, and where it answers (services it forwards, or why not).
type Replan = (Placement, mpsc::Sender<Result<usize, BridgeError>>);

/// How long a re-plan of the sending thread may take (it looks between two cycles, at least every
/// [`IDLE_WAKE`]).
pub const REPLAN_TIMEOUT: Duration = Duration::from_secs(5);

impl Drop for Bridge {
    fn drop(&mut self) {
        // No frame after this; a callback still running holds the lock, so taking the receiving
        // side waits for it, and its ports are dropped here, not later in a Zenoh thread.
        drop(self.subscriber.take());
        drop(lock(&self.inbound).take());
        self.stop.store(true, Ordering::SeqCst);
        for t in self.threads.drain(..) {
            let _ = t.join();
        }
    }
}

type Drain = Box<dyn FnMut(&mut dyn FnMut(&[u8])) -> Result<usize, BridgeError>>;
/// Publishes a sample's bytes, its send stamp (if it has one) shifted by the given ns; returns
/// the shifted stamp (0: none).
type Inject = Box<dyn FnMut(&[u8], i64) -> Result<u64, BridgeError>>;

/// Offset of the send stamp (`sent_ns`) in the stamped wire types, `None` for the others.
fn stamp_offset<T: Message>() -> Option<usize> {
    let t = TypeId::of::<T>();
    if t == TypeId::of::<VehicleState>() {
        Some(std::mem::offset_of!(VehicleState, sent_ns))
    } else if t == TypeId::of::<NeighbourState>() {
        Some(std::mem::offset_of!(NeighbourState, sent_ns))
    } else if t == TypeId::of::<ControlCommand>() {
        Some(std::mem::offset_of!(ControlCommand, sent_ns))
    } else {
        None
    }
}

/// One forwarded publish-subscribe service on the sending side.
struct OutTopic {
    name: String,
    type_name: &'static str,
    dests: Vec<usize>,
    drain: Drain,
}

/// One forwarded event on the sending side.
struct OutEvent {
    name: String,
    dests: Vec<usize>,
    listener: Listener<Svc>,
}

/// One service on the receiving side.
enum InPort {
    Topic {
        type_name: &'static str,
        size: usize,
        inject: Inject,
    },
    /// Boxed: a notifier is far larger than the topic variant, and ports live in a map.
    Event(Box<Notifier<Svc>>),
}

/// Walks the service table: creates services (optionally), and opens the bridge's ports.
struct Opener<'a> {
    node: &'a RunNode,
    cfg: &'a BridgeConfig,
    hosts: &'a [String],
    /// Open the out side (true) or the in side (false).
    out: bool,
    keep: Vec<Box<dyn Any>>,
    topics: Vec<OutTopic>,
    events: Vec<OutEvent>,
    ins: HashMap<String, InPort>,
    /// A re-plan: the ports of the previous plan, kept (with new destinations) where the service
    /// is still forwarded, so no sample queued in them is lost; the rest are dropped with them.
    old: Ports,
}

/// The ports of one plan, by service name.
#[derive(Default)]
struct Ports {
    topics: HashMap<String, OutTopic>,
    events: HashMap<String, OutEvent>,
    ins: HashMap<String, InPort>,
}

fn err<'a, E: std::fmt::Debug>(
    what: &'static str,
    name: &'a str,
) -> impl FnOnce(E) -> BridgeError + 'a {
    move |e| BridgeError::ipc(what, name, e)
}

impl<'a> Opener<'a> {
    /// Opens (`out`: the sending side; else the receiving side) every service of the run's table
    /// that this host forwards.
    fn visit_all(
        node: &'a RunNode,
        cfg: &'a BridgeConfig,
        hosts: &'a [String],
        out: bool,
        old: Ports,
    ) -> Result<Opener<'a>, BridgeError> {
        let mut o = Opener {
            node,
            cfg,
            hosts,
            out,
            keep: Vec::new(),
            topics: Vec::new(),
            events: Vec::new(),
            ins: HashMap::new(),
            old,
        };
        services::visit(&cfg.sizing, &mut o)?;
        Ok(o)
    }

    fn route(
        &self,
        name: &str,
        pattern: &str,
        senders: &[services::Party],
        receivers: &[services::Party],
        scope: services::Scope,
    ) -> Result<(Vec<usize>, bool), BridgeError> {
        let r = self.cfg.placement.route(
            &self.cfg.me,
            name,
            senders,
            receivers,
            scope,
            agent_index(pattern, name),
        )?;
        let dests = r
            .out_to
            .iter()
            .map(|h| {
                self.hosts
                    .iter()
                    .position(|x| x == h)
                    .expect("a host of the placement")
            })
            .collect();
        Ok((dests, r.inbound))
    }
}

impl Visitor for Opener<'_> {
    type Error = BridgeError;

    fn topic<T: Message>(&mut self, s: Named<Topic<T>>, l: Limits) -> Result<(), BridgeError> {
        if self.cfg.create && !self.out {
            let sn = service_name(&s.name).map_err(err("name", &s.name))?;
            let f = pubsub_with_limits(self.node.service_builder(&sn).publish_subscribe::<T>(), &l)
                .history_size(s.spec.history)
                .create()
                .map_err(err("cannot create", &s.name))?;
            self.keep.push(Box::new(f));
        }
        let (dests, inbound) = self.route(
            &s.name,
            s.spec.pattern,
            s.spec.publishers,
            s.spec.subscribers,
            s.spec.scope,
        )?;
        let type_name = wire_type_name::<T>();
        if self.out && !dests.is_empty() {
            if let Some(mut t) = self.old.topics.remove(&s.name) {
                t.dests = dests;
                self.topics.push(t);
                return Ok(());
            }
            let sub = ports::subscriber(self.node, &s).map_err(BridgeError::from)?;
            let drain: Drain = Box::new(move |f| {
                let mut n = 0;
                while let Some(sample) = sub.receive()? {
                    f(wire_bytes(sample.payload()));
                    n += 1;
                }
                Ok(n)
            });
            self.topics.push(OutTopic {
                name: s.name.clone(),
                type_name,
                dests,
                drain,
            });
        } else if !self.out && inbound {
            if let Some(p) = self.old.ins.remove(&s.name) {
                self.ins.insert(s.name.clone(), p);
                return Ok(());
            }
            let publisher = ports::publisher(self.node, &s).map_err(BridgeError::from)?;
            let name = s.name.clone();
            let stamp = stamp_offset::<T>();
            let inject: Inject = Box::new(move |bytes, shift| {
                let mut sample = publisher
                    .loan_uninit()
                    .map_err(|e| BridgeError::ipc("cannot loan on", &name, e))?;
                // SAFETY: the size was checked against T's; the bytes are a T's bytes from the
                // sending host (same build and wire layout, checked at the handshake).
                let mut sample = unsafe {
                    std::ptr::copy_nonoverlapping(
                        bytes.as_ptr(),
                        sample.payload_mut().as_mut_ptr() as *mut u8,
                        size_of::<T>(),
                    );
                    sample.assume_init()
                };
                let mut sent = 0;
                if let Some(at) = stamp {
                    // SAFETY: `at` is the offset of a u64 field inside T (offset_of!), within
                    // the sample's payload; unaligned access, whatever the payload's alignment.
                    unsafe {
                        let p = (sample.payload_mut() as *mut T as *mut u8).add(at) as *mut u64;
                        sent = clock::translate(p.read_unaligned(), shift);
                        p.write_unaligned(sent);
                    }
                }
                sample
                    .send()
                    .map(|_| sent)
                    .map_err(|e| BridgeError::ipc("cannot publish on", &name, e))
            });
            self.ins.insert(
                s.name.clone(),
                InPort::Topic {
                    type_name,
                    size: size_of::<T>(),
                    inject,
                },
            );
        }
        Ok(())
    }

    fn slices<T: Message>(
        &mut self,
        s: Named<Topic<T, Slice>>,
        l: Limits,
    ) -> Result<(), BridgeError> {
        if self.cfg.create && !self.out {
            let sn = service_name(&s.name).map_err(err("name", &s.name))?;
            let f = pubsub_with_limits(
                self.node.service_builder(&sn).publish_subscribe::<[T]>(),
                &l,
            )
            .history_size(s.spec.history)
            .create()
            .map_err(err("cannot create", &s.name))?;
            self.keep.push(Box::new(f));
        }
        let (dests, inbound) = self.route(
            &s.name,
            s.spec.pattern,
            s.spec.publishers,
            s.spec.subscribers,
            s.spec.scope,
        )?;
        if !dests.is_empty() || inbound {
            return Err(BridgeError::SliceCrosses(s.name.clone()));
        }
        Ok(())
    }

    fn event(&mut self, s: Named<Event>, l: Limits) -> Result<(), BridgeError> {
        let sn = service_name(&s.name).map_err(err("name", &s.name))?;
        if self.cfg.create && !self.out {
            let f: iceoryx2::service::port_factory::event::PortFactory<Svc> =
                event_with_limits(self.node.service_builder(&sn).event(), &l)
                    .create()
                    .map_err(err("cannot create", &s.name))?;
            self.keep.push(Box::new(f));
        }
        let (dests, inbound) = self.route(
            &s.name,
            s.spec.pattern,
            s.spec.notifiers,
            s.spec.listeners,
            s.spec.scope,
        )?;
        if self.out && !dests.is_empty() {
            if let Some(mut e) = self.old.events.remove(&s.name) {
                e.dests = dests;
                self.events.push(e);
                return Ok(());
            }
            let listener = self
                .node
                .service_builder(&sn)
                .event()
                .open()
                .map_err(err("cannot open", &s.name))?
                .listener_builder()
                .create()
                .map_err(err("cannot listen on", &s.name))?;
            self.events.push(OutEvent {
                name: s.name.clone(),
                dests,
                listener,
            });
        } else if !self.out && inbound {
            if let Some(p) = self.old.ins.remove(&s.name) {
                self.ins.insert(s.name.clone(), p);
                return Ok(());
            }
            let n = ports::notifier(self.node, &s).map_err(BridgeError::from)?;
            self.ins.insert(s.name.clone(), InPort::Event(Box::new(n)));
        }
        Ok(())
    }
}

/// Frames a [`frame_subscriber`] holds before Zenoh's receiving thread blocks (a full FIFO
/// blocks it).
pub const FRAME_QUEUE: usize = 4096;

/// The publisher of a stream of frames to `key`: `CongestionControl::Block` (nothing is dropped),
/// `Priority::RealTime`, `express` (no batching delay: the frame is the batch), remote subscribers
/// only. The bridges and the bare Zenoh cases of `formation bench` ([`crate::bench`]) send with it.
pub fn frame_publisher(
    session: &zenoh::Session,
    key: String,
) -> Result<zenoh::pubsub::Publisher<'static>, ZenohError> {
    session
        .declare_publisher(key)
        .congestion_control(CongestionControl::Block)
        .priority(Priority::RealTime)
        .express(true)
        .allowed_destination(Locality::Remote)
        .wait()
        .map_err(|e| ZenohError::new("bridge: cannot declare a publisher", e))
}

/// Declares a subscriber of the frames sent to `key` with [`frame_publisher`], remote publishers
/// only, with `handler`.
fn declare_frame_subscriber<H>(
    session: &zenoh::Session,
    key: String,
    handler: H,
) -> Result<zenoh::pubsub::Subscriber<H::Handler>, ZenohError>
where
    H: zenoh::handlers::IntoHandler<zenoh::sample::Sample> + Send,
    H::Handler: Send,
{
    session
        .declare_subscriber(key)
        .with(handler)
        .allowed_origin(Locality::Remote)
        .wait()
        .map_err(|e| ZenohError::new("bridge: cannot subscribe", e))
}

/// A subscriber of frames sent to `key` with [`frame_publisher`] whose frames a thread of its
/// own takes: one FIFO of [`FRAME_QUEUE`] frames, so they stay in order. The bare Zenoh cases
/// of `formation bench` receive with it: there the thread that takes a frame stands for the role
/// processes a bridge wakes.
pub fn frame_subscriber(
    session: &zenoh::Session,
    key: String,
) -> Result<
    zenoh::pubsub::Subscriber<zenoh::handlers::FifoChannelHandler<zenoh::sample::Sample>>,
    ZenohError,
> {
    declare_frame_subscriber(session, key, zenoh::handlers::FifoChannel::new(FRAME_QUEUE))
}

/// A subscriber of frames sent to `key` with [`frame_publisher`] that handles each frame in
/// Zenoh's receiving thread (`on_frame`), as they come, in order: what a bridge receives with.
pub fn frame_callback_subscriber(
    session: &zenoh::Session,
    key: String,
    on_frame: impl Fn(zenoh::sample::Sample) + Send + Sync + 'static,
) -> Result<zenoh::pubsub::Subscriber<()>, ZenohError> {
    declare_frame_subscriber(session, key, zenoh::handlers::Callback::from(on_frame))
}

/// The bytes of a `#[repr(C)]` wire value as they lie in memory: what crosses between hosts and
/// what the export puts on Zenoh.
pub(crate) fn wire_bytes<T: Message>(v: &T) -> &[u8] {
    wire_slice_bytes(std::slice::from_ref(v))
}

/// The bytes of consecutive `#[repr(C)]` wire values (a slice service's payload).
pub(crate) fn wire_slice_bytes<T: Message>(v: &[T]) -> &[u8] {
    // SAFETY: T is a `#[repr(C)]`, `Copy` wire type without uninitialised padding (the wire
    // contract: every padding is an explicit `_pad` field), so all its bytes are initialised.
    unsafe { std::slice::from_raw_parts(v.as_ptr() as *const u8, size_of_val(v)) }
}

const KIND_SAMPLE: u8 = 0;
const KIND_EVENT: u8 = 1;
const KIND_FROM: u8 = 2;

pub(crate) fn put_from(frame: &mut Vec<u8>, host: &str) {
    frame.push(KIND_FROM);
    frame.extend_from_slice(&(host.len() as u16).to_le_bytes());
    frame.extend_from_slice(host.as_bytes());
}

pub(crate) fn put_sample(frame: &mut Vec<u8>, name: &str, type_name: &str, bytes: &[u8]) {
    frame.push(KIND_SAMPLE);
    frame.extend_from_slice(&(name.len() as u16).to_le_bytes());
    frame.extend_from_slice(name.as_bytes());
    frame.push(type_name.len() as u8);
    frame.extend_from_slice(type_name.as_bytes());
    frame.extend_from_slice(&(bytes.len() as u32).to_le_bytes());
    frame.extend_from_slice(bytes);
}

pub(crate) fn put_event(frame: &mut Vec<u8>, name: &str) {
    frame.push(KIND_EVENT);
    frame.extend_from_slice(&(name.len() as u16).to_le_bytes());
    frame.extend_from_slice(name.as_bytes());
}

/// The frame of `records`, in their order, without the proof a bridge appends (the inverse of
/// [`parse_frame`]).
pub fn encode_frame(records: &[Record<'_>]) -> Vec<u8> {
    let mut f = Vec::new();
    for r in records {
        match r {
            Record::Sample {
                name,
                type_name,
                bytes,
            } => put_sample(&mut f, name, type_name, bytes),
            Record::Event(name) => put_event(&mut f, name),
            Record::From(host) => put_from(&mut f, host),
        }
    }
    f
}

/// One record of a frame.
#[derive(Debug, PartialEq, Eq)]
pub enum Record<'a> {
    /// A sample of `name` with its wire type name and bytes.
    Sample {
        /// Service name.
        name: &'a str,
        /// Wire type name.
        type_name: &'a str,
        /// The `#[repr(C)]` bytes.
        bytes: &'a [u8],
    },
    /// A wake-up of `name`.
    Event(&'a str),
    /// The host that sent the frame (its first record).
    From(&'a str),
}

/// Parses a frame into its records; `Err` names what is malformed.
pub fn parse_frame(mut f: &[u8]) -> Result<Vec<Record<'_>>, RecordError> {
    fn take<'a>(f: &mut &'a [u8], n: usize) -> Result<&'a [u8], RecordError> {
        if f.len() < n {
            return Err(RecordError::Truncated {
                left: f.len(),
                needed: n,
            });
        }
        let (a, b) = f.split_at(n);
        *f = b;
        Ok(a)
    }
    fn text<'a>(f: &mut &'a [u8], n: usize) -> Result<&'a str, RecordError> {
        std::str::from_utf8(take(f, n)?).map_err(|_| RecordError::NotUtf8)
    }
    let mut v = Vec::new();
    while !f.is_empty() {
        let kind = take(&mut f, 1)?[0];
        let len = u16::from_le_bytes(take(&mut f, 2)?.try_into().unwrap()) as usize;
        let name = text(&mut f, len)?;
        match kind {
            KIND_SAMPLE => {
                let tl = take(&mut f, 1)?[0] as usize;
                let type_name = text(&mut f, tl)?;
                let size = u32::from_le_bytes(take(&mut f, 4)?.try_into().unwrap()) as usize;
                let bytes = take(&mut f, size)?;
                v.push(Record::Sample {
                    name,
                    type_name,
                    bytes,
                });
            }
            KIND_EVENT => v.push(Record::Event(name)),
            KIND_FROM => v.push(Record::From(name)),
            k => return Err(RecordError::Kind(k)),
        }
    }
    Ok(v)
}

impl Bridge {
    /// Starts the bridge; returns once every service exists on this host (`cfg.create`) and every
    /// port of the bridge is open, so role processes may start.
    pub fn start(session: zenoh::Session, cfg: BridgeConfig) -> Result<Bridge, BridgeError> {
        let stop = Arc::new(AtomicBool::new(false));
        let stats = Arc::new(Stats::default());
        let links = Arc::new(Mutex::new(BTreeMap::new()));
        let hosts = cfg.placement.hosts();
        let inbound = Inbound::open(cfg.clone())?;
        let forwarded_in = inbound.ins.len();
        let inbound = Arc::new(Mutex::new(Some(inbound)));
        let subscriber = {
            let (inbound, stats, links) = (inbound.clone(), stats.clone(), links.clone());
            frame_callback_subscriber(
                &session,
                proto::run_to(&cfg.run_id, &cfg.me),
                move |sample| {
                    if let Some(i) = lock(&inbound).as_mut() {
                        i.receive(&sample.payload().to_bytes(), &stats, &links);
                    }
                },
            )?
        };
        let (ready_tx, ready_rx) = mpsc::channel::<Result<usize, BridgeError>>();
        let (out_tx, out_rx) = mpsc::channel::<Replan>();
        let (link_priority, scheduling) = LinkPriority::raise(cfg.rt_priority);
        let mut bridge = Bridge {
            stop: stop.clone(),
            threads: Vec::new(),
            stats: stats.clone(),
            forwarded: (0, forwarded_in),
            replan: out_tx,
            links,
            inbound,
            subscriber: Some(subscriber),
            scheduling,
            _link_priority: link_priority,
        };
        bridge.threads.push(
            std::thread::Builder::new()
                .name(crate::priority::BRIDGE_THREAD.into())
                .spawn(move || run_out(session, cfg, hosts, stop, stats, ready_tx, out_rx))
                .map_err(BridgeError::Thread)?,
        );
        let outbound = ready_rx.recv().map_err(|_| BridgeError::SendingEnded)??;
        bridge.forwarded.0 = outbound;
        Ok(bridge)
    }
}

impl Bridge {
    /// Re-plans the running bridge for a new placement (a lost host's agents moved to another
    /// host): the receiving side first, so a service this host now receives has its port before
    /// any host sends it (between two frames), then the sending side, between two of its cycles
    /// (every sample drained before went out under the old plan, every one after under the new).
    /// Ports of services still forwarded are kept, with their new destinations, so nothing queued
    /// in them is lost; ports of services no longer forwarded are dropped, so a sample still
    /// coming from a lost host is refused. Returns the services forwarded (out, in).
    pub fn replan(&mut self, placement: &Placement) -> Result<(usize, usize), BridgeError> {
        let inbound = lock(&self.inbound)
            .as_mut()
            .ok_or(BridgeError::Stopped)?
            .replan(placement)?;
        let (ack, answer) = mpsc::channel();
        self.replan
            .send((placement.clone(), ack))
            .map_err(|_| BridgeError::SendingGone)?;
        let out = answer
            .recv_timeout(REPLAN_TIMEOUT)
            .map_err(|_| BridgeError::ReplanTimeout(REPLAN_TIMEOUT))??;
        self.forwarded = (out, inbound);
        Ok(self.forwarded)
    }
}

/// The receiving side of a bridge: its iceoryx2 node, the services it created (on a host other
/// than the launcher) and its ports into the forwarded services, used from Zenoh's subscriber
/// callback (Zenoh's receiving thread) under [`Bridge`]'s mutex.
struct Inbound {
    cfg: BridgeConfig,
    node: RunNode,
    /// The services this host created: they live as long as the bridge.
    _keep: Vec<Box<dyn Any>>,
    ins: HashMap<String, InPort>,
    /// Per sending host: the shift of its stamps onto this host's clock, and the link's name.
    from: HashMap<String, (i64, String)>,
    /// Scratch: (translated send stamp, publish time) of the samples of one frame.
    stamps: Vec<(u64, u64)>,
    /// Sequence numbers seen per sending host.
    replay: HashMap<String, Replay>,
    /// Hosts that have left the run (lost): their frames are refused and counted as fenced.
    gone: Vec<String>,
    /// Refusals logged at most once a second per sender and reason.
    log: LogLimit,
}

// SAFETY: `Inbound` owns an iceoryx2 node of the inter-process service flavour (`ipc::Service`)
// and every port and port factory made from it. That flavour's ports share their state through
// `Rc` (iceoryx2's `SingleThreaded` policy), which is what makes them `!Send`; `ipc_threadsafe`
// differs from `ipc` only in swapping that `Rc` for an `Arc` behind a mutex, so nothing else in
// the ports is bound to a thread. Every `Rc` clone of these ports (port factories, ports, loaned
// samples) lives inside this value and never leaves it: samples are loaned and sent within one
// call, no port or factory is handed out. The value is only reached through the bridge's
// `Mutex<Option<Inbound>>`, so no two threads ever touch those reference counts at once, and the
// mutex orders every access after the previous one. Moving it to another thread is then sound.
unsafe impl Send for Inbound {}

impl Inbound {
    /// Creates the services (`cfg.create`) and opens the ports of the services this host
    /// receives.
    fn open(cfg: BridgeConfig) -> Result<Inbound, BridgeError> {
        let hosts = cfg.placement.hosts();
        let offset = |h: &str| cfg.clock_offsets_ns.get(h).copied().unwrap_or(0);
        let me_offset = offset(&cfg.me);
        let from = hosts
            .iter()
            .filter(|h| **h != cfg.me)
            .map(|h| {
                (
                    h.clone(),
                    (
                        clock::shift_ns(offset(h), me_offset),
                        clock::link_name(h, &cfg.me),
                    ),
                )
            })
            .collect();
        let node = ipc::node(&cfg.prefix, "fm-bridge-in").map_err(BridgeError::from)?;
        let o = Opener::visit_all(&node, &cfg, &hosts, false, Ports::default())?;
        let (keep, ins) = (o.keep, o.ins);
        Ok(Inbound {
            cfg,
            node,
            _keep: keep,
            ins,
            from,
            stamps: Vec::with_capacity(64),
            replay: HashMap::new(),
            gone: Vec::new(),
            log: LogLimit::default(),
        })
    }

    /// Re-plans the receiving side (see [`Bridge::replan`]); the services it receives.
    fn replan(&mut self, placement: &Placement) -> Result<usize, BridgeError> {
        self.cfg.placement = placement.clone();
        self.cfg.create = false;
        let hosts = self.cfg.placement.hosts();
        // A host that has left the placement is lost for good: nothing it sends is taken.
        let left: Vec<String> = self
            .from
            .keys()
            .filter(|h| !hosts.contains(h))
            .cloned()
            .collect();
        for h in left {
            self.from.remove(&h);
            self.gone.push(h);
        }
        let old = Ports {
            ins: std::mem::take(&mut self.ins),
            ..Ports::default()
        };
        let o = Opener::visit_all(&self.node, &self.cfg, &hosts, false, old)?;
        self.ins = o.ins;
        Ok(self.ins.len())
    }

    /// Publishes a frame's samples into the local services and re-raises its events, in the
    /// frame's order; records the one-way delay of every stamped sample.
    fn receive(
        &mut self,
        frame: &[u8],
        stats: &Stats,
        links: &Mutex<BTreeMap<String, LinkDelays>>,
    ) {
        stats.frames_in.fetch_add(1, Ordering::Relaxed);
        let Some((records, sender)) = self.admit(frame, stats) else {
            stats.refused.fetch_add(1, Ordering::Relaxed);
            return;
        };
        let source = self.from.get(sender);
        self.stamps.clear();
        for r in records.into_iter().skip(1) {
            let key: &str = match &r {
                Record::Sample { name, .. } => name,
                Record::Event(name) => name,
                Record::From(_) => {
                    self.log.warn(sender, "second sender", || {
                        format!(
                            "bridge: a frame from {sender} names a second sender; the rest refused"
                        )
                    });
                    stats.refused.fetch_add(1, Ordering::Relaxed);
                    break;
                }
            };
            match (r, self.ins.get_mut(key)) {
                (
                    Record::Sample {
                        name,
                        type_name,
                        bytes,
                    },
                    Some(InPort::Topic {
                        type_name: t,
                        size,
                        inject,
                    }),
                ) => {
                    if type_name != *t || bytes.len() != *size {
                        self.log.warn(sender, "type or size", || {
                            format!(
                                "bridge: {name}: refused a {type_name} of {} bytes from {sender} (expected {t} of {size})",
                                bytes.len()
                            )
                        });
                        stats.refused.fetch_add(1, Ordering::Relaxed);
                    } else {
                        match inject(bytes, source.map_or(0, |s| s.0)) {
                            Ok(0) => {}
                            Ok(sent) => self.stamps.push((sent, now_ns())),
                            Err(e) => tracing::warn!("{e}"),
                        }
                    }
                }
                (Record::Event(_), Some(InPort::Event(n))) => ports::poke(n),
                (r, _) => {
                    self.log.warn(sender, "no such service", || {
                        format!("bridge: no such forwarded service here: {r:?} from {sender}")
                    });
                    stats.refused.fetch_add(1, Ordering::Relaxed);
                }
            }
        }
        if let (Some((_, link)), false) = (source, self.stamps.is_empty()) {
            let mut l = lock(links);
            let d = l.entry(link.clone()).or_default();
            for &(sent, now) in &self.stamps {
                d.record(sent, now);
            }
        }
    }
}

impl Inbound {
    /// The records of a frame and its sending host, if the frame may be taken (see the module
    /// documentation): not too long, with proof of the run's secret for this host, a sequence
    /// number its sender has not used, and a sender that is a host of the run named first.
    fn admit<'f>(&mut self, frame: &'f [u8], stats: &Stats) -> Option<(Vec<Record<'f>>, &'f str)> {
        let me = self.cfg.me.clone();
        if frame.len() > MAX_FRAME {
            self.log.warn("unknown", "oversized", || {
                format!(
                    "bridge: a frame of {} bytes refused unread (at most {MAX_FRAME})",
                    frame.len()
                )
            });
            return None;
        }
        let (body, seq) = match self.cfg.key.open(Purpose::Frame, &me, frame) {
            Ok(v) => v,
            Err(e) => {
                self.log.warn("unknown", "no proof", || {
                    format!("bridge: a frame refused: {e}")
                });
                return None;
            }
        };
        let records = match parse_frame(body) {
            Ok(r) => r,
            Err(e) => {
                self.log.warn("unknown", "malformed", || {
                    format!("bridge: frame refused: {e}")
                });
                return None;
            }
        };
        let sender = match records.first() {
            Some(Record::From(h)) if self.from.contains_key(*h) => *h,
            Some(Record::From(h)) if self.gone.iter().any(|g| g == h) => {
                let h = h.to_string();
                stats.fenced.fetch_add(1, Ordering::Relaxed);
                self.log.warn(&h, "fenced", || {
                    format!("bridge: a frame from {h}, a host lost to the run, refused (fenced)")
                });
                return None;
            }
            Some(Record::From(h)) => {
                let h = h.to_string();
                self.log.warn("unknown", "not a host", || {
                    format!("bridge: a frame from {h}, not a host of the run, refused")
                });
                return None;
            }
            _ => {
                self.log.warn("unknown", "no sender", || {
                    "bridge: a frame that does not name its sender first refused".to_string()
                });
                return None;
            }
        };
        if let Err(e) = self
            .replay
            .entry(sender.to_string())
            .or_default()
            .accept(seq)
        {
            self.log.warn(sender, "replayed", || {
                format!("bridge: a frame from {sender} refused: {e}")
            });
            return None;
        }
        Some((records, sender))
    }
}

/// Why a bridge cannot start, re-plan or forward: the service and what failed.
#[derive(Debug, thiserror::Error)]
pub enum BridgeError {
    /// An iceoryx2 operation on a service failed (iceoryx2's error, in its debug form).
    #[error("bridge: {what} {name}: {why}")]
    Ipc {
        /// The operation (`cannot create`, `cannot loan on`, ...).
        what: &'static str,
        /// The service.
        name: String,
        /// iceoryx2's error.
        why: String,
    },
    /// The bridge's iceoryx2 node cannot be made.
    #[error(transparent)]
    Node(#[from] ipc::IpcError),
    /// A port of a forwarded service cannot be opened or read.
    #[error(transparent)]
    Port(#[from] formation_config::node::error::PortError),
    /// A service cannot be routed for the placement.
    #[error(transparent)]
    Route(#[from] PlanError),
    /// A slice service whose publisher and subscriber are on different hosts.
    #[error(
        "bridge: {0} (slices) cannot cross hosts: its publisher and subscriber must share a host"
    )]
    SliceCrosses(String),
    /// A frame publisher or subscriber cannot be declared.
    #[error(transparent)]
    Zenoh(#[from] ZenohError),
    /// The sending thread's WaitSet cannot be made (iceoryx2's error, in its debug form).
    #[error("bridge: cannot create a WaitSet: {0}")]
    WaitSet(String),
    /// The sending thread cannot be started.
    #[error("bridge: cannot start a thread: {0}")]
    Thread(std::io::Error),
    /// The sending thread ended before its ports were open.
    #[error("bridge: the sending thread ended")]
    SendingEnded,
    /// A re-plan of a stopped bridge.
    #[error("bridge: stopped")]
    Stopped,
    /// A re-plan after the sending thread ended.
    #[error("bridge: the sending thread has ended")]
    SendingGone,
    /// The sending thread did not take the re-plan in time.
    #[error("bridge: no re-plan within {0:?}")]
    ReplanTimeout(Duration),
}

impl BridgeError {
    /// iceoryx2's `e` on `what` of service `name`.
    fn ipc(what: &'static str, name: &str, e: impl std::fmt::Debug) -> BridgeError {
        BridgeError::Ipc {
            what,
            name: name.to_string(),
            why: format!("{e:?}"),
        }
    }
}

crate::error::into_string!(BridgeError);

/// Why a frame does not parse ([`parse_frame`]).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum RecordError {
    /// Fewer bytes than the record needs.
    #[error("truncated frame: {left} bytes left, {needed} needed")]
    Truncated {
        /// Bytes left.
        left: usize,
        /// Bytes needed.
        needed: usize,
    },
    /// A service or type name that is not UTF-8.
    #[error("a name is not UTF-8")]
    NotUtf8,
    /// An unknown record kind.
    #[error("unknown record kind {0}")]
    Kind(u8),
}

/// Locks `m`, also after a panic of another holder (the data stays usable: every update is
/// complete before the next record is handled).
fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}

/// Drains the run's events and topics into `frames` (one per destination host), pass after pass
/// until one finds nothing (at most [`DRAIN_PASSES`]), into the same frames: what comes in while
/// the bridge drains goes out with it. `fired` holds one flag per event. Returns whether the last
/// pass still found something.
fn drain_into(
    frames: &mut [Vec<u8>],
    events: &[OutEvent],
    topics: &mut [OutTopic],
    fired: &mut [bool],
    stats: &Stats,
) -> bool {
    let mut more = false;
    for _ in 0..DRAIN_PASSES {
        more = false;
        // Events first: any sample published before a notification we saw is in its queue now;
        // each pass appends its samples, then its events.
        for (k, e) in events.iter().enumerate() {
            let mut got = false;
            let _ = e.listener.try_wait(|_| got = true);
            fired[k] = got;
            more |= got;
        }
        for t in topics.iter_mut() {
            let (dests, name, type_name) = (&t.dests, &t.name, t.type_name);
            let r = (t.drain)(&mut |bytes| {
                for &d in dests {
                    put_sample(&mut frames[d], name, type_name, bytes);
                }
            });
            match r {
                Ok(n) => {
                    more |= n > 0;
                    stats.samples_out.fetch_add(n as u64, Ordering::Relaxed);
                }
                Err(e) => tracing::warn!("bridge: {name}: {e}"),
            }
        }
        for (k, e) in events.iter().enumerate() {
            if fired[k] {
                for &d in &e.dests {
                    put_event(&mut frames[d], &e.name);
                }
                stats.events_out.fetch_add(1, Ordering::Relaxed);
            }
        }
        if !more {
            break;
        }
    }
    more
}

fn run_out(
    session: zenoh::Session,
    mut cfg: BridgeConfig,
    mut hosts: Vec<String>,
    stop: Arc<AtomicBool>,
    stats: Arc<Stats>,
    ready: mpsc::Sender<Result<usize, BridgeError>>,
    replan: mpsc::Receiver<Replan>,
) {
    if cfg.rt_priority > 0 {
        // This thread only (its name is not a Zenoh runtime's); a failure leaves it under the
        // normal policy, as the link threads' report says.
        let _ = formation_config::node::sched::set_thread_policy(0, cfg.rt_priority);
    }
    let node = match ipc::node(&cfg.prefix, "fm-bridge-out") {
        Ok(n) => n,
        Err(e) => {
            let _ = ready.send(Err(e.into()));
            return;
        }
    };
    let waitset = match WaitSetBuilder::new()
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<Svc>()
    {
        Ok(w) => w,
        Err(e) => {
            let _ = ready.send(Err(BridgeError::WaitSet(format!("{e:?}"))));
            return;
        }
    };
    let mut old = Ports::default();
    let mut ack = ready;
    // Sequence number of the last frame sent (to any host), for the receivers' replay check.
    let mut sent: u64 = 0;
    // One plan after the other: the first, then one per re-plan.
    loop {
        let plan =
            Opener::visit_all(&node, &cfg, &hosts, true, std::mem::take(&mut old)).and_then(|o| {
                let mut pubs = Vec::new();
                for h in &hosts {
                    pubs.push(frame_publisher(&session, proto::run_to(&cfg.run_id, h))?);
                }
                Ok((o.topics, o.events, pubs))
            });
        let (mut topics, events, pubs) = match plan {
            Ok(v) => v,
            Err(e) => {
                let _ = ack.send(Err(e));
                return;
            }
        };
        let mut guards = Vec::new();
        for e in &events {
            match waitset.attach_notification(&e.listener) {
                Ok(g) => guards.push(g),
                Err(x) => {
                    let _ = ack.send(Err(BridgeError::ipc("cannot wait on", &e.name, x)));
                    return;
                }
            }
        }
        let _ = ack.send(Ok(topics.len() + events.len()));
        // Every frame starts with this host's name; a frame with nothing after it is not sent.
        let mut from = Vec::new();
        put_from(&mut from, &cfg.me);
        let header = from.len();
        let mut frames: Vec<Vec<u8>> = vec![from.clone(); hosts.len()];
        let mut fired = vec![false; events.len()];
        let next = loop {
            if stop.load(Ordering::SeqCst) {
                break None;
            }
            // Between two cycles: every sample drained so far went out under this plan.
            if let Ok(r) = replan.try_recv() {
                break Some(r);
            }
            let more = drain_into(&mut frames, &events, &mut topics, &mut fired, &stats);
            for (d, f) in frames.iter_mut().enumerate() {
                if f.len() > header {
                    let mut f = std::mem::replace(f, from.clone());
                    sent += 1;
                    cfg.key.seal(Purpose::Frame, &hosts[d], sent, &mut f);
                    if let Err(e) = pubs[d].put(f).wait() {
                        tracing::warn!("bridge: cannot send to {}: {e}", hosts[d]);
                    }
                    stats.frames_out.fetch_add(1, Ordering::Relaxed);
                }
            }
            if more {
                continue;
            }
            if guards.is_empty() {
                std::thread::sleep(IDLE_WAKE);
            } else {
                let _ = waitset.wait_and_process_once_with_timeout(
                    |_| CallbackProgression::Continue,
                    IDLE_WAKE,
                );
            }
        };
        drop(guards);
        drop(pubs);
        let Some((placement, reply)) = next else {
            break;
        };
        old = Ports {
            topics: topics.drain(..).map(|t| (t.name.clone(), t)).collect(),
            events: events.into_iter().map(|e| (e.name.clone(), e)).collect(),
            ins: HashMap::new(),
        };
        cfg.placement = placement;
        cfg.create = false;
        hosts = cfg.placement.hosts();
        ack = reply;
    }
    drop(waitset);
    drop(node);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_send_stamp_is_found_in_states_shares_and_commands_only() {
        use formation_config::protocol::wire::ReferenceFrame;
        for (at, sent) in [
            (stamp_offset::<VehicleState>(), {
                let v = VehicleState {
                    sent_ns: 0x0102_0304_0506_0708,
                    ..Default::default()
                };
                // SAFETY: reading the bytes of a repr(C) Copy value.
                unsafe {
                    std::slice::from_raw_parts(
                        &v as *const _ as *const u8,
                        size_of::<VehicleState>(),
                    )
                    .to_vec()
                }
            }),
            (stamp_offset::<ControlCommand>(), {
                let v = ControlCommand {
                    sent_ns: 0x0102_0304_0506_0708,
                    ..Default::default()
                };
                // SAFETY: as above.
                unsafe {
                    std::slice::from_raw_parts(
                        &v as *const _ as *const u8,
                        size_of::<ControlCommand>(),
                    )
                    .to_vec()
                }
            }),
        ] {
            let at = at.unwrap();
            assert_eq!(
                u64::from_le_bytes(sent[at..at + 8].try_into().unwrap()),
                0x0102_0304_0506_0708
            );
        }
        assert!(stamp_offset::<NeighbourState>().is_some());
        assert!(stamp_offset::<ReferenceFrame>().is_none());
    }

    #[test]
    fn a_frame_round_trips_its_records_in_order_and_truncation_is_an_error() {
        let mut f = Vec::new();
        put_sample(
            &mut f,
            "formation/agent/3/state",
            "formation.v1.VehicleState",
            &[1, 2, 3, 4],
        );
        put_event(&mut f, "formation/wake/agent/3");
        put_from(&mut f, "b");
        let r = parse_frame(&f).unwrap();
        assert_eq!(
            r,
            vec![
                Record::Sample {
                    name: "formation/agent/3/state",
                    type_name: "formation.v1.VehicleState",
                    bytes: &[1, 2, 3, 4]
                },
                Record::Event("formation/wake/agent/3"),
                Record::From("b"),
            ]
        );
        assert!(parse_frame(&f[..f.len() - 3]).is_err());
        assert!(parse_frame(&[7, 0, 0]).is_err());
    }
}
