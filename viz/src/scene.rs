//! The 3D scene of a run as Foxglove's well-known messages, built by pure functions from
//! [`Frame`]s: what the live view serves and `run.mcap` records, message for message.
//!
//! World frame `world`: the paper's inertial frame (x, y horizontal, z up, metres). Per scene
//! frame (every [`scene_decimation`] steps, [`SCENE_RATE_HZ`] of simulation time):
//!
//! | topic | schema | content |
//! |---|---|---|
//! | `/tf` | `foxglove.FrameTransforms` | `world` -> `agent/{i}`: P_i and the attitude A_i as a quaternion |
//! | `/scene/agents` | `foxglove.SceneUpdate` | each quadrotor as a body in its own frame (two arms, four rotors, a heading arrow, its id), its trail (the last [`TRAIL_S`] s), its camera footprint on the ground (radius P_i3 tan(theta_S / 2)) and a line to its slot; grey while its process is down |
//! | `/scene/mission` | `foxglove.SceneUpdate` | the virtual leader P_d, the slots P_d + Delta_i0, the target T_g and its disk (radius R of the coverage metric) |
//! | `/scene/links` | `foxglove.SceneUpdate` | the graph's edges coloured by state ([`LinkState`]: up green, stale amber, down red) and the leader's links (grey) |
//! | `/scene/events` | `foxglove.SceneUpdate` | a marker (text and a red halo) for each event of the last [`EVENT_MARKER_S`] s, at the agent or link it hits |
//! | `/log` | `foxglove.Log` | one line per event, logged at the step it applies |
//! | `/agent/{i}/plot` | `formation.AgentPlot` (JSON) | the numbers Plot panels want: formation error, Gamma-hat, delta-hat and the true faults, constraint margins, delay, whether the agent is up, P_i |
//!
//! Every SceneUpdate replaces all entities of its topic (a deletion of everything, then the
//! entities), so a viewer that joins late or seeks in a recording shows the right scene at once.
//! Log times are the simulation time t_k = k dt in nanoseconds.

use crate::frame::{AgentSample, Frame, Limits};
use formation_config::scenario::events::{Event, EventKind, Timeline};
pub use formation_config::view::LinkState;
use formation_config::view::{agent_rgb, quaternion_xyzw, DOWN_RGB};
use formation_config::Scenario;
use foxglove::messages::{
    line_primitive, log, scene_entity_deletion, ArrowPrimitive, Color, CubePrimitive,
    CylinderPrimitive, Duration, FrameTransform, FrameTransforms, LinePrimitive, Log, Point3, Pose,
    Quaternion, SceneEntity, SceneEntityDeletion, SceneUpdate, SpherePrimitive, TextPrimitive,
    Timestamp, Vector3,
};
use serde::Serialize;
use std::collections::VecDeque;

/// Simulation-time rate of the scene, Hz: 25 frames per simulated second (every 40 steps at
/// dt = 1 ms), rounded up to a multiple of the `trajectory.csv` decimation so that every scene
/// frame is also a row of `trajectory.csv`.
pub const SCENE_RATE_HZ: f64 = 25.0;
/// Length of the trail drawn behind each quadrotor, s of simulation time.
pub const TRAIL_S: f64 = 3.0;
/// How long an event's marker stays in the scene, s of simulation time.
pub const EVENT_MARKER_S: f64 = 4.0;
/// Arm length of the drawn quadrotor (centre to rotor), m: a display size of a 450 mm-class
/// frame (the paper's model has no geometry beyond mass and inertia).
pub const ARM_M: f64 = 0.225;
/// Diameter of a drawn rotor disk, m (display size).
pub const ROTOR_DIAMETER_M: f64 = 0.2;
/// The fixed frame of the scene.
pub const WORLD_FRAME: &str = "world";
/// Name of the JSON schema of `/agent/{i}/plot`.
pub const PLOT_SCHEMA_NAME: &str = "formation.AgentPlot";

