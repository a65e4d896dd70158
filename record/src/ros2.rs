//! The ROS 2 view of a run (feature `ros2`, crate `formation-ros2`; docs/ros2.md):
//! `--record rosbag2` writes `DIR/rosbag2/` (a rosbag2 folder: `metadata.yaml` and
//! `rosbag2_0.mcap`) on the recorder's writer thread, from the steps `trajectory.csv` records;
//! `--ros2` publishes the same messages live on DDS from those steps, through a bounded queue that
//! never holds the run back (a full queue drops the step, counted).

use super::sink::{Cadence, Sink, Step};
use formation_config::protocol::wire::PlantTruth;
use formation_config::scenario::events::{Event, Timeline};
use formation_config::Scenario;
use formation_ros2::bag::BagWriter;
use formation_ros2::{AgentPose, Encoder, Frame, LinkState, Scene};
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

/// Folder of the rosbag2 recording in the run directory (also the bag's name).
pub const BAG_DIR: &str = "rosbag2";
/// The MCAP file of the recording (rosbag2 names it `<bag>_0.mcap`).
pub const BAG_FILE: &str = "rosbag2_0.mcap";
/// rosbag2's metadata file.
pub const BAG_METADATA: &str = "metadata.yaml";

/// The scene of scenario `s`: graph edges (0-based, sorted), agents linked to the leader, target
/// radius.
pub fn scene_of(s: &Scenario) -> Scene {
    Scene {
        n_agents: s.n_agents(),
        edges: formation_config::view::edges(s),
        leader_links: formation_config::view::leader_links(s),
        target_radius_m: s.metrics.target_radius_m,
    }
}

/// Builds [`Frame`]s from the recorder's records: poses, slots, and the state of every edge from
/// the run's timeline (the scenario's events and the injections so far).
pub struct Frames {
    edges: Vec<(usize, usize)>,
    timeline: Timeline,
    dt_ns: u64,
    agents: Vec<AgentPose>,
    slots: Vec<[f64; 3]>,
    links: Vec<LinkState>,
}

impl Frames {
    /// For scenario `s`.
    pub fn new(s: &Scenario) -> Frames {
        Frames {
            edges: scene_of(s).edges,
            timeline: s.timeline(),
            dt_ns: dt_ns(s),
            agents: Vec::with_capacity(s.n_agents()),
            slots: Vec::with_capacity(s.n_agents()),
            links: Vec::new(),
        }
    }

    /// Simulation time of step k, ns.
    pub fn time_ns(&self, step: u64) -> u64 {
        step * self.dt_ns
    }

    /// An accepted injection (a line of `events.jsonl`): its event joins the timeline.
    pub fn injection(&mut self, line: &serde_json::Value) {
        let event = line
            .get("scenario_event")
            .and_then(|e| serde_json::from_value::<Event>(e.clone()).ok());
        if let Some(e) = event {
            self.timeline.add(&e);
        }
    }

    /// The frame of step `step`.
    pub fn frame(
        &mut self,
        step: u64,
        p_d: [f64; 3],
        target: [f64; 3],
        offsets: &[[f64; 3]],
        truths: &[PlantTruth],
    ) -> Frame<'_> {
        self.agents.clear();
        self.agents.extend(truths.iter().map(|t| AgentPose {
            position: t.state.position,
            attitude: t.state.attitude,
        }));
        self.slots.clear();
        self.slots.extend(
            offsets
                .iter()
                .map(|o| [p_d[0] + o[0], p_d[1] + o[1], p_d[2] + o[2]]),
        );
        let timeline = &self.timeline;
        self.links.clear();
        self.links.extend(
            self.edges
                .iter()
                .map(|&(a, b)| LinkState::at(timeline, a, b, step)),
        );
        Frame {
            time_ns: step * self.dt_ns,
            p_d,
            target,
            agents: &self.agents,
            slots: &self.slots,
            links: &self.links,
        }
    }
}

