//! A run's telemetry for outside readers over the network (`formation run --zenoh-listen
//! ENDPOINT`): any Zenoh program (the PyPI binding `eclipse-zenoh`, Zenoh's own tools) on another
//! machine reads the run without iceoryx2 and without a `formation` build.
//!
//! One thread puts the run on Zenoh. The steps come from the recorder, as to every other output
//! of the run: the recorder hands each step it records (the step record, its reference) to a
//! [`StepFeed`], a bounded queue that never waits. What the recorder does not see, the runtime
//! events and every agent's telemetry, the thread reads from the run's iceoryx2 services as an
//! outside observer (one of the `--observers` slots, its own node under the run's prefix). It
//! sleeps on the orchestrator's wake-up event (the plant raises it every `ACK_EVERY` steps), then
//! drains the feed and the services and puts each sample on Zenoh:
//!
//! | key | payload | encoding schema |
//! |---|---|---|
//! | `formation/<run>/info` | queryable: JSON ([`info_json`]) | `application/json` |
//! | `formation/<run>/state/<agent>` | `VehicleState` of quadrotor `<agent>` (1-based), every step | `formation.v3.VehicleState` |
//! | `formation/<run>/steps` | the step record: N `StepEntry` back to back, every step | `formation.v3.StepEntry` |
//! | `formation/<run>/reference` | `ReferenceFrame` of every step recorded | `formation.v1.ReferenceFrame` |
//! | `formation/<run>/events` | `RuntimeEvent` (crash, hang, link, loss, takeover, ...) | `formation.v1.RuntimeEvent` |
//! | `formation/<run>/telemetry/<agent>` | `AgentTelemetry` of agent `<agent>` (1-based), latest | `formation.v2.AgentTelemetry` |
//! | `formation/<run>/end` | JSON [`EndReport`], once, after the run's last step | `application/json` |
//!
//! Payloads are the `#[repr(C)]` bytes the iceoryx2 services carry (little endian, layout in the
//! info); the encoding is `application/octet-stream` with the wire type name as its schema. The
//! state of quadrotor i is the `state` part of its step record's plant truth: the very value the
//! plant publishes on `formation/agent/{i}/state` (with its send stamp `sent_ns` 0).
//!
//! Nothing here can slow the run: the feed and the iceoryx2 subscribers overflow (the oldest step
//! or sample of a full queue is replaced, without a lock; the recorder and the publishers never
//! wait for this reader), the thread runs at background priority, and the Zenoh publishers use
//! `CongestionControl::Drop`: a reader that is slow or far away loses samples, it never holds the
//! lockstep back. Each sample carries its step, so a reader sees what it lost. A key no reader
//! subscribes to (Zenoh's matching status) is not put at all: without readers the export only
//! drains its queues.
//!
//! The end of a run ([`Export::finish`], before the role processes are stopped, bounded by
//! [`END_BOUND`]): the export catches up with the last step recorded (it may lag behind a run
//! that ends while it is starved), puts `formation/<run>/end` (JSON, [`EndReport`]) and keeps its
//! session open until no reader subscribes any more (a reader that has its last step leaves) or
//! the bound is over; then it undeclares its publishers and closes. What it could not read
//! (steps overwritten in its feed while it was starved) is counted in
//! [`EndReport::steps_missed`]; what Zenoh dropped on the way to a slow reader only the reader
//! sees (each payload carries its step).

use crate::bridge::{wire_bytes, wire_slice_bytes};
use crate::error::ZenohError;
use crate::session::{Mode, OptionError, Options};
use crossbeam_queue::ArrayQueue;
use formation_config::node::error::PortError;
use formation_config::node::ipc;
use formation_config::node::ports::{self, Input, Wake};
use formation_config::protocol::layout::{every_type, TypeLayout, WireLayout};
use formation_config::protocol::messages::{RuntimeEvent, StepEntry};
use formation_config::protocol::services::{self, wire_type_name, Message};
use formation_config::protocol::wire::{
    AgentTelemetry, ControlCommand, PlantTruth, ReferenceFrame, VehicleState,
};
use serde_json::{json, Value};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{mpsc, Arc};
use std::thread::JoinHandle;
use std::time::Duration;
use zenoh::bytes::Encoding;
use zenoh::qos::CongestionControl;
use zenoh::Wait;

/// Longest the export thread sleeps without a wake-up (it then drains anyway and checks whether
/// it must stop): a run that stands still (waiting for its processes) costs one wake-up per period.
pub const IDLE_WAKE: Duration = Duration::from_millis(100);