/// Frame of agent `id` (1-based), the child of `world` in `/tf`.
pub fn agent_frame(id: usize) -> String {
    format!("agent/{id}")
}

/// Steps between two scene frames of scenario `s` (see [`SCENE_RATE_HZ`]).
pub fn scene_decimation(s: &Scenario) -> u64 {
    let out = s.output_decimation();
    let want = (1.0 / (SCENE_RATE_HZ * s.simulation.dt_s)).round().max(1.0) as u64;
    want.div_ceil(out) * out
}

/// The state of the edge {a, b} (0-based) at step k, from the run's timeline.
pub fn link_state(timeline: &Timeline, a: usize, b: usize, k: u64) -> LinkState {
    LinkState::at(timeline, a, b, k)
}

/// The rotation of ZYX Euler angles A = [phi, theta, psi] (body to inertial, R = Rz Ry Rx as
/// the plant's eq. (1)) as a unit quaternion.
pub(crate) fn quaternion(a: [f64; 3]) -> Quaternion {
    let [x, y, z, w] = quaternion_xyzw(a);
    Quaternion { x, y, z, w }
}

/// A point of the scene rotated by a quaternion (for the top-view figure and the tests).
pub(crate) fn rotate(q: &Quaternion, v: [f64; 3]) -> [f64; 3] {
    // v' = v + 2 w (u x v) + 2 u x (u x v), u = (x, y, z).
    let u = [q.x, q.y, q.z];
    let cross = |a: [f64; 3], b: [f64; 3]| {
        [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ]
    };
    let t = cross(u, v);
    let t = [2.0 * t[0], 2.0 * t[1], 2.0 * t[2]];
    let c = cross(u, t);
    [
        v[0] + q.w * t[0] + c[0],
        v[1] + q.w * t[1] + c[1],
        v[2] + q.w * t[2] + c[2],
    ]
}

/// Colour of agent `id` (1-based): the palette of the figures, cycled.
pub(crate) fn agent_color(id: usize, alpha: f64) -> Color {
    let [r, g, b] = agent_rgb(id);
    rgba(r, g, b, alpha)
}

fn rgba(r: u8, g: u8, b: u8, a: f64) -> Color {
    Color {
        r: f64::from(r) / 255.0,
        g: f64::from(g) / 255.0,
        b: f64::from(b) / 255.0,
        a,
    }
}

/// Colour of a quadrotor whose process is down.
fn down_color(alpha: f64) -> Color {
    let [r, g, b] = DOWN_RGB;
    rgba(r, g, b, alpha)
}

/// Colour of an edge in `state`.
pub(crate) fn link_color(state: LinkState) -> Color {
    let ([r, g, b], alpha) = state.rgba();
    rgba(r, g, b, f64::from(alpha))
}

/// An event of the run and the step it applies at.
#[derive(Debug, Clone, PartialEq)]
pub struct EventMark {
    /// First step the event applies to.
    pub step: u64,
    /// The event (agent ids 1-based).
    pub event: Event,
}

impl EventMark {
    /// One line saying what happens (the `/log` message and the marker's text).
    pub fn describe(&self, dt: f64) -> String {
        let e = &self.event;
        let t = self.step as f64 * dt;
        let agent = e.agent.unwrap_or(0);
        let what = match e.kind {
            EventKind::Fault => {
                let g = e.gamma.unwrap_or([1.0; 3]);
                let d = e.delta.unwrap_or([0.0; 3]);
                format!(
                    "actuator fault of agent {agent}: Gamma = [{}, {}, {}], delta = [{}, {}, {}] N m",
                    g[0], g[1], g[2], d[0], d[1], d[2]
                )
            }
            EventKind::Delay => format!(
                "delay of agent {agent}: tau = {} + {} sin({} t) s",
                e.base_s.unwrap_or(0.0),
                e.amplitude_s.unwrap_or(0.0),
                e.angular_rate_rad_s.unwrap_or(0.0)
            ),
            EventKind::Crash | EventKind::Hang => format!(
                "{} of agent {agent}, down {} s",
                e.kind.name(),
                e.down_s.unwrap_or(f64::INFINITY)
            ),
            EventKind::LinkDown | EventKind::LinkUp => {
                let [a, b] = e.agents.unwrap_or([0, 0]);
                let state = if e.kind == EventKind::LinkDown {
                    "down"
                } else {
                    "up"
                };
                format!("link {a}-{b} {state}")
            }
            EventKind::MessageLoss => match (e.from, e.to) {
                (Some(f), Some(t)) => format!(
                    "message loss {f} -> {t}, p = {}",
                    e.probability.unwrap_or(0.0)
                ),
                _ => format!(
                    "message loss on every edge, p = {}",
                    e.probability.unwrap_or(0.0)
                ),
            },
        };
        format!("t = {t:.3} s (step {}): {what}", self.step)
    }

