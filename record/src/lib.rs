//! The recorder: turns the per-step messages of a run (reference frame, plant truths, control
//! commands) into `summary.json` (metrics computed on every step) and hands every step to the
//! run's outputs, each a [`Sink`]: `trajectory.csv` (decimated), `run.mcap` and the rosbag2 (the
//! decimated steps and the injections) on the writer thread; the live Foxglove view, the live
//! ROS 2 topics and the Zenoh export (added by the runtime, [`Recorder::add_sink`]) at every step,
//! without waiting.
//!
//! Both runners feed it the same messages, so the files of an in-process run and of a lockstep run
//! over iceoryx2 are byte-identical when the trajectories are.
//!
//! The crate `formation-record` depends on the scenario model and the wire messages
//! (`formation-config`), not on the runtime that feeds it; the runtime re-exports it as
//! `formation_runtime::record`. [`rng`] is the seeded generator of coverage samples, generated
//! graphs and sweeps.

pub mod coverage;
pub mod csv;
mod fanout;
#[cfg(feature = "foxglove")]
pub mod live;
pub mod mcap;
#[cfg(feature = "foxglove")]
mod mcap_scene;
pub mod metrics;
pub mod recovery;
pub mod rng;
#[cfg(feature = "ros2")]
pub mod ros2;
pub mod separation;
pub mod sink;
pub mod summary;
pub mod table;
mod writer;

/// What `--foxglove` says in a build without the cargo feature `foxglove`.
pub const NO_FOXGLOVE: &str =
    "--foxglove: this build has no Foxglove view (build the orchestrator with its default feature `foxglove`)";

/// What `--ros2` and `--record rosbag2` say in a build without the cargo feature `ros2`.
pub const NO_ROS2: &str =
    "--ros2, --record rosbag2: this build has no ROS 2 view (build the orchestrator with its default feature `ros2`)";

pub use metrics::Divergence;
pub use sink::{Cadence, Sink, Step};
pub use summary::Summary;

use formation_config::protocol::wire::{ControlCommand, PlantTruth, ReferenceFrame};
use formation_config::{Scenario, Variant};
use std::path::{Path, PathBuf};

/// A recording format besides `trajectory.csv` and `summary.json` (`--record`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Format {
    /// `DIR/run.mcap`: every output step and injection as JSON messages with JSON Schemas, one
    /// channel per agent and kind (docs/formats.md); opens in Foxglove.
    Mcap,
    /// `DIR/rosbag2/`: a rosbag2 folder (`metadata.yaml`, MCAP storage, CDR) with the ROS 2
    /// topics of `--ros2`, for `ros2 bag info/play` (docs/ros2.md; feature `ros2`).
    Rosbag2,
}

/// Which files a [`Recorder`] writes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Outputs {
    /// `trajectory.csv` (sweeps need only `summary.json`).
    pub trajectory: bool,
    /// `run.mcap`.
    pub mcap: bool,
    /// `--foxglove ADDR`: serve the live view there (feature `foxglove`).
    pub foxglove: Option<LiveOptions>,
    /// `DIR/rosbag2/` (feature `ros2`).
    pub rosbag2: bool,
    /// `--ros2`: publish on DDS (feature `ros2`).
    pub ros2: Option<Ros2Options>,
}

/// How the live ROS 2 topics start (`--ros2`); the domain and discovery range come from ROS 2's
/// environment variables.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ros2Options {
    /// `--ros2-wait S`: seconds to wait for a subscriber before the run starts (0: none).
    pub wait_s: f64,
}

/// Where the live Foxglove view is served and how long the run waits for a first viewer.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LiveOptions {
    /// `--foxglove ADDR`.
    pub addr: std::net::SocketAddr,
    /// `--foxglove-wait S`: seconds to wait for a viewer before the run starts (0: none).
    pub wait_s: f64,
}

impl Outputs {
    /// `trajectory.csv` and the files of `formats`.
    pub fn with(formats: &[Format]) -> Outputs {
        Outputs {
            trajectory: true,
            mcap: formats.contains(&Format::Mcap),
            foxglove: None,
            rosbag2: formats.contains(&Format::Rosbag2),
            ros2: None,
        }
    }
}

