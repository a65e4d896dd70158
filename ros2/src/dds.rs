//! The live publisher: the run's topics on the DDS-RTPS wire (RustDDS), as a ROS 2 node's would
//! be (`rt/` prefix, ROS 2's DDS type names, CDR payloads), so `ros2 topic echo`, rviz2 and any
//! DDS implementation on the same domain receive them.
//!
//! Observer only: [`Publisher::offer`] copies the output step into a bounded queue and returns at
//! once; a full queue drops the step (counted). Encoding and the DDS writes run on the
//! publisher's own thread; a write that finds a reliable reader's window full is dropped too
//! (counted), never waited for.

use crate::scene::{AgentPose, Encoder, Frame, LinkState, Qos, Reliability, Scene, Topic};
use rustdds::no_key::{DataWriter, SerializerAdapter};
use rustdds::{
    policy, DomainParticipant, DomainParticipantBuilder, QosPolicies, QosPolicyBuilder,
    RepresentationIdentifier, TopicKind,
};
use std::net::{IpAddr, Ipv4Addr};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{sync_channel, Receiver, SyncSender, TrySendError};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Output steps the queue between the run and the publisher thread holds (500: 5 s of simulation
/// time at 100 Hz of output, ~0.3 s of a lockstep paper run). The publisher runs at the background
/// nice (10): on a machine busy with other work it gets the CPU in bursts, and with a queue of 100
/// a reader lost ~0.5 % of a lockstep run's steps there (34 of 6 000); a step queued costs ~0.5 kB
/// at N = 5.
pub const QUEUE_STEPS: usize = 500;

/// Longest wait, at the end of a run, for matched reliable readers to acknowledge the last samples.
pub const ACK_WAIT: Duration = Duration::from_secs(2);

/// Interval at which [`Publisher::wait_for_subscriber`] looks for a matched reader.
const MATCH_POLL: Duration = Duration::from_millis(50);

/// Pause of the publisher thread after it has emptied the queue (10 ms): it then wakes at most
/// 100 times a second, however fast the run, instead of once per output step (a lockstep paper run
/// offers ~1 600 output steps a second; each wake-up is a context switch on a CPU the step chain
/// may need). At that run's pace the queue ([`QUEUE_STEPS`]) takes ~0.3 s to fill; a live view
/// lags by at most this pause.
pub const DRAIN_PAUSE: Duration = Duration::from_millis(10);

/// Interval at which the publisher thread looks again for the topics that have a reader (100 ms).
/// A topic without one is neither encoded nor written (every topic is volatile: a sample nobody
/// reads now is read by nobody), so a run nobody watches costs the lockstep next to nothing; a
/// reader that joins is served from at most this long after its discovery, as quick as a ROS 2
/// tool notices anyway.
pub const READERS_EVERY: Duration = Duration::from_millis(100);

/// Which peers the participant is discovered by (ROS 2's `ROS_AUTOMATIC_DISCOVERY_RANGE`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DiscoveryRange {
    /// Processes on this machine only: discovery announced and multicast joined on the loopback
    /// interface only, only loopback locators advertised.
    Localhost,
    /// Every network interface (RTPS' default multicast discovery on the subnet).
    Subnet,
}

/// Where and how the publisher joins DDS.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Options {
    /// DDS domain (`ROS_DOMAIN_ID`), 0 to 232.
    pub domain_id: u16,
    /// Discovery range.
    pub range: DiscoveryRange,
}

/// Highest domain id whose RTPS ports (7400 + 250 d + ...) fit in 16 bits.
pub const MAX_DOMAIN_ID: u16 = 232;

/// A ROS 2 environment variable that makes no sense.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct EnvError {
    /// The variable.
    pub variable: &'static str,
    /// Its value.
    pub value: String,
    /// What it should be.
    pub expected: &'static str,
}

impl std::fmt::Display for EnvError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{}={:?}: expected {}",
            self.variable, self.value, self.expected
        )
    }
}

impl std::error::Error for EnvError {}