    /// The short text of the marker in the scene.
    fn label(&self) -> String {
        let e = &self.event;
        match e.kind {
            EventKind::LinkDown | EventKind::LinkUp => {
                let [a, b] = e.agents.unwrap_or([0, 0]);
                format!("{} {a}-{b}", e.kind.name())
            }
            EventKind::MessageLoss => "message loss".into(),
            k => format!("{} {}", k.name(), e.agent.unwrap_or(0)),
        }
    }

    /// Severity in `/log`.
    fn level(&self) -> log::Level {
        match self.event.kind {
            EventKind::Crash | EventKind::Hang | EventKind::LinkDown | EventKind::Fault => {
                log::Level::Warning
            }
            _ => log::Level::Info,
        }
    }
}

/// What the scene knows of a run besides its frames: geometry, graph, timeline, limits.
#[derive(Debug, Clone)]
pub struct SceneConfig {
    /// Number of agents N.
    pub n: usize,
    /// Step dt, s.
    pub dt: f64,
    /// Steps between scene frames.
    pub decimation: u64,
    /// Radius R of the target's disk, m.
    pub target_radius_m: f64,
    /// tan(theta_S / 2) of the sensors (footprint radius = height x this).
    pub half_fov_tan: f64,
    /// Edges {a, b} of the graph, 0-based, a < b.
    pub edges: Vec<(usize, usize)>,
    /// Agents (0-based) the leader informs (b_i > 0).
    pub leader_links: Vec<usize>,
    /// Constraint limits (margins of `/agent/{i}/plot`).
    pub limits: Limits,
}

impl SceneConfig {
    /// The scene of scenario `s`.
    pub fn from_scenario(s: &Scenario) -> SceneConfig {
        SceneConfig {
            n: s.n_agents(),
            dt: s.simulation.dt_s,
            decimation: scene_decimation(s),
            target_radius_m: s.metrics.target_radius_m,
            half_fov_tan: (s.metrics.sensor_fov_deg.to_radians() * 0.5).tan(),
            edges: formation_config::view::edges(s),
            leader_links: formation_config::view::leader_links(s),
            limits: Limits::of(s),
        }
    }
}

/// `/agent/{i}/plot`: the numbers of agent i that Plot panels want, at one scene frame.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct AgentPlot {
    /// Simulation step k.
    pub step: u64,
    /// Simulation time t_k, s.
    pub t: f64,
    /// Agent id, 1-based.
    pub agent: usize,
    /// Whether the agent's process computes its command at this step.
    pub up: bool,
    /// Position P_i, m.
    pub position: [f64; 3],
    /// Formation error |P_i - P_d - Delta_i0|, m.
    pub formation_error_m: f64,
    /// Gamma-hat_i (diagonal), eq. (48).
    pub gamma_hat: [f64; 3],
    /// delta-hat_i, eq. (47), N m.
    pub delta_hat: [f64; 3],
    /// True Gamma_i.
    pub gamma: [f64; 3],
    /// True delta_i, N m.
    pub delta: [f64; 3],
    /// Attitude constraint margin C_i1bar - |A_i|, rad.
    pub attitude_margin_rad: f64,
    /// Rate constraint margin C_i2bar - |Omega_i|, rad/s.
    pub rate_margin_rad_s: f64,
    /// Delay tau_i(t_k), s.
    pub tau_s: f64,
}