/// Writes the outputs of one run.
pub struct Recorder {
    /// Every output of the run ([`Sink`]s).
    out: fanout::Fanout,
    /// Formation error of each agent at the step recorded last, m (the steps' view).
    errors: Vec<f64>,
    metrics: metrics::Metrics,
    decimation: u64,
    out_dir: PathBuf,
    scenario: String,
    variant: Variant,
    mode: &'static str,
    dt: f64,
    timing: Option<serde_json::Value>,
    export: Option<serde_json::Value>,
    /// Per-step worst formation error and violations, for the events' recovery.
    series: recovery::Series,
    /// The scenario's events and graph.
    events: Vec<formation_config::scenario::events::Event>,
    timeline: formation_config::scenario::events::Timeline,
    topology: formation_config::scenario::graph::Topology,
    /// What a live run added: runtime events, the supervision's incidents, restarts per agent.
    runtime_events: Vec<formation_config::protocol::messages::RuntimeEvent>,
    incidents: Vec<recovery::Mark>,
    restarts: Vec<u32>,
    checkpoints_refused: Vec<u32>,
    /// Multi-host runs: each agent's host at the end (empty: one machine).
    agent_hosts: Vec<String>,
}

impl Recorder {
    /// Creates `out_dir` and `trajectory.csv` in it.
    pub fn create(
        s: &Scenario,
        variant: Variant,
        mode: &'static str,
        out_dir: &Path,
    ) -> std::io::Result<Recorder> {
        Recorder::create_with(s, variant, mode, out_dir, Outputs::with(&[]))
    }

    /// Creates `out_dir` and the files of `outputs` in it.
    pub fn create_with(
        s: &Scenario,
        variant: Variant,
        mode: &'static str,
        out_dir: &Path,
        outputs: Outputs,
    ) -> std::io::Result<Recorder> {
        formation_config::node::files::ensure_private_dir(out_dir)?;
        let csv_path = out_dir.join("trajectory.csv");
        let mcap_path = out_dir.join(mcap::FILE_NAME);
        if !outputs.mcap {
            // A recording of an earlier run in the same folder would not match this run.
            match std::fs::remove_file(&mcap_path) {
                Err(e) if e.kind() != std::io::ErrorKind::NotFound => return Err(e),
                _ => {}
            }
        }
        // Every output, in the order the fan-out hands a step to them: the live views on the
        // run loop's thread, the files on the writer thread.
        let mut sinks: Vec<Box<dyn Sink>> = Vec::new();
        #[cfg(feature = "foxglove")]
        if let Some(o) = outputs.foxglove {
            sinks.push(Box::new(live::LiveFeed::start(o, s)?));
        }
        #[cfg(not(feature = "foxglove"))]
        if outputs.foxglove.is_some() {
            return Err(std::io::Error::other(NO_FOXGLOVE));
        }
        #[cfg(feature = "ros2")]
        {
            if !outputs.rosbag2 {
                ros2::remove_stale(out_dir)?;
            }
            if let Some(o) = outputs.ros2 {
                sinks.push(Box::new(ros2::LiveRos2::start(o, s)?));
            }
        }
        #[cfg(not(feature = "ros2"))]
        if outputs.ros2.is_some() || outputs.rosbag2 {
            return Err(std::io::Error::other(NO_ROS2));
        }
        if outputs.trajectory {
            sinks.push(Box::new(csv::RowWriter::create(&csv_path, s)?));
        }
        if outputs.mcap {
            sinks.push(Box::new(mcap::McapSink::create(&mcap_path, s, variant)?));
        }
        #[cfg(feature = "ros2")]
        if outputs.rosbag2 {
            sinks.push(Box::new(ros2::BagSink::create(out_dir, s)?));
        }
        Ok(Recorder {
            out: fanout::Fanout::new(sinks)?,
            errors: Vec::with_capacity(s.n_agents()),
            metrics: metrics::Metrics::new(s),
            decimation: s.output_decimation(),
            out_dir: out_dir.to_path_buf(),
            scenario: s.name.clone(),
            variant,
            mode,
            dt: s.simulation.dt_s,
            timing: None,
            export: None,
            series: recovery::Series::with_capacity(
                s.n_steps() as usize,
                s.metrics.safety_distance_m,
            ),
            events: s.events.clone(),
            timeline: s.timeline(),
            topology: formation_config::scenario::graph::Topology::from_scenario(s),
            runtime_events: Vec::new(),
            incidents: Vec::new(),
            restarts: vec![0; s.n_agents()],
            checkpoints_refused: vec![0; s.n_agents()],
            agent_hosts: Vec::new(),
        })
    }