impl Options {
    /// The options of ROS 2's environment: `ROS_DOMAIN_ID` (default 0),
    /// `ROS_AUTOMATIC_DISCOVERY_RANGE` (`LOCALHOST` (default), `SUBNET`, `SYSTEM_DEFAULT` (=
    /// `SUBNET`); `OFF` is refused: nothing could discover the run) and, when that is unset,
    /// `ROS_LOCALHOST_ONLY` (`0`: `SUBNET`, `1`: `LOCALHOST`).
    pub fn from_env(get: impl Fn(&str) -> Option<String>) -> Result<Options, EnvError> {
        let domain_id = match get("ROS_DOMAIN_ID").filter(|v| !v.trim().is_empty()) {
            None => 0,
            Some(v) => v
                .trim()
                .parse::<u16>()
                .ok()
                .filter(|d| *d <= MAX_DOMAIN_ID)
                .ok_or(EnvError {
                    variable: "ROS_DOMAIN_ID",
                    value: v,
                    expected: "a whole number from 0 to 232",
                })?,
        };
        let range = match get("ROS_AUTOMATIC_DISCOVERY_RANGE").filter(|v| !v.is_empty()) {
            Some(v) => match v.as_str() {
                "LOCALHOST" => DiscoveryRange::Localhost,
                "SUBNET" | "SYSTEM_DEFAULT" => DiscoveryRange::Subnet,
                _ => {
                    return Err(EnvError {
                        variable: "ROS_AUTOMATIC_DISCOVERY_RANGE",
                        value: v,
                        expected: "LOCALHOST, SUBNET or SYSTEM_DEFAULT (OFF would hide the run)",
                    })
                }
            },
            None => match get("ROS_LOCALHOST_ONLY").filter(|v| !v.is_empty()) {
                None => DiscoveryRange::Localhost,
                Some(v) if v == "1" => DiscoveryRange::Localhost,
                Some(v) if v == "0" => DiscoveryRange::Subnet,
                Some(v) => {
                    return Err(EnvError {
                        variable: "ROS_LOCALHOST_ONLY",
                        value: v,
                        expected: "0 or 1",
                    })
                }
            },
        };
        Ok(Options { domain_id, range })
    }
}

/// A CDR message as it goes on the wire (after the encapsulation header, which RustDDS writes).
struct Raw(rustdds::bytes::Bytes);

/// Hands [`Raw`] payloads to RustDDS as they are.
struct RawCdr;

impl SerializerAdapter<Raw> for RawCdr {
    type Error = std::convert::Infallible;

    fn output_encoding() -> RepresentationIdentifier {
        RepresentationIdentifier::CDR_LE
    }

    fn to_bytes(value: &Raw) -> Result<rustdds::bytes::Bytes, Self::Error> {
        Ok(value.0.clone())
    }
}

/// What failed when the publisher started.
#[derive(Debug)]
pub struct StartError(String);

impl std::fmt::Display for StartError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "DDS: {}", self.0)
    }
}

impl std::error::Error for StartError {}

/// An owned output step on its way to the publisher thread.
struct Step {
    time_ns: u64,
    p_d: [f64; 3],
    target: [f64; 3],
    agents: Vec<AgentPose>,
    slots: Vec<[f64; 3]>,
    links: Vec<LinkState>,
}

enum Item {
    Step(Step),
    Event(String),
}

/// Counts of a publisher's work.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Stats {
    /// Output steps offered.
    pub offered: u64,
    /// Output steps (and events) dropped because the queue was full.
    pub dropped: u64,
    /// Output steps published (written to every topic that had a reader).
    pub published: u64,
    /// Output steps offered while no topic had a reader: neither encoded nor written.
    pub unheard: u64,
    /// DDS writes refused (a reliable reader's window full), each one message of one topic.
    pub writes_refused: u64,
}

#[derive(Default)]
struct Counters {
    dropped: AtomicU64,
    published: AtomicU64,
    unheard: AtomicU64,
    writes_refused: AtomicU64,
}

type Writer = DataWriter<Raw, RawCdr>;

/// The live publisher of one run.
pub struct Publisher {
    tx: Option<SyncSender<Item>>,
    thread: Option<std::thread::JoinHandle<()>>,
    counters: Arc<Counters>,
    offered: u64,
    participant: DomainParticipant,
    /// The DDS topic whose readers [`Publisher::wait_for_subscriber`] waits for.
    watched: String,
}