/// JSON Schema of [`AgentPlot`].
pub fn plot_schema() -> serde_json::Value {
    let vec3 = |d: &str| serde_json::json!({"type": "array", "items": {"type": "number"}, "minItems": 3, "maxItems": 3, "description": d});
    let num = |d: &str| serde_json::json!({"type": "number", "description": d});
    serde_json::json!({
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": PLOT_SCHEMA_NAME,
        "description": "Agent i at one scene frame: the numbers Plot panels want.",
        "type": "object",
        "properties": {
            "step": {"type": "integer", "description": "simulation step k"},
            "t": num("simulation time t_k, s"),
            "agent": {"type": "integer", "description": "agent id, 1-based"},
            "up": {"type": "boolean", "description": "whether the agent's process computes its command at this step"},
            "position": vec3("position P_i, m"),
            "formation_error_m": num("formation error |P_i - P_d - Delta_i0|, m"),
            "gamma_hat": vec3("Gamma-hat_i (diagonal), eq. (48)"),
            "delta_hat": vec3("delta-hat_i, eq. (47), N m"),
            "gamma": vec3("true multiplicative fault Gamma_i"),
            "delta": vec3("true additive fault delta_i, N m"),
            "attitude_margin_rad": num("attitude constraint margin |A_iC| + margin - |A_i|, rad (negative: violated)"),
            "rate_margin_rad_s": num("rate constraint margin C_i2bar - |Omega_i|, rad/s (negative: violated)"),
            "tau_s": num("delay tau_i(t_k), s"),
        },
        "required": ["step", "t", "agent", "up", "position", "formation_error_m", "gamma_hat",
                     "delta_hat", "gamma", "delta", "attitude_margin_rad", "rate_margin_rad_s", "tau_s"],
    })
}

/// Everything one scene frame publishes.
#[derive(Debug, Clone, PartialEq)]
pub struct Scene {
    /// Step of the frame.
    pub step: u64,
    /// `/tf`.
    pub(crate) transforms: FrameTransforms,
    /// `/scene/agents`.
    pub(crate) agents: SceneUpdate,
    /// `/scene/mission`.
    pub(crate) mission: SceneUpdate,
    /// `/scene/links`.
    pub(crate) links: SceneUpdate,
    /// `/scene/events`.
    pub(crate) events: SceneUpdate,
    /// `/log`: the events that apply since the previous frame, each with its step.
    pub(crate) logs: Vec<(u64, Log)>,
    /// `/agent/{i}/plot`, agents 1..N.
    pub plots: Vec<AgentPlot>,
}

impl Scene {
    /// The position of agent `id` (1-based) in the world frame as `/tf` carries it, m.
    pub fn agent_translation(&self, id: usize) -> Option<[f64; 3]> {
        let frame = agent_frame(id);
        let t = self
            .transforms
            .transforms
            .iter()
            .find(|t| t.child_frame_id == frame)?;
        let p = t.translation.as_ref()?;
        Some([p.x, p.y, p.z])
    }
}

/// Builds the scene frame after frame: keeps the trails, the timeline and the events.
#[derive(Debug, Clone)]
pub struct SceneBuilder {
    cfg: SceneConfig,
    timeline: Timeline,
    /// Every event, in the order added (scenario events first, then injections).
    events: Vec<EventMark>,
    /// Positions at the last frames, per agent (at most `trail_len`).
    trails: Vec<VecDeque<[f64; 3]>>,
    trail_len: usize,
    /// Step of the last frame built (`None` before the first).
    last_step: Option<u64>,
}

fn v3(p: [f64; 3]) -> Vector3 {
    Vector3 {
        x: p[0],
        y: p[1],
        z: p[2],
    }
}