/// Longest the end of an export takes ([`Export::finish`]): catching up with the run's last step,
/// then waiting for the readers to leave. 2 s: a reader that keeps up has its last sample a few
/// ms after the run's last step (measured in docs/measurements.md); a reader that stays
/// subscribed (a dashboard) holds the run's exit by this bound, not more.
pub const END_BOUND: Duration = Duration::from_millis(2000);

/// Steps the [`StepFeed`] holds for the export thread: 1024, one second of the paper's 1 kHz
/// steps, far more than the thread lags behind between two wake-ups (`ACK_EVERY` steps) when it
/// gets the CPU; a thread starved for longer loses the oldest steps, counted in
/// [`EndReport::steps_missed`]. Memory: at most twice this many steps of one reference and N step
/// entries each (about 12 KiB a step for the paper's five agents).
pub const FEED_CAPACITY: usize = 1024;

/// How often [`Export::finish`] looks whether the export caught up and whether readers are left:
/// 1 ms, small against [`END_BOUND`] and against a reader's own latency.
const END_POLL: Duration = Duration::from_millis(1);

/// Topic of the end marker: `formation/<run>/end` carries the [`EndReport`] as JSON once, at the
/// end of the run.
pub const END_TOPIC: &str = "end";

/// The `format` of the info reply.
pub const INFO_FORMAT: &str = "formation-zenoh-info/1";

/// What the export publishes under `formation/<run>/`: the key's topic, the iceoryx2 service it
/// comes from, whether it exists once per agent (`/<agent>`, 1-based), the wire type and what it
/// carries.
#[derive(Debug, Clone, Copy)]
pub struct Exported {
    /// Topic: the key is `formation/<run>/<topic>` or `formation/<run>/<topic>/<agent>`.
    pub topic: &'static str,
    /// The iceoryx2 service whose samples the payloads are (`{i}`: 0-based agent index): read
    /// from it (events, telemetry), or handed over by the recorder, which records them from it
    /// (the step record and the state in it; the reference, computed with the leader's code bit
    /// for bit).
    pub service: &'static str,
    /// One key per agent.
    pub per_agent: bool,
    /// Wire type name (the encoding's schema).
    pub type_name: fn() -> &'static str,
    /// Layout of the wire type.
    pub layout: fn() -> TypeLayout,
    /// Samples in one payload: `1`, or `0` for N (one per agent, back to back).
    pub count: usize,
    /// What it carries, in one line.
    pub doc: &'static str,
}

fn entry<T: Message + WireLayout>(
    topic: &'static str,
    service: &'static str,
    per_agent: bool,
    count: usize,
    doc: &'static str,
) -> Exported {
    Exported {
        topic,
        service,
        per_agent,
        type_name: wire_type_name::<T>,
        layout: TypeLayout::of::<T>,
        count,
        doc,
    }
}

/// Every key the export publishes (the info queryable aside).
pub fn exported() -> [Exported; 5] {
    [
        entry::<VehicleState>(
            "state",
            services::VEHICLE_STATE.pattern,
            true,
            1,
            "quadrotor <agent>'s state at every step (position, velocity, attitude, rate)",
        ),
        entry::<StepEntry>(
            "steps",
            services::STEPS.pattern,
            false,
            0,
            "every step's plant truth and command of all N quadrotors (N StepEntry back to back)",
        ),
        entry::<ReferenceFrame>(
            "reference",
            services::REFERENCE.pattern,
            false,
            1,
            "the leader's reference of every step (P_d, its derivatives, the formation shape)",
        ),
        entry::<RuntimeEvent>(
            "events",
            services::RUNTIME_EVENTS.pattern,
            false,
            1,
            "runtime events: crash, hang, link, loss, an agent taken down or taking over",
        ),
        entry::<AgentTelemetry>(
            "telemetry",
            services::TELEMETRY.pattern,
            true,
            1,
            "agent <agent>'s live telemetry (errors, estimates, constraint margins), latest samples",
        ),
    ]
}

/// The key of `topic` in run `run_id`; `agent` is the 1-based agent id of a per-agent key.
pub fn key(run_id: &str, topic: &str, agent: Option<usize>) -> String {
    match agent {
        Some(a) => format!("formation/{run_id}/{topic}/{a}"),
        None => format!("formation/{run_id}/{topic}"),
    }
}

/// The info queryable's key of run `run_id`; `formation/*/info` asks every run reachable.
pub fn info_key(run_id: &str) -> String {
    key(run_id, "info", None)
}