/// dt in whole nanoseconds.
fn dt_ns(s: &Scenario) -> u64 {
    (s.simulation.dt_s * 1e9).round() as u64
}

/// The `/formation/events` text of an injection line and its step (`None`: a rejection): the
/// JSON of `run.mcap`'s `/events`.
pub fn event_text(line: &serde_json::Value) -> Option<(u64, String)> {
    super::sink::event_message(line).map(|(step, e)| (step, e.to_string()))
}

/// `--record rosbag2`: the recording, written on the recorder's writer thread.
pub struct BagSink {
    dir: PathBuf,
    bag: BagWriter<BufWriter<File>>,
    encoder: Encoder,
    frames: Frames,
}

impl BagSink {
    /// Creates `run_dir/rosbag2/` (owner-only) and its MCAP file.
    pub fn create(run_dir: &Path, s: &Scenario) -> std::io::Result<BagSink> {
        let dir = run_dir.join(BAG_DIR);
        formation_config::node::files::ensure_private_dir(&dir)?;
        let file = BufWriter::with_capacity(
            1 << 20,
            formation_config::node::files::create_replacing(&dir.join(BAG_FILE))?,
        );
        let encoder = Encoder::new(scene_of(s));
        let bag = BagWriter::create(file, BAG_FILE, encoder.topics())?;
        Ok(BagSink {
            dir,
            bag,
            encoder,
            frames: Frames::new(s),
        })
    }

    /// Records the messages of one output step.
    pub(crate) fn write_step(&mut self, rows: &Step<'_>) -> std::io::Result<()> {
        let Some(first) = rows.truths.first() else {
            return Ok(());
        };
        let step = first.state.step;
        let f = self
            .frames
            .frame(step, rows.p_d(), rows.target(), rows.offsets(), rows.truths);
        let (bag, time_ns) = (&mut self.bag, f.time_ns);
        let mut result = Ok(());
        self.encoder.frame(&f, |topic, bytes| {
            if result.is_ok() {
                result = bag.write(topic, time_ns, bytes);
            }
        });
        result
    }

    /// Records an injection line (a rejection records nothing).
    pub(crate) fn write_event(&mut self, line: &serde_json::Value) -> std::io::Result<()> {
        self.frames.injection(line);
        let Some((step, text)) = event_text(line) else {
            return Ok(());
        };
        let (bag, time_ns) = (&mut self.bag, self.frames.time_ns(step));
        let mut result = Ok(());
        self.encoder.event(&text, |topic, bytes| {
            result = bag.write(topic, time_ns, bytes);
        });
        result
    }

    /// Closes the MCAP file and writes `metadata.yaml` beside it.
    pub fn finish(self) -> std::io::Result<()> {
        let (file, metadata, _) = self.bag.finish()?;
        use std::io::Write;
        file.into_inner().map_err(|e| e.into_error())?.flush()?;
        formation_config::node::files::write_atomic(
            &self.dir.join(BAG_METADATA),
            metadata.as_bytes(),
        )
    }
}

impl Sink for BagSink {
    fn cadence(&self) -> Cadence {
        Cadence::Output
    }

    fn step(&mut self, rows: &Step<'_>) -> std::io::Result<()> {
        self.write_step(rows)
    }

    fn event(&mut self, line: &serde_json::Value) -> std::io::Result<()> {
        self.write_event(line)
    }

    fn finish(self: Box<Self>) -> std::io::Result<()> {
        BagSink::finish(*self)
    }
}

/// Removes the rosbag2 folder an earlier run left in `run_dir` (a run without
/// `--record rosbag2` must not leave a recording that is not its own).
pub fn remove_stale(run_dir: &Path) -> std::io::Result<()> {
    let dir = run_dir.join(BAG_DIR);
    for f in [BAG_FILE, BAG_METADATA] {
        match std::fs::remove_file(dir.join(f)) {
            Err(e) if e.kind() != std::io::ErrorKind::NotFound => return Err(e),
            _ => {}
        }
    }
    match std::fs::remove_dir(&dir) {
        Err(e) if e.kind() != std::io::ErrorKind::NotFound => Err(e),
        _ => Ok(()),
    }
}