fn p3(p: [f64; 3]) -> Point3 {
    Point3 {
        x: p[0],
        y: p[1],
        z: p[2],
    }
}

fn pose(p: [f64; 3], q: Quaternion) -> Option<Pose> {
    Some(Pose {
        position: Some(v3(p)),
        orientation: Some(q),
    })
}

fn identity() -> Quaternion {
    Quaternion {
        x: 0.0,
        y: 0.0,
        z: 0.0,
        w: 1.0,
    }
}

fn at(p: [f64; 3]) -> Option<Pose> {
    pose(p, identity())
}

/// Simulation time of step k as a timestamp.
pub(crate) fn timestamp(step: u64, dt: f64) -> Timestamp {
    let ns = step_ns(step, dt);
    Timestamp::new((ns / 1_000_000_000) as u32, (ns % 1_000_000_000) as u32)
}

/// Simulation time of step k in nanoseconds (the log time of its messages).
pub fn step_ns(step: u64, dt: f64) -> u64 {
    step * (dt * 1e9).round() as u64
}

fn entity(id: String, frame_id: String, ts: Timestamp) -> SceneEntity {
    SceneEntity {
        timestamp: Some(ts),
        frame_id,
        id,
        lifetime: Some(Duration::new(0, 0)),
        ..SceneEntity::default()
    }
}

/// A SceneUpdate that first deletes every entity of its topic.
fn replace_all(entities: Vec<SceneEntity>, ts: Timestamp) -> SceneUpdate {
    SceneUpdate {
        deletions: vec![SceneEntityDeletion {
            timestamp: Some(ts),
            r#type: scene_entity_deletion::Type::All as i32,
            id: String::new(),
        }],
        entities,
    }
}

fn flat_disk(centre: [f64; 3], radius: f64, color: Color) -> CylinderPrimitive {
    CylinderPrimitive {
        pose: at(centre),
        size: Some(v3([2.0 * radius, 2.0 * radius, 0.01])),
        bottom_scale: 1.0,
        top_scale: 1.0,
        color: Some(color),
    }
}

fn sphere(centre: [f64; 3], diameter: f64, color: Color) -> SpherePrimitive {
    SpherePrimitive {
        pose: at(centre),
        size: Some(v3([diameter; 3])),
        color: Some(color),
    }
}

fn text(p: [f64; 3], s: String, size: f64, color: Color) -> TextPrimitive {
    TextPrimitive {
        pose: at(p),
        billboard: true,
        font_size: size,
        scale_invariant: false,
        color: Some(color),
        text: s,
    }
}

fn line(
    kind: line_primitive::Type,
    points: Vec<Point3>,
    thickness: f64,
    color: Color,
) -> LinePrimitive {
    LinePrimitive {
        r#type: kind as i32,
        pose: at([0.0; 3]),
        thickness,
        scale_invariant: false,
        points,
        color: Some(color),
        colors: Vec::new(),
        indices: Vec::new(),
    }
}

/// The body of quadrotor `id` in its own frame: two arms in an X, four rotors, a heading arrow.
fn body(id: usize, color: Color, ts: Timestamp) -> SceneEntity {
    let mut e = entity(format!("quad/{id}"), agent_frame(id), ts);
    e.frame_locked = true;
    let diag = std::f64::consts::FRAC_PI_4;
    for yaw in [diag, -diag] {
        e.cubes.push(CubePrimitive {
            pose: pose([0.0; 3], quaternion([0.0, 0.0, yaw])),
            size: Some(v3([2.0 * ARM_M, 0.03, 0.02])),
            color: Some(rgba(40, 40, 40, 1.0)),
        });
    }
    let r = ARM_M * std::f64::consts::FRAC_1_SQRT_2;
    for (sx, sy) in [(1.0, 1.0), (1.0, -1.0), (-1.0, 1.0), (-1.0, -1.0)] {
        e.cylinders.push(CylinderPrimitive {
            pose: at([sx * r, sy * r, 0.02]),
            size: Some(v3([ROTOR_DIAMETER_M, ROTOR_DIAMETER_M, 0.01])),
            bottom_scale: 1.0,
            top_scale: 1.0,
            color: Some(Color { a: 0.8, ..color }),
        });
    }
    e.arrows.push(ArrowPrimitive {
        pose: at([0.0, 0.0, 0.03]),
        shaft_length: 0.25,
        shaft_diameter: 0.02,
        head_length: 0.08,
        head_diameter: 0.06,
        color: Some(color),
    });
    // Beside the body (seen from above it would sit on the arms).
    e.texts
        .push(text([-0.3, -0.3, 0.3], id.to_string(), 0.3, color));
    e
}