/// The encoding of a payload of wire type `type_name`: `application/octet-stream;<type name>`.
pub fn encoding(type_name: &str) -> Encoding {
    Encoding::APPLICATION_OCTET_STREAM.with_schema(type_name)
}

/// What the info tells of the run besides its keys.
#[derive(Debug, Clone)]
pub struct RunFacts {
    /// Run id.
    pub run_id: String,
    /// Scenario name.
    pub scenario: String,
    /// Controller variant.
    pub variant: String,
    /// `lockstep` or `realtime`.
    pub mode: String,
    /// Number of agents N.
    pub n_agents: usize,
    /// Step, s.
    pub dt_s: f64,
    /// Steps of the whole run.
    pub steps: u64,
}

/// The JSON the info queryable answers: the run, every key with its type, and the layout (size,
/// alignment, field offsets) of every wire type, nested ones included.
pub fn info_json(f: &RunFacts) -> Value {
    let keys: Vec<Value> = exported()
        .iter()
        .map(|e| {
            let l = (e.layout)();
            json!({
                "topic": e.topic,
                "key": if e.per_agent {
                    key(&f.run_id, e.topic, None) + "/<agent>"
                } else {
                    key(&f.run_id, e.topic, None)
                },
                "per_agent": e.per_agent,
                "agents": if e.per_agent { json!([1, f.n_agents]) } else { Value::Null },
                "type_name": (e.type_name)(),
                "type": l.name,
                "size": l.size,
                "samples_per_payload": if e.count == 0 { f.n_agents } else { e.count },
                "iceoryx2_service": e.service,
                "doc": e.doc,
            })
        })
        .collect();
    let types: Vec<Value> = every_type()
        .iter()
        .map(|t| {
            json!({
                "type": t.name, "size": t.size, "align": t.align,
                "fields": t.fields.iter().map(|x| json!({
                    "name": x.name, "offset": x.offset, "size": x.size, "ty": x.ty, "unit": x.unit,
                })).collect::<Vec<_>>(),
            })
        })
        .collect();
    json!({
        "format": INFO_FORMAT,
        "run_id": f.run_id,
        "scenario": f.scenario,
        "variant": f.variant,
        "mode": f.mode,
        "n_agents": f.n_agents,
        "dt_s": f.dt_s,
        "steps": f.steps,
        "byte_order": "little",
        "encoding": "application/octet-stream;<type_name>",
        "keys": keys,
        "types": types,
    })
}

/// What an export is started with.
#[derive(Debug, Clone)]
pub struct ExportConfig {
    /// The run.
    pub facts: RunFacts,
    /// iceoryx2 prefix of the run.
    pub prefix: String,
    /// Endpoints to listen on (`tcp/ADDR:PORT`); beyond loopback only with `auth`.
    pub listen: Vec<String>,
    /// `user:password` file (mode 0600): the readers admitted (every line), as for a daemon.
    pub auth: Option<PathBuf>,
}

impl ExportConfig {
    /// The Zenoh session options (checked: endpoints, the loopback rule, the credentials file).
    pub fn options(&self) -> Options {
        Options {
            mode: Mode::Export,
            listen: self.listen.clone(),
            connect: Vec::new(),
            auth: self.auth.clone(),
            tls: None,
            lease_ms: crate::session::DEFAULT_LEASE_MS,
        }
    }
}

/// Counters of an export.
#[derive(Debug, Default)]
pub struct Stats {
    /// Zenoh puts made.
    pub puts: AtomicU64,
    /// Wake-ups of the export thread.
    pub wakes: AtomicU64,
    /// Info queries answered.
    pub queries: AtomicU64,
    /// Step records read from the run (and put when a reader subscribes).
    pub steps_read: AtomicU64,
    /// One past the highest step read (0: none yet).
    pub next_step: AtomicU64,
    /// Steps the export never read: overwritten in its feed while it was starved (gaps in the
    /// steps it read).
    pub steps_missed: AtomicU64,
}

/// Steps lost between two step records read one after the other: the gap between `next` (one
/// past the step read before, 0 at the start) and `step`, the step just read.
pub fn steps_skipped(next: u64, step: u64) -> u64 {
    step.saturating_sub(next)
}

/// Whether the export has read every step a run recorded: `next_step` is one past the highest
/// step it read, `recorded` the number of steps the run recorded (its steps are 0..recorded).
pub fn caught_up(next_step: u64, recorded: u64) -> bool {
    next_step >= recorded
}