/// `--ros2`: the live publisher and what the recorder needs to feed it.
pub struct LiveRos2 {
    publisher: formation_ros2::dds::Publisher,
    frames: Frames,
    decimation: u64,
}

impl LiveRos2 {
    /// Joins the DDS domain of the environment (`ROS_DOMAIN_ID`, discovery range) and says so on
    /// standard error; with `wait_s` > 0, waits that long at most for a subscriber.
    pub fn start(o: super::Ros2Options, s: &Scenario) -> std::io::Result<LiveRos2> {
        let options = env_options().map_err(std::io::Error::other)?;
        let publisher = formation_ros2::dds::Publisher::start(
            scene_of(s),
            options,
            formation_config::node::sched::background_thread,
        )
        .map_err(|e| std::io::Error::new(std::io::ErrorKind::AddrNotAvailable, e))?;
        eprintln!(
            "ros2: publishing on DDS domain {} ({}): /formation/agent_<i>/pose, /tf, /formation/markers, /formation/reference, /formation/events, /clock (docs/ros2.md)",
            publisher.domain_id(),
            match options.range {
                formation_ros2::dds::DiscoveryRange::Localhost => "discovery on this machine only",
                formation_ros2::dds::DiscoveryRange::Subnet => "discovery on every network interface",
            }
        );
        if o.wait_s > 0.0 {
            eprintln!(
                "ros2: waiting up to {} s for a subscriber (--ros2-wait)",
                o.wait_s
            );
            let joined =
                publisher.wait_for_subscriber(std::time::Duration::from_secs_f64(o.wait_s));
            eprintln!(
                "ros2: {}; the run starts",
                if joined {
                    "a subscriber joined"
                } else {
                    "no subscriber joined"
                }
            );
        }
        Ok(LiveRos2 {
            publisher,
            frames: Frames::new(s),
            decimation: s.output_decimation(),
        })
    }
}

/// The live topics take the steps `trajectory.csv` records at its decimation (not the step of a
/// divergence), offered without waiting; an accepted injection joins the timeline and goes out
/// on `/formation/events`.
impl Sink for LiveRos2 {
    fn cadence(&self) -> Cadence {
        Cadence::Every
    }

    fn step(&mut self, s: &Step<'_>) -> std::io::Result<()> {
        if s.step.is_multiple_of(self.decimation) {
            let f = self
                .frames
                .frame(s.step, s.p_d(), s.target(), s.offsets(), s.truths);
            self.publisher.offer(&f);
        }
        Ok(())
    }

    fn event(&mut self, line: &serde_json::Value) -> std::io::Result<()> {
        self.frames.injection(line);
        if let Some((_, text)) = event_text(line) {
            self.publisher.event(text);
        }
        Ok(())
    }

    /// Publishes what is queued, leaves the domain and says what was sent.
    fn finish(self: Box<Self>) -> std::io::Result<()> {
        let s = self.publisher.finish();
        eprintln!(
            "ros2: published {} of {} output steps ({} while nobody read any topic, {} dropped by the full queue, {} DDS writes refused)",
            s.published, s.offered, s.unheard, s.dropped, s.writes_refused
        );
        Ok(())
    }
}

/// A ROS 2 environment variable that makes no sense ([`env_options`]).
pub use formation_ros2::dds::EnvError;

/// The DDS options of the environment (`ROS_DOMAIN_ID`, `ROS_AUTOMATIC_DISCOVERY_RANGE`,
/// `ROS_LOCALHOST_ONLY`).
pub fn env_options() -> Result<formation_ros2::dds::Options, EnvError> {
    formation_ros2::dds::Options::from_env(|k| std::env::var(k).ok())
}