fn qos_of(q: &Qos) -> QosPolicies {
    let reliability = match q.reliability {
        Reliability::Reliable => policy::Reliability::Reliable {
            max_blocking_time: rustdds::Duration::ZERO,
        },
        Reliability::BestEffort => policy::Reliability::BestEffort,
    };
    QosPolicyBuilder::new()
        .durability(policy::Durability::Volatile)
        .reliability(reliability)
        .history(policy::History::KeepLast {
            depth: q.depth as i32,
        })
        .build()
}

fn writer_of(
    participant: &DomainParticipant,
    publisher: &rustdds::Publisher,
    t: &Topic,
) -> Result<Writer, StartError> {
    let qos = qos_of(&t.qos);
    let topic = participant
        .create_topic(
            format!("rt{}", t.name),
            crate::msg::dds_type_name(t.type_name),
            &qos,
            TopicKind::NoKey,
        )
        .map_err(|e| StartError(format!("topic {}: {e}", t.name)))?;
    publisher
        .create_datawriter_no_key::<Raw, RawCdr>(&topic, Some(qos))
        .map_err(|e| StartError(format!("writer of {}: {e}", t.name)))
}

/// What the publisher thread hands back once it has joined the domain.
type Joined = Result<(DomainParticipant, String), StartError>;

impl Publisher {
    /// Joins the domain and creates a writer per topic of `scene`, all on a thread of the
    /// publisher's own that first runs `on_thread` (e.g. lowering its priority: RustDDS' threads,
    /// started from it, inherit that); the writes run there.
    pub fn start(scene: Scene, options: Options, on_thread: fn()) -> Result<Publisher, StartError> {
        let (tx, rx) = sync_channel(QUEUE_STEPS);
        let (joined_tx, joined_rx) = sync_channel::<Joined>(1);
        let counters = Arc::new(Counters::default());
        let c = counters.clone();
        let thread = std::thread::Builder::new()
            .name("ros2-publisher".into())
            .spawn(move || {
                on_thread();
                match join(scene, options) {
                    Ok((participant, encoder, writers, watched)) => {
                        let _ = joined_tx.send(Ok((participant.clone(), watched)));
                        publish(rx, encoder, writers, &participant, &c);
                    }
                    Err(e) => {
                        let _ = joined_tx.send(Err(e));
                    }
                }
            })
            .map_err(|e| StartError(format!("thread: {e}")))?;
        let joined = joined_rx
            .recv()
            .map_err(|_| StartError("the publisher thread stopped".into()));
        let (participant, watched) = match joined.and_then(|j| j) {
            Ok(j) => j,
            Err(e) => {
                let _ = thread.join();
                return Err(e);
            }
        };
        Ok(Publisher {
            tx: Some(tx),
            thread: Some(thread),
            counters,
            offered: 0,
            participant,
            watched,
        })
    }

    /// The domain joined.
    pub fn domain_id(&self) -> u16 {
        self.participant.domain_id()
    }

    /// Waits up to `timeout` until a reader of agent 1's pose topic is discovered; whether one was.
    pub fn wait_for_subscriber(&self, timeout: Duration) -> bool {
        let until = Instant::now() + timeout;
        loop {
            let matched = self
                .participant
                .discovered_readers()
                .iter()
                .any(|r| r.subscription_topic_data.topic_name() == &self.watched);
            if matched {
                return true;
            }
            if Instant::now() >= until {
                return false;
            }
            std::thread::sleep(MATCH_POLL);
        }
    }

    /// Offers an output step; never blocks (a full queue drops it).
    pub fn offer(&mut self, f: &Frame) {
        self.offered += 1;
        let step = Step {
            time_ns: f.time_ns,
            p_d: f.p_d,
            target: f.target,
            agents: f.agents.to_vec(),
            slots: f.slots.to_vec(),
            links: f.links.to_vec(),
        };
        self.send(Item::Step(step));
    }