/// How the end of an export went ([`Export::finish`]); `summary.json` `export` and the end marker
/// `formation/<run>/end`.
#[derive(Debug, Clone, serde::Serialize)]
pub struct EndReport {
    /// Steps the run recorded (its steps are 0..recorded).
    pub recorded: u64,
    /// Step records the export read and put (to every reader subscribed then).
    pub steps_exported: u64,
    /// Steps the export never read (its feed overflowed while it was starved): no reader got
    /// them.
    pub steps_missed: u64,
    /// One past the last step exported (`recorded` when it caught up).
    pub next_step: u64,
    /// Whether it read every step up to the last recorded one within the bound.
    pub caught_up: bool,
    /// Time from the run's last step to the export's last put, ms.
    pub drain_ms: f64,
    /// Time from then until no reader subscribed any more (or the bound), ms.
    pub linger_ms: f64,
    /// Whether readers were still subscribed when the bound ended the export.
    pub readers_left: bool,
    /// The bound of both, ms ([`END_BOUND`]).
    pub bound_ms: f64,
}

impl EndReport {
    /// One line for the run's stderr.
    pub fn line(&self) -> String {
        format!(
            "export: {} of {} steps put{}, {} missed by the export (its queue overflowed); drained in {:.0} ms, {} after {:.0} ms (bound {:.0} ms)",
            self.steps_exported,
            self.recorded,
            if self.caught_up { "" } else { " (not caught up within the bound)" },
            self.steps_missed,
            self.drain_ms,
            if self.readers_left { "readers still subscribed" } else { "no reader left" },
            self.linger_ms,
            self.bound_ms
        )
    }
}

/// A running export; [`Export::finish`] ends it with the run; dropped without it (a run that
/// returns on an error), it is stopped after a last drain and closed.
pub struct Export {
    stop: Arc<AtomicBool>,
    /// Set by [`Export::finish`]: the thread polls every [`END_POLL`] instead of sleeping.
    finishing: Arc<AtomicBool>,
    thread: Option<JoinHandle<Writers>>,
    /// Its counters.
    pub stats: Arc<Stats>,
    queryable: Option<zenoh::query::Queryable<()>>,
    session: zenoh::Session,
    run_id: String,
    feed: Arc<Feed>,
}

impl Export {
    /// The queue the recorder hands the run's steps to.
    pub fn feed(&self) -> StepFeed {
        StepFeed(self.feed.clone())
    }

    /// Ends the export with a run that recorded `recorded` steps (call it before the role
    /// processes stop: their queued samples go with them): waits until the export has read step
    /// `recorded - 1` (or the bound), stops its thread after a last drain, puts the end marker and
    /// waits until no reader subscribes (or the bound); then closes. Bounded by [`END_BOUND`].
    pub fn finish(mut self, recorded: u64) -> EndReport {
        let start = std::time::Instant::now();
        self.finishing.store(true, Ordering::SeqCst);
        while !caught_up(self.stats.next_step.load(Ordering::SeqCst), recorded)
            && start.elapsed() < END_BOUND
        {
            std::thread::sleep(END_POLL);
        }
        let writers = self.stop_thread();
        let drain = start.elapsed();
        let next_step = self.stats.next_step.load(Ordering::SeqCst);
        let mut report = EndReport {
            recorded,
            steps_exported: self.stats.steps_read.load(Ordering::SeqCst),
            steps_missed: self.stats.steps_missed.load(Ordering::SeqCst)
                + recorded.saturating_sub(next_step),
            next_step,
            caught_up: caught_up(next_step, recorded),
            drain_ms: drain.as_secs_f64() * 1e3,
            linger_ms: 0.0,
            readers_left: false,
            bound_ms: END_BOUND.as_secs_f64() * 1e3,
        };
        if let Some(w) = &writers {
            let end = serde_json::to_vec(&report).expect("JSON of plain values");
            let _ = self
                .session
                .put(key(&self.run_id, END_TOPIC, None), end)
                .encoding(Encoding::APPLICATION_JSON)
                .congestion_control(CongestionControl::Block)
                .wait();
            while w.any_reader() && start.elapsed() < END_BOUND {
                std::thread::sleep(END_POLL);
            }
            report.readers_left = w.any_reader();
        }
        report.linger_ms = (start.elapsed() - drain).as_secs_f64() * 1e3;
        drop(writers);
        self.close();
        report
    }

    /// Stops the thread after its last drain; its publishers (`None` if it panicked).
    fn stop_thread(&mut self) -> Option<Writers> {
        self.stop.store(true, Ordering::SeqCst);
        self.thread.take().and_then(|t| t.join().ok())
    }