impl SceneBuilder {
    /// A builder for a run of `cfg` whose timeline holds `events` (the scenario's `[[events]]`).
    pub fn new(cfg: SceneConfig, events: &[Event]) -> SceneBuilder {
        let span = (TRAIL_S / (cfg.dt * cfg.decimation as f64)).round() as usize;
        let mut b = SceneBuilder {
            timeline: Timeline::new(&[], cfg.dt),
            events: Vec::new(),
            trails: vec![VecDeque::with_capacity(span + 1); cfg.n],
            trail_len: span.max(2),
            last_step: None,
            cfg,
        };
        for e in events {
            b.add_event(e);
        }
        b
    }

    /// The builder of scenario `s` (its geometry, graph and `[[events]]`).
    pub fn for_scenario(s: &Scenario) -> SceneBuilder {
        SceneBuilder::new(SceneConfig::from_scenario(s), &s.events)
    }

    /// Its configuration.
    pub fn config(&self) -> &SceneConfig {
        &self.cfg
    }

    /// Adds an event to the timeline (an injection into a live run; before its step is built).
    pub fn add_event(&mut self, e: &Event) {
        self.timeline.add(e);
        self.events.push(EventMark {
            step: e.step(self.cfg.dt),
            event: e.clone(),
        });
    }

    /// The events known so far.
    pub fn events(&self) -> &[EventMark] {
        &self.events
    }

    /// Whether step k is a scene frame.
    pub fn is_frame(&self, k: u64) -> bool {
        k.is_multiple_of(self.cfg.decimation)
    }

    /// Takes frame `f` (the next scene frame) into the trails and builds its scene.
    pub fn build(&mut self, f: &Frame) -> Scene {
        self.push(f);
        self.emit(f)
    }

    /// Takes frame `f` into the trails without building its scene (a frame the live view skips).
    pub fn push(&mut self, f: &Frame) {
        for (trail, a) in self.trails.iter_mut().zip(&f.agents) {
            if trail.len() == self.trail_len {
                trail.pop_front();
            }
            if a.position.iter().all(|v| v.is_finite()) {
                trail.push_back(a.position);
            }
        }
    }

    /// The scene of frame `f`, already pushed; the `/log` lines of later scenes start after it.
    pub fn emit(&mut self, f: &Frame) -> Scene {
        let scene = self.scene(f);
        self.last_step = Some(f.step);
        scene
    }

    /// The scene of frame `f` with the trails as they are (pure: nothing changes).
    pub fn scene(&self, f: &Frame) -> Scene {
        let ts = timestamp(f.step, self.cfg.dt);
        let up: Vec<bool> = (0..f.agents.len())
            .map(|i| self.timeline.up(i, f.step))
            .collect();
        Scene {
            step: f.step,
            transforms: self.transforms(f, ts),
            agents: self.agents(f, &up, ts),
            mission: self.mission(f, ts),
            links: self.links(f, ts),
            events: self.markers(f, ts),
            logs: self.logs(f.step),
            plots: f
                .agents
                .iter()
                .enumerate()
                .map(|(i, a)| plot(f, i, a, up[i]))
                .collect(),
        }
    }