    /// Records step k. Returns the divergence if this step is where the run diverged (the first one).
    pub fn record(
        &mut self,
        step: u64,
        reference: &ReferenceFrame,
        truths: &[PlantTruth],
        commands: &[ControlCommand],
    ) -> std::io::Result<Option<Divergence>> {
        let div = self.metrics.record(step, reference, truths, commands);
        let (worst, violations) = self
            .metrics
            .agents
            .iter()
            .fold((0.0f64, 0u64), |(w, v), a| {
                (
                    w.max(a.last_error),
                    v + a.attitude_violations + a.rate_violations,
                )
            });
        self.series.push(worst, violations);
        if let Some(d) = self.metrics.separation.last {
            self.series.push_separation(d);
        }
        let output = step.is_multiple_of(self.decimation) || div.is_some();
        if output || self.out.takes_every_step() {
            self.errors.clear();
            self.errors
                .extend(self.metrics.agents.iter().map(|a| a.last_error));
            let s = Step {
                step,
                reference,
                truths,
                commands,
                errors: &self.errors,
            };
            self.out.step(&s, output)?;
        }
        Ok(div)
    }

    /// Hands an injection (a line of `events.jsonl`) to every output at the step it applies
    /// (`run.mcap`, the rosbag2 and the live views show the accepted ones).
    pub fn event(&mut self, line: &serde_json::Value) -> std::io::Result<()> {
        self.out.event(line)
    }

    /// Adds an output: it gets the steps from the next one on (the Zenoh export of
    /// `formation run --zenoh-listen`, started once the run's services exist).
    pub fn add_sink(&mut self, sink: Box<dyn Sink>) -> std::io::Result<()> {
        self.out.add(sink)
    }

    /// Sets the `timing` object of `summary.json` (realtime runs).
    pub fn set_timing(&mut self, timing: serde_json::Value) {
        self.timing = Some(timing);
    }

    /// Sets the `export` object of `summary.json` (runs with `--zenoh-listen`).
    pub fn set_export(&mut self, export: serde_json::Value) {
        self.export = Some(export);
    }

    /// Checkpoints refused per agent (damaged, another agent's or run's): restarted cold.
    pub fn set_checkpoints_refused(&mut self, refused: Vec<u32>) {
        self.checkpoints_refused = refused;
    }

    /// Multi-host runs: the host of every agent at the end of the run (`summary.json`
    /// `agents[i].host`).
    pub fn set_agent_hosts(&mut self, hosts: Vec<String>) {
        self.agent_hosts = hosts;
    }

    /// Live fault and delay injections: listed in `events[]` like the same events of a replay.
    pub fn add_events(&mut self, events: &[formation_config::scenario::events::Event]) {
        self.events.extend_from_slice(events);
    }

    /// What a live run added to its timeline: runtime events (live crashes, hangs, links, losses,
    /// agents taken down), the supervision's incidents, restarts per agent under the policy.
    pub fn set_runtime(
        &mut self,
        events: Vec<formation_config::protocol::messages::RuntimeEvent>,
        incidents: Vec<recovery::Mark>,
        restarts: Vec<u32>,
    ) {
        for e in &events {
            e.apply(&mut self.timeline);
        }
        self.runtime_events = events;
        self.incidents = incidents;
        self.restarts = restarts;
    }

    /// Flushes the files written so far (used when a run is interrupted).
    pub fn flush(&mut self) -> std::io::Result<()> {
        self.out.flush()
    }

    /// Finishes every output and writes `summary.json`; returns the summary.
    pub fn finish(mut self, steps: u64, wall_time_s: f64) -> std::io::Result<Summary> {
        self.out.finish()?;
        let mut summary = summary::Summary::build(
            &self.metrics,
            &self.scenario,
            self.variant,
            self.mode,
            self.dt,
            steps,
            wall_time_s,
        );
        summary.timing = self.timing.take();
        summary.export = self.export.take();
        let marks = recovery::marks(&self.events, &self.runtime_events, &self.incidents, self.dt);
        summary.events = self.series.measure(&marks, self.dt);
        if !self.timeline.is_empty() {
            summary.connectivity = Some(recovery::connectivity(
                &self.topology,
                &self.timeline,
                steps,
                self.dt,
            ));
        }
        for (a, r) in summary.agents.iter_mut().zip(&self.restarts) {
            a.restarts = *r;
        }
        for (a, r) in summary.agents.iter_mut().zip(&self.checkpoints_refused) {
            a.checkpoints_refused = *r;
        }
        for (a, h) in summary.agents.iter_mut().zip(&self.agent_hosts) {
            a.host = Some(h.clone());
        }
        summary.write(&self.out_dir.join("summary.json"))?;
        Ok(summary)
    }
}