    /// Offers an event (`/formation/events`: its JSON); never blocks.
    pub fn event(&mut self, json: String) {
        self.send(Item::Event(json));
    }

    fn send(&mut self, item: Item) {
        if let Some(tx) = &self.tx {
            match tx.try_send(item) {
                Ok(()) => {}
                Err(TrySendError::Full(_)) | Err(TrySendError::Disconnected(_)) => {
                    self.counters.dropped.fetch_add(1, Ordering::Relaxed);
                }
            }
        }
    }

    /// Publishes what is queued, waits up to [`ACK_WAIT`] for reliable readers to acknowledge
    /// it, leaves the domain; returns the counts.
    pub fn finish(mut self) -> Stats {
        self.tx.take();
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
        Stats {
            offered: self.offered,
            dropped: self.counters.dropped.load(Ordering::Relaxed),
            published: self.counters.published.load(Ordering::Relaxed),
            unheard: self.counters.unheard.load(Ordering::Relaxed),
            writes_refused: self.counters.writes_refused.load(Ordering::Relaxed),
        }
    }
}

/// Joins the domain and creates a writer per topic: the participant, the encoder, the writers
/// and the DDS topic whose readers [`Publisher::wait_for_subscriber`] waits for.
fn join(
    scene: Scene,
    options: Options,
) -> Result<(DomainParticipant, Encoder, Vec<Writer>, String), StartError> {
    let mut builder = DomainParticipantBuilder::new(options.domain_id);
    if options.range == DiscoveryRange::Localhost {
        builder = builder.with_only_networks([IpAddr::V4(Ipv4Addr::LOCALHOST)]);
    }
    let participant = builder
        .build()
        .map_err(|e| StartError(format!("domain {}: {e}", options.domain_id)))?;
    let publisher = participant
        .create_publisher(&QosPolicies::qos_none())
        .map_err(|e| StartError(format!("publisher: {e}")))?;
    let encoder = Encoder::new(scene);
    let writers = encoder
        .topics()
        .iter()
        .map(|t| writer_of(&participant, &publisher, t))
        .collect::<Result<Vec<_>, _>>()?;
    let watched = format!(
        "rt{}",
        encoder.topics()[crate::scene::POSES.min(encoder.topics().len() - 1)].name
    );
    Ok((participant, encoder, writers, watched))
}

/// Which of `topics` (DDS names) have a discovered reader now.
fn topics_read(participant: &DomainParticipant, topics: &[String]) -> Vec<bool> {
    let readers = participant.discovered_readers();
    topics
        .iter()
        .map(|t| {
            readers
                .iter()
                .any(|r| r.subscription_topic_data.topic_name() == t)
        })
        .collect()
}