    fn transforms(&self, f: &Frame, ts: Timestamp) -> FrameTransforms {
        FrameTransforms {
            transforms: f
                .agents
                .iter()
                .enumerate()
                .map(|(i, a)| FrameTransform {
                    timestamp: Some(ts),
                    parent_frame_id: WORLD_FRAME.into(),
                    child_frame_id: agent_frame(i + 1),
                    translation: Some(v3(a.position)),
                    rotation: Some(quaternion(a.attitude)),
                })
                .collect(),
        }
    }

    fn agents(&self, f: &Frame, up: &[bool], ts: Timestamp) -> SceneUpdate {
        let mut out = Vec::with_capacity(4 * f.agents.len());
        for (i, a) in f.agents.iter().enumerate() {
            let id = i + 1;
            let color = |alpha| {
                if up[i] {
                    agent_color(id, alpha)
                } else {
                    down_color(alpha)
                }
            };
            out.push(body(id, color(1.0), ts));
            let mut trail = entity(format!("trail/{id}"), WORLD_FRAME.into(), ts);
            let points: Vec<Point3> = self.trails[i].iter().map(|p| p3(*p)).collect();
            if points.len() >= 2 {
                trail.lines.push(line(
                    line_primitive::Type::LineStrip,
                    points,
                    0.03,
                    color(0.8),
                ));
            }
            out.push(trail);
            let mut foot = entity(format!("footprint/{id}"), WORLD_FRAME.into(), ts);
            let radius = a.position[2].max(0.0) * self.cfg.half_fov_tan;
            if radius.is_finite() {
                foot.cylinders.push(flat_disk(
                    [a.position[0], a.position[1], 0.005],
                    radius,
                    color(0.15),
                ));
            }
            out.push(foot);
            if let Some(slot) = f.slots.get(i) {
                let mut err = entity(format!("error/{id}"), WORLD_FRAME.into(), ts);
                err.lines.push(line(
                    line_primitive::Type::LineStrip,
                    vec![p3(a.position), p3(*slot)],
                    0.01,
                    color(0.6),
                ));
                out.push(err);
            }
        }
        replace_all(out, ts)
    }

    fn mission(&self, f: &Frame, ts: Timestamp) -> SceneUpdate {
        let mut target = entity("target".into(), WORLD_FRAME.into(), ts);
        let t = f.target;
        target.cylinders.push(flat_disk(
            [t[0], t[1], 0.002],
            self.cfg.target_radius_m,
            rgba(60, 60, 60, 0.18),
        ));
        target
            .spheres
            .push(sphere([t[0], t[1], 0.15], 0.3, rgba(180, 20, 20, 1.0)));
        target.texts.push(text(
            [t[0] + 0.3, t[1] - 0.6, 0.5],
            "target".into(),
            0.25,
            rgba(180, 20, 20, 1.0),
        ));
        let mut leader = entity("leader".into(), WORLD_FRAME.into(), ts);
        leader
            .spheres
            .push(sphere(f.p_d, 0.18, rgba(20, 20, 20, 1.0)));
        leader.texts.push(text(
            [f.p_d[0] + 0.3, f.p_d[1] + 0.3, f.p_d[2] + 0.3],
            "P_d".into(),
            0.22,
            rgba(20, 20, 20, 1.0),
        ));
        let mut slots = entity("slots".into(), WORLD_FRAME.into(), ts);
        for (i, s) in f.slots.iter().enumerate() {
            slots
                .spheres
                .push(sphere(*s, 0.16, agent_color(i + 1, 0.35)));
        }
        replace_all(vec![target, leader, slots], ts)
    }