    /// Undeclares the info queryable, then closes the session (publishers are undeclared before,
    /// with their writers): nothing of this Zenoh session is declared while it closes.
    fn close(&mut self) {
        if let Some(q) = self.queryable.take() {
            let _ = q.undeclare().wait();
        }
        let _ = self.session.close().wait();
    }
}

impl Drop for Export {
    fn drop(&mut self) {
        if self.thread.is_some() {
            drop(self.stop_thread());
        }
        self.close();
    }
}

/// Why the export cannot start or read: the session, a Zenoh declaration, a service of the run.
#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    /// The Zenoh session does not open (an endpoint refused, credentials missing or unsafe).
    #[error(transparent)]
    Session(#[from] OptionError),
    /// A queryable, publisher or matching listener cannot be declared.
    #[error("export: {0}")]
    Zenoh(#[from] ZenohError),
    /// The run's iceoryx2 node cannot be made.
    #[error("export: {0}")]
    Node(#[from] formation_config::node::ipc::IpcError),
    /// A service of the run cannot be opened or read.
    #[error("export: {0}")]
    Port(#[from] PortError),
    /// The export thread cannot be started.
    #[error("export: cannot start a thread: {0}")]
    Thread(std::io::Error),
    /// The export thread ended before its ports were open.
    #[error("export: the thread ended before it was ready")]
    Ended,
}

/// One step as the recorder recorded it.
struct Fed {
    reference: ReferenceFrame,
    entries: Vec<StepEntry>,
}

/// The queue between the recorder and the export thread, and the spent steps it hands back (so a
/// step costs the recorder two copies, no allocation).
struct Feed {
    queue: ArrayQueue<Box<Fed>>,
    spare: ArrayQueue<Box<Fed>>,
}

impl Feed {
    fn new() -> Feed {
        Feed {
            queue: ArrayQueue::new(FEED_CAPACITY),
            spare: ArrayQueue::new(FEED_CAPACITY),
        }
    }
}

/// The recorder's end of the export: [`StepFeed::offer`] hands a recorded step to the export
/// thread and never waits.
pub struct StepFeed(Arc<Feed>);

impl StepFeed {
    /// Step `reference.step` as recorded: its reference, the plant's truths and the commands of
    /// the N agents (the step record). A full feed drops its oldest step (counted by the export
    /// as missed); no lock is taken.
    pub fn offer(
        &self,
        reference: &ReferenceFrame,
        truths: &[PlantTruth],
        commands: &[ControlCommand],
    ) {
        let mut fed = self.0.spare.pop().unwrap_or_else(|| {
            Box::new(Fed {
                reference: ReferenceFrame::default(),
                entries: Vec::with_capacity(truths.len()),
            })
        });
        fed.reference = *reference;
        fed.entries.clear();
        fed.entries.extend(
            truths
                .iter()
                .zip(commands)
                .map(|(&truth, &command)| StepEntry { truth, command }),
        );
        if let Some(oldest) = self.0.queue.force_push(fed) {
            let _ = self.0.spare.push(oldest);
        }
    }
}

/// The export thread's ports.
struct Readers {
    wake: Wake,
    events: Input<RuntimeEvent>,
    telemetry: Vec<Input<AgentTelemetry>>,
}

impl Readers {
    fn open(node: &ports::RunNode, n: usize) -> Result<Readers, ExportError> {
        Ok(Readers {
            wake: Wake::open(node, &services::WAKE_ORCHESTRATOR.named())?,
            events: ports::subscriber(node, &services::RUNTIME_EVENTS.named())?,
            telemetry: (0..n)
                .map(|i| ports::subscriber(node, &services::TELEMETRY.at(i)))
                .collect::<Result<_, _>>()?,
        })
    }
}

/// A Zenoh publisher and whether any subscriber matches it now (kept by Zenoh's matching
/// listener): without a reader nothing is copied or sent.
struct Out {
    publisher: zenoh::pubsub::Publisher<'static>,
    matching: Arc<AtomicBool>,
}

impl Out {
    fn declare(s: &zenoh::Session, key: String, type_name: &str) -> Result<Out, ZenohError> {
        let publisher = s
            .declare_publisher(key)
            .encoding(encoding(type_name))
            .congestion_control(CongestionControl::Drop)
            .wait()
            .map_err(|e| ZenohError::new("cannot declare a publisher", e))?;
        let matching = Arc::new(AtomicBool::new(false));
        let flag = matching.clone();
        publisher
            .matching_listener()
            .callback(move |m| flag.store(m.matching(), Ordering::Relaxed))
            .background()
            .wait()
            .map_err(|e| ZenohError::new("cannot watch for readers", e))?;
        Ok(Out {
            publisher,
            matching,
        })
    }

    /// Whether a reader subscribes to it.
    fn wanted(&self) -> bool {
        self.matching.load(Ordering::Relaxed)
    }

    fn put(&self, bytes: &[u8], stats: &Stats) {
        // Drop congestion control: a full link drops the sample here, it never waits.
        if self.wanted() && self.publisher.put(bytes.to_vec()).wait().is_ok() {
            stats.puts.fetch_add(1, Ordering::Relaxed);
        }
    }
}

/// The Zenoh publishers of one run.
struct Writers {
    states: Vec<Out>,
    steps: Out,
    reference: Out,
    events: Out,
    telemetry: Vec<Out>,
}

impl Writers {
    /// Whether any reader subscribes to any key of the run.
    fn any_reader(&self) -> bool {
        self.states
            .iter()
            .chain(&self.telemetry)
            .chain([&self.steps, &self.reference, &self.events])
            .any(Out::wanted)
    }

    /// One publisher per key of [`exported`], in its order.
    fn declare(s: &zenoh::Session, run_id: &str, n: usize) -> Result<Writers, ZenohError> {
        let [state, steps, reference, events, telemetry] = exported();
        let one = |e: &Exported, agent: Option<usize>| {
            Out::declare(s, key(run_id, e.topic, agent), (e.type_name)())
        };
        let each = |e: &Exported| {
            (1..=n)
                .map(|a| one(e, Some(a)))
                .collect::<Result<Vec<Out>, ZenohError>>()
        };
        Ok(Writers {
            states: each(&state)?,
            steps: one(&steps, None)?,
            reference: one(&reference, None)?,
            events: one(&events, None)?,
            telemetry: each(&telemetry)?,
        })
    }
}

/// Drains the feed and every reader and puts what they held; the number of samples read.
fn drain(feed: &Feed, r: &Readers, w: &Writers, stats: &Stats) -> Result<usize, ExportError> {
    let mut n = 0;
    while let Some(fed) = feed.queue.pop() {
        let entries: &[StepEntry] = &fed.entries;
        if let Some(first) = entries.first() {
            let step = first.truth.state.step;
            let next = stats.next_step.load(Ordering::Relaxed);
            stats
                .steps_missed
                .fetch_add(steps_skipped(next, step), Ordering::Relaxed);
            stats.next_step.store(next.max(step + 1), Ordering::SeqCst);
            stats.steps_read.fetch_add(1, Ordering::Relaxed);
        }
        for (entry, p) in entries.iter().zip(&w.states) {
            p.put(wire_bytes(&entry.truth.state), stats);
        }
        w.steps.put(wire_slice_bytes(entries), stats);
        w.reference.put(wire_bytes(&fed.reference), stats);
        let _ = feed.spare.push(fed);
        n += 1;
    }
    while let Some(s) = r.events.receive()? {
        w.events.put(wire_bytes(s.payload()), stats);
        n += 1;
    }
    for (t, p) in r.telemetry.iter().zip(&w.telemetry) {
        while let Some(s) = t.receive()? {
            p.put(wire_bytes(s.payload()), stats);
            n += 1;
        }
    }
    Ok(n)
}

/// An export whose Zenoh session is open (its endpoints bound, the info answered) and whose
/// thread is not started yet: the run's services do not exist yet.
pub struct Listening {
    cfg: ExportConfig,
    session: zenoh::Session,
    queryable: zenoh::query::Queryable<()>,
    writers: Writers,
    stats: Arc<Stats>,
}

impl Listening {
    /// Opens the Zenoh session listening on `cfg.listen` (a refused endpoint, a missing or
    /// unsafe credentials file, a port in use: an error naming it), declares the info queryable
    /// and the publishers.
    pub fn open(cfg: ExportConfig) -> Result<Listening, ExportError> {
        let session = cfg.options().open()?;
        let info = serde_json::to_vec(&info_json(&cfg.facts)).expect("JSON of plain values");
        let stats = Arc::new(Stats::default());
        let answered = stats.clone();
        let queryable = session
            .declare_queryable(info_key(&cfg.facts.run_id))
            .callback(move |q| {
                let _ = q
                    .reply(q.key_expr().clone(), info.clone())
                    .encoding(Encoding::APPLICATION_JSON)
                    .wait();
                answered.queries.fetch_add(1, Ordering::Relaxed);
            })
            .wait()
            .map_err(|e| ZenohError::new("cannot declare the info queryable", e))?;
        let writers = Writers::declare(&session, &cfg.facts.run_id, cfg.facts.n_agents)?;
        Ok(Listening {
            cfg,
            session,
            queryable,
            writers,
            stats,
        })
    }

    /// Starts the export thread once the run's services exist; returns when its iceoryx2 ports
    /// are open, so no sample of the run's first step is missed.
    pub fn start(self) -> Result<Export, ExportError> {
        let Listening {
            cfg,
            session,
            queryable,
            writers,
            stats,
        } = self;
        let stop = Arc::new(AtomicBool::new(false));
        let finishing = Arc::new(AtomicBool::new(false));
        let run_id = cfg.facts.run_id.clone();
        let (ready_tx, ready_rx) = mpsc::channel::<Result<(), ExportError>>();
        let feed = Arc::new(Feed::new());
        let thread = {
            let flags = Flags {
                stop: stop.clone(),
                finishing: finishing.clone(),
            };
            let (stats, feed) = (stats.clone(), feed.clone());
            std::thread::Builder::new()
                .name("export".into())
                .spawn(move || run(cfg, writers, feed, flags, stats, ready_tx))
                .map_err(ExportError::Thread)?
        };
        let mut export = Export {
            stop,
            finishing,
            thread: Some(thread),
            stats,
            queryable: Some(queryable),
            session,
            run_id,
            feed,
        };
        match ready_rx.recv() {
            Ok(Ok(())) => Ok(export),
            Ok(Err(e)) => Err(e),
            Err(_) => {
                // The thread ended without a word: its panic, if any, is joined here.
                export.thread.take().map(|t| t.join());
                Err(ExportError::Ended)
            }
        }
    }
}

/// What the export thread is told: stop after a last drain; poll fast (the run is ending).
struct Flags {
    stop: Arc<AtomicBool>,
    finishing: Arc<AtomicBool>,
}

/// The export thread: drains the feed and the run's services into `writers` until told to stop;
/// returns the writers, so the end of the export still knows its readers.
fn run(
    cfg: ExportConfig,
    writers: Writers,
    feed: Arc<Feed>,
    flags: Flags,
    stats: Arc<Stats>,
    ready: mpsc::Sender<Result<(), ExportError>>,
) -> Writers {
    // Background priority: the role processes and the recorder go first; a starved export only
    // loses samples (its queues overflow), it never holds them back.
    formation_config::node::sched::background_thread();
    let node = match ipc::node(&cfg.prefix, "fm-export") {
        Ok(n) => n,
        Err(e) => {
            let _ = ready.send(Err(e.into()));
            return writers;
        }
    };
    let readers = match Readers::open(&node, cfg.facts.n_agents) {
        Ok(r) => r,
        Err(e) => {
            let _ = ready.send(Err(e));
            return writers;
        }
    };
    let _ = ready.send(Ok(()));
    loop {
        // Read before draining: samples published up to the stop are still put.
        let stopping = flags.stop.load(Ordering::SeqCst);
        if let Err(e) = drain(&feed, &readers, &writers, &stats) {
            tracing::warn!("{e}");
        }
        if stopping {
            break;
        }
        stats.wakes.fetch_add(1, Ordering::Relaxed);
        // The run's last steps raise no wake-up of their own: at the end, poll.
        let sleep = if flags.finishing.load(Ordering::SeqCst) {
            END_POLL
        } else {
            IDLE_WAKE
        };
        if let Err(e) = readers.wake.wait(sleep) {
            tracing::warn!("export: {e}");
            std::thread::sleep(sleep);
        }
    }
    drop(readers);
    drop(node);
    writers
}

#[cfg(test)]
mod tests {
    use super::*;

    fn facts() -> RunFacts {
        RunFacts {
            run_id: "1a2b".into(),
            scenario: "paper".into(),
            variant: "proposed".into(),
            mode: "lockstep".into(),
            n_agents: 5,
            dt_s: 0.001,
            steps: 30000,
        }
    }

    #[test]
    fn gaps_in_the_steps_read_count_as_missed_and_the_end_waits_for_the_last_step() {
        assert_eq!(steps_skipped(0, 0), 0);
        assert_eq!(steps_skipped(5, 5), 0);
        assert_eq!(steps_skipped(5, 9), 4);
        // A step read again (a replay after a restart) is no gap.
        assert_eq!(steps_skipped(9, 3), 0);
        assert!(!caught_up(9999, 10_000));
        assert!(caught_up(10_000, 10_000));
        // A run that recorded nothing has nothing to wait for.
        assert!(caught_up(0, 0));
    }

    #[test]
    fn the_end_line_names_what_was_put_missed_and_how_long_the_end_took() {
        let r = EndReport {
            recorded: 10_000,
            steps_exported: 9_990,
            steps_missed: 10,
            next_step: 10_000,
            caught_up: true,
            drain_ms: 3.2,
            linger_ms: 41.0,
            readers_left: false,
            bound_ms: 2000.0,
        };
        assert_eq!(
            r.line(),
            "export: 9990 of 10000 steps put, 10 missed by the export (its queue overflowed); drained in 3 ms, no reader left after 41 ms (bound 2000 ms)"
        );
    }

    #[test]
    fn a_full_feed_drops_its_oldest_steps_and_the_gap_counts_them() {
        let feed = StepFeed(Arc::new(Feed::new()));
        let (truths, commands) = ([PlantTruth::default(); 5], [ControlCommand::default(); 5]);
        let extra = 7;
        for k in 0..(FEED_CAPACITY + extra) as u64 {
            let reference = ReferenceFrame {
                step: k,
                ..ReferenceFrame::default()
            };
            let mut truths = truths;
            truths.iter_mut().for_each(|t| t.state.step = k);
            feed.offer(&reference, &truths, &commands);
        }
        let first = feed.0.queue.pop().expect("a step");
        assert_eq!(first.entries.len(), 5);
        let step = first.entries[0].truth.state.step;
        assert_eq!((step, first.reference.step), (extra as u64, extra as u64));
        assert_eq!(steps_skipped(0, step), extra as u64);
        // The newest step is kept: a starved export still ends on the run's last step.
        let mut last = step;
        while let Some(f) = feed.0.queue.pop() {
            last = f.entries[0].truth.state.step;
        }
        assert_eq!(last, (FEED_CAPACITY + extra - 1) as u64);
    }

    #[test]
    fn keys_name_the_run_the_topic_and_the_one_based_agent() {
        assert_eq!(key("1a2b", "state", Some(1)), "formation/1a2b/state/1");
        assert_eq!(key("1a2b", "reference", None), "formation/1a2b/reference");
        assert_eq!(info_key("1a2b"), "formation/1a2b/info");
    }

    #[test]
    fn the_encoding_carries_the_versioned_wire_type_name() {
        assert_eq!(
            encoding(wire_type_name::<VehicleState>()).to_string(),
            "application/octet-stream;formation.v3.VehicleState"
        );
    }

    #[test]
    fn the_info_gives_every_key_its_type_size_and_the_field_offsets_a_decoder_needs() {
        let v = info_json(&facts());
        assert_eq!(v["format"], INFO_FORMAT);
        assert_eq!(
            (v["n_agents"].as_u64(), v["dt_s"].as_f64()),
            (Some(5), Some(0.001))
        );
        let keys = v["keys"].as_array().unwrap();
        let state = keys.iter().find(|k| k["topic"] == "state").unwrap();
        assert_eq!(state["key"], "formation/1a2b/state/<agent>");
        assert_eq!(state["type_name"], "formation.v3.VehicleState");
        assert_eq!(state["size"], size_of::<VehicleState>());
        let steps = keys.iter().find(|k| k["topic"] == "steps").unwrap();
        assert_eq!(steps["samples_per_payload"], 5);
        assert_eq!(steps["size"], size_of::<StepEntry>());
        // Every key's type has its layout in the info, with the offset of each field.
        let types = v["types"].as_array().unwrap();
        for k in keys {
            let t = types.iter().find(|t| t["type"] == k["type"]).unwrap();
            assert_eq!(t["size"], k["size"]);
        }
        let vs = types.iter().find(|t| t["type"] == "VehicleState").unwrap();
        let pos = vs["fields"]
            .as_array()
            .unwrap()
            .iter()
            .find(|f| f["name"] == "position")
            .unwrap();
        assert_eq!(pos["offset"], std::mem::offset_of!(VehicleState, position));
    }

    #[test]
    fn a_state_payload_is_the_plant_truth_state_bytes() {
        let mut e = StepEntry::default();
        e.truth.state.position = [1.0, -2.0, 3.5];
        e.truth.state.step = 42;
        let b = wire_bytes(&e.truth.state);
        assert_eq!(b.len(), size_of::<VehicleState>());
        let at = std::mem::offset_of!(VehicleState, position);
        assert_eq!(
            f64::from_le_bytes(b[at + 8..at + 16].try_into().unwrap()),
            -2.0
        );
        assert_eq!(u64::from_le_bytes(b[0..8].try_into().unwrap()), 42);
    }
}