/// The publisher thread: encodes each queued item and writes it to the topics that have a reader
/// (looked up every [`READERS_EVERY`]).
fn publish(
    rx: Receiver<Item>,
    mut encoder: Encoder,
    writers: Vec<Writer>,
    participant: &DomainParticipant,
    c: &Counters,
) {
    let topics: Vec<String> = encoder
        .topics()
        .iter()
        .map(|t| format!("rt{}", t.name))
        .collect();
    let mut read = topics_read(participant, &topics);
    let mut looked = Instant::now();
    // Each wake-up empties the queue, then pauses (DRAIN_PAUSE); a closed queue ends the loop.
    let mut next = rx.recv().ok();
    while let Some(item) = next.take() {
        if looked.elapsed() >= READERS_EVERY {
            read = topics_read(participant, &topics);
            looked = Instant::now();
        }
        let write = |topic: usize, bytes: &[u8]| {
            if !read[topic] {
                return;
            }
            // The encapsulation header is RustDDS' to write.
            let body =
                rustdds::bytes::Bytes::copy_from_slice(&bytes[crate::cdr::CDR_LE_HEADER.len()..]);
            if writers[topic].write(Raw(body), None).is_err() {
                c.writes_refused.fetch_add(1, Ordering::Relaxed);
            }
        };
        match item {
            Item::Step(_) if !read.iter().any(|r| *r) => {
                c.unheard.fetch_add(1, Ordering::Relaxed);
            }
            Item::Step(s) => {
                let f = Frame {
                    time_ns: s.time_ns,
                    p_d: s.p_d,
                    target: s.target,
                    agents: &s.agents,
                    slots: &s.slots,
                    links: &s.links,
                };
                encoder.frame(&f, write);
                c.published.fetch_add(1, Ordering::Relaxed);
            }
            Item::Event(json) => encoder.event(&json, write),
        }
        next = match rx.try_recv() {
            Ok(item) => Some(item),
            Err(std::sync::mpsc::TryRecvError::Empty) => {
                std::thread::sleep(DRAIN_PAUSE);
                rx.recv().ok()
            }
            Err(std::sync::mpsc::TryRecvError::Disconnected) => None,
        };
    }
    for w in &writers {
        let _ = w.wait_for_acknowledgments(ACK_WAIT);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn env<'a>(vars: &'a [(&'a str, &'a str)]) -> impl Fn(&str) -> Option<String> + 'a {
        move |k| {
            vars.iter()
                .find(|(n, _)| *n == k)
                .map(|(_, v)| v.to_string())
        }
    }

    #[test]
    fn discovery_is_localhost_only_unless_asked_for_the_subnet() {
        let o = Options::from_env(env(&[])).unwrap();
        assert_eq!(
            o,
            Options {
                domain_id: 0,
                range: DiscoveryRange::Localhost
            }
        );
        let subnet = [
            ("ROS_AUTOMATIC_DISCOVERY_RANGE", "SUBNET"),
            ("ROS_DOMAIN_ID", "42"),
        ];
        let o = Options::from_env(env(&subnet)).unwrap();
        assert_eq!((o.domain_id, o.range), (42, DiscoveryRange::Subnet));
        let legacy = [("ROS_LOCALHOST_ONLY", "0")];
        assert_eq!(
            Options::from_env(env(&legacy)).unwrap().range,
            DiscoveryRange::Subnet
        );
        let both = [
            ("ROS_LOCALHOST_ONLY", "0"),
            ("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST"),
        ];
        assert_eq!(
            Options::from_env(env(&both)).unwrap().range,
            DiscoveryRange::Localhost
        );
    }

    #[test]
    fn every_offered_step_is_counted_and_without_a_reader_none_is_encoded_or_written() {
        let scene = Scene {
            n_agents: 3,
            edges: vec![(0, 1), (1, 2)],
            leader_links: vec![0],
            target_radius_m: 1.0,
        };
        // A domain of its own (localhost only), away from the default 0.
        let domain_id = 1 + (std::process::id() % 200) as u16;
        let options = Options {
            domain_id,
            range: DiscoveryRange::Localhost,
        };
        let mut p = Publisher::start(scene, options, || {}).expect("joins the domain");
        let agents = [AgentPose {
            position: [0.0; 3],
            attitude: [0.0; 3],
        }; 3];
        let offers = 20 * QUEUE_STEPS as u64;
        for k in 0..offers {
            p.offer(&Frame {
                time_ns: k * 10_000_000,
                p_d: [0.0; 3],
                target: [0.0; 3],
                agents: &agents,
                slots: &[[0.0; 3]; 3],
                links: &[LinkState::Up, LinkState::Stale],
            });
        }
        let s = p.finish();
        assert_eq!(s.offered, offers);
        assert_eq!(s.published + s.unheard + s.dropped, offers, "{s:?}");
        // Nobody reads this domain: nothing is encoded or written (an e2e test in
        // tests/tests/ros2.rs has a reader receive every step).
        assert_eq!(s.published, 0, "{s:?}");
        assert!(s.unheard > 0, "{s:?}");
    }

    #[test]
    fn a_bad_domain_or_range_names_the_variable() {
        let e = Options::from_env(env(&[("ROS_DOMAIN_ID", "300")])).unwrap_err();
        assert_eq!(e.variable, "ROS_DOMAIN_ID");
        let e = Options::from_env(env(&[("ROS_AUTOMATIC_DISCOVERY_RANGE", "OFF")])).unwrap_err();
        assert_eq!(e.variable, "ROS_AUTOMATIC_DISCOVERY_RANGE");
    }
}