    fn links(&self, f: &Frame, ts: Timestamp) -> SceneUpdate {
        let mut graph = entity("graph".into(), WORLD_FRAME.into(), ts);
        let mut edges = line(
            line_primitive::Type::LineList,
            Vec::new(),
            0.035,
            link_color(LinkState::Up),
        );
        for &(a, b) in &self.cfg.edges {
            let (Some(pa), Some(pb)) = (f.agents.get(a), f.agents.get(b)) else {
                continue;
            };
            let c = link_color(link_state(&self.timeline, a, b, f.step));
            edges.points.extend([p3(pa.position), p3(pb.position)]);
            edges.colors.extend([c, c]);
        }
        graph.lines.push(edges);
        let mut leader = entity("leader-links".into(), WORLD_FRAME.into(), ts);
        let mut links = line(
            line_primitive::Type::LineList,
            Vec::new(),
            0.015,
            rgba(110, 110, 110, 0.6),
        );
        for &i in &self.cfg.leader_links {
            if let Some(a) = f.agents.get(i) {
                links.points.extend([p3(f.p_d), p3(a.position)]);
            }
        }
        leader.lines.push(links);
        replace_all(vec![graph, leader], ts)
    }

    /// Where an event's marker goes at frame `f`: its agent, the middle of its link, or the
    /// swarm's centre.
    fn marker_position(&self, f: &Frame, e: &Event) -> [f64; 3] {
        let pos = |id: usize| f.agents.get(id.wrapping_sub(1)).map(|a| a.position);
        let centre = || {
            let n = f.agents.len().max(1) as f64;
            let mut c = [0.0; 3];
            for a in &f.agents {
                for (ck, pk) in c.iter_mut().zip(a.position) {
                    *ck += pk / n;
                }
            }
            c
        };
        match (e.agent, e.agents) {
            (Some(a), _) => pos(a).unwrap_or_else(centre),
            (None, Some([a, b])) => match (pos(a), pos(b)) {
                (Some(p), Some(q)) => [
                    (p[0] + q[0]) / 2.0,
                    (p[1] + q[1]) / 2.0,
                    (p[2] + q[2]) / 2.0,
                ],
                _ => centre(),
            },
            _ => centre(),
        }
    }

    fn markers(&self, f: &Frame, ts: Timestamp) -> SceneUpdate {
        let span = (EVENT_MARKER_S / self.cfg.dt).round() as u64;
        let mut out = Vec::new();
        for (idx, m) in self.events.iter().enumerate() {
            if !(m.step <= f.step && f.step < m.step.saturating_add(span)) {
                continue;
            }
            let p = self.marker_position(f, &m.event);
            let mut e = entity(format!("event/{idx}"), WORLD_FRAME.into(), ts);
            let red = rgba(220, 30, 30, 1.0);
            e.spheres.push(sphere(p, 0.9, rgba(220, 30, 30, 0.25)));
            e.texts
                .push(text([p[0], p[1], p[2] + 0.7], m.label(), 0.3, red));
            out.push(e);
        }
        replace_all(out, ts)
    }

    /// `/log` lines of the events that apply after the last frame built, up to step k.
    fn logs(&self, k: u64) -> Vec<(u64, Log)> {
        let mut out: Vec<(u64, Log)> = self
            .events
            .iter()
            .filter(|m| m.step <= k && self.last_step.is_none_or(|last| m.step > last))
            .map(|m| {
                (
                    m.step,
                    Log {
                        timestamp: Some(timestamp(m.step, self.cfg.dt)),
                        level: m.level() as i32,
                        message: m.describe(self.cfg.dt),
                        name: "formation".into(),
                        file: String::new(),
                        line: 0,
                    },
                )
            })
            .collect();
        out.sort_by_key(|(s, _)| *s);
        out
    }
}

fn plot(f: &Frame, i: usize, a: &AgentSample, up: bool) -> AgentPlot {
    AgentPlot {
        step: f.step,
        t: f.t,
        agent: i + 1,
        up,
        position: a.position,
        formation_error_m: a.formation_error_m,
        gamma_hat: a.gamma_hat,
        delta_hat: a.delta_hat,
        gamma: a.gamma,
        delta: a.delta,
        attitude_margin_rad: a.attitude_margin_rad,
        rate_margin_rad_s: a.rate_margin_rad_s,
        tau_s: a.tau_s,
    }
}
