//! The topics of a run and the messages of one output step ([`Frame`]) on them: what the live
//! publisher sends and the rosbag2 writer records, byte for byte the same.
//!
//! | topic | type | what |
//! |---|---|---|
//! | `/clock` | `rosgraph_msgs/msg/Clock` | simulation time t_k = k dt |
//! | `/formation/agent_<i>/pose` | `geometry_msgs/msg/PoseStamped` | quadrotor i's position P_i and attitude A_i, frame `world` |
//! | `/tf` | `tf2_msgs/msg/TFMessage` | `world` → `agent_<i>` (each quadrotor) and `world` → `virtual_leader` (P_d) |
//! | `/formation/reference` | `geometry_msgs/msg/PoseArray` | poses[0] the virtual leader P_d, poses[1] the ground target T_g, poses[1 + i] the slot P_d + Delta_i0 of agent i |
//! | `/formation/markers` | `visualization_msgs/msg/MarkerArray` | slots, target disk, virtual leader, graph links coloured by state, the leader's links |
//! | `/formation/events` | `std_msgs/msg/String` | an accepted injection, as the JSON of `run.mcap`'s `/events` |
//!
//! Every message of a step carries the stamp t_k (simulation time, never the wall clock).

use crate::cdr::CdrWriter;
use crate::msg::{
    self, Clock, Color, Header, Marker, MarkerArray, MarkerKind, Message, Pose, PoseArray,
    PoseStamped, StringMsg, TfMessage, Time, TransformStamped,
};
pub use formation_config::view::LinkState;
use formation_config::view::{agent_rgb, quaternion_xyzw};

/// The fixed frame of every message.
pub const WORLD_FRAME: &str = "world";
/// The tf frame of the virtual leader P_d.
pub const LEADER_FRAME: &str = "virtual_leader";

/// The tf frame of agent `id` (1-based).
pub fn agent_frame(id: usize) -> String {
    format!("agent_{id}")
}

/// The pose topic of agent `id` (1-based).
pub fn pose_topic(id: usize) -> String {
    format!("/formation/agent_{id}/pose")
}

/// Reliability of a topic's writer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Reliability {
    /// Lost samples are resent (matches reliable and best-effort readers).
    Reliable,
    /// Sent once.
    BestEffort,
}

/// The QoS a topic is offered with (history KEEP_LAST of `depth`, durability VOLATILE, liveliness
/// AUTOMATIC, no deadline or lifespan).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Qos {
    /// Reliability.
    pub reliability: Reliability,
    /// Samples kept per writer for late acknowledgements.
    pub depth: u32,
}

/// ROS 2's default QoS (`rclcpp::QoS(10)`, rmw_qos_profile_default): reliable, keep last 10.
pub const QOS_DEFAULT: Qos = Qos {
    reliability: Reliability::Reliable,
    depth: 10,
};

/// QoS of `/tf`: that of tf2_ros' TransformBroadcaster (reliable, keep last 100).
pub const QOS_TF: Qos = Qos {
    reliability: Reliability::Reliable,
    depth: 100,
};

/// QoS of `/clock`: reliable, keep last 1 (rclcpp's ClockQoS keeps 1 sample; a reliable writer
/// matches its best-effort readers and the reliable ones of `ros2 topic echo` alike).
pub const QOS_CLOCK: Qos = Qos {
    reliability: Reliability::Reliable,
    depth: 1,
};

/// One topic of a run.
#[derive(Debug, Clone, PartialEq)]
pub struct Topic {
    /// ROS 2 name, e.g. `/tf`.
    pub name: String,
    /// ROS 2 type, e.g. `tf2_msgs/msg/TFMessage`.
    pub type_name: &'static str,
    /// `ros2msg` definition.
    pub definition: &'static str,
    /// Type description hash.
    pub type_hash: &'static str,
    /// Offered QoS.
    pub qos: Qos,
}

impl Topic {
    fn of<M: Message>(name: String, qos: Qos) -> Topic {
        Topic {
            name,
            type_name: M::TYPE,
            definition: M::DEFINITION,
            type_hash: M::TYPE_HASH,
            qos,
        }
    }
}

/// Index of `/clock` in [`Encoder::topics`].
pub const CLOCK: usize = 0;
/// Index of `/tf`.
pub const TF: usize = 1;
/// Index of `/formation/reference`.
pub const REFERENCE: usize = 2;
/// Index of `/formation/markers`.
pub const MARKERS: usize = 3;
/// Index of `/formation/events`.
pub const EVENTS: usize = 4;
/// Index of agent 1's pose topic; agent i's is `POSES + i - 1`.
pub const POSES: usize = 5;

/// What does not change during a run.
#[derive(Debug, Clone, PartialEq)]
pub struct Scene {
    /// Number of quadrotors N.
    pub n_agents: usize,
    /// The graph's undirected edges {a, b}, 0-based agent indices.
    pub edges: Vec<(usize, usize)>,
    /// Agents (0-based) that receive the virtual leader (b_i > 0).
    pub leader_links: Vec<usize>,
    /// Radius of the target's disk, m.
    pub target_radius_m: f64,
}

/// Position and attitude of one quadrotor.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AgentPose {
    /// P_i, m (inertial frame `world`).
    pub position: [f64; 3],
    /// A_i = [phi, theta, psi], ZYX Euler angles, rad.
    pub attitude: [f64; 3],
}

/// One output step of a run.
#[derive(Debug, Clone, Copy)]
pub struct Frame<'a> {
    /// t_k = k dt, ns of simulation time.
    pub time_ns: u64,
    /// Virtual leader P_d, m.
    pub p_d: [f64; 3],
    /// Ground target T_g, m.
    pub target: [f64; 3],
    /// The N quadrotors.
    pub agents: &'a [AgentPose],
    /// Slots P_d + Delta_i0 of the N agents, m.
    pub slots: &'a [[f64; 3]],
    /// State of each of [`Scene::edges`].
    pub links: &'a [LinkState],
}

/// The rotation of ZYX Euler angles A = [phi, theta, psi] (body to inertial, R = Rz Ry Rx) as a
/// unit quaternion [x, y, z, w].
pub fn quaternion(a: [f64; 3]) -> [f64; 4] {
    quaternion_xyzw(a)
}

fn rgba(r: u8, g: u8, b: u8, a: f32) -> Color {
    [
        f32::from(r) / 255.0,
        f32::from(g) / 255.0,
        f32::from(b) / 255.0,
        a,
    ]
}

/// Colour of agent `id` (1-based): the palette of the figures and the Foxglove scene.
pub fn agent_color(id: usize, alpha: f32) -> Color {
    let [r, g, b] = agent_rgb(id);
    rgba(r, g, b, alpha)
}

/// Colour of an edge (those of the Foxglove scene).
pub fn link_color(state: LinkState) -> Color {
    let ([r, g, b], alpha) = state.rgba();
    rgba(r, g, b, alpha)
}

/// Sizes of the markers, m.
const SLOT_DIAMETER_M: f64 = 0.16;
const LEADER_DIAMETER_M: f64 = 0.18;
const TARGET_DISK_HEIGHT_M: f64 = 0.004;
const LINK_WIDTH_M: f64 = 0.035;
const LEADER_LINK_WIDTH_M: f64 = 0.015;

/// Turns output steps into encoded messages, one topic at a time.
pub struct Encoder {
    scene: Scene,
    topics: Vec<Topic>,
    w: CdrWriter,
}

impl Encoder {
    /// The topics of `scene`.
    pub fn new(scene: Scene) -> Encoder {
        let mut topics = vec![
            Topic::of::<Clock>("/clock".into(), QOS_CLOCK),
            Topic::of::<TfMessage>("/tf".into(), QOS_TF),
            Topic::of::<PoseArray>("/formation/reference".into(), QOS_DEFAULT),
            Topic::of::<MarkerArray>("/formation/markers".into(), QOS_DEFAULT),
            Topic::of::<StringMsg>("/formation/events".into(), QOS_DEFAULT),
        ];
        for id in 1..=scene.n_agents {
            topics.push(Topic::of::<PoseStamped>(pose_topic(id), QOS_DEFAULT));
        }
        Encoder {
            scene,
            topics,
            w: CdrWriter::new(),
        }
    }

    /// The topics; messages are handed out with their index here.
    pub fn topics(&self) -> &[Topic] {
        &self.topics
    }

    fn emit<M: Message>(&mut self, topic: usize, m: &M, out: &mut impl FnMut(usize, &[u8])) {
        msg::encode(m, &mut self.w);
        out(topic, self.w.bytes());
    }

    /// The messages of one output step, handed to `out(topic index, CDR bytes)`: `/clock`, each
    /// agent's pose, `/tf`, `/formation/reference`, `/formation/markers`.
    pub fn frame(&mut self, f: &Frame, mut out: impl FnMut(usize, &[u8])) {
        let stamp = Time::from_nanos(f.time_ns);
        let header = || Header {
            stamp,
            frame_id: WORLD_FRAME.into(),
        };
        self.emit(CLOCK, &Clock { clock: stamp }, &mut out);
        let mut tf = TfMessage::default();
        for (i, a) in f.agents.iter().enumerate() {
            let pose = Pose {
                position: a.position,
                orientation: quaternion(a.attitude),
            };
            let msg = PoseStamped {
                header: header(),
                pose,
            };
            self.emit(POSES + i, &msg, &mut out);
            tf.transforms.push(TransformStamped {
                header: header(),
                child_frame_id: agent_frame(i + 1),
                translation: pose.position,
                rotation: pose.orientation,
            });
        }
        tf.transforms.push(TransformStamped {
            header: header(),
            child_frame_id: LEADER_FRAME.into(),
            translation: f.p_d,
            rotation: [0.0, 0.0, 0.0, 1.0],
        });
        self.emit(TF, &tf, &mut out);
        let mut poses = vec![Pose::at(f.p_d), Pose::at(f.target)];
        poses.extend(f.slots.iter().map(|s| Pose::at(*s)));
        let reference = PoseArray {
            header: header(),
            poses,
        };
        self.emit(REFERENCE, &reference, &mut out);
        let markers = self.markers(f, &header);
        self.emit(MARKERS, &markers, &mut out);
    }

    fn markers(&self, f: &Frame, header: &dyn Fn() -> Header) -> MarkerArray {
        let marker = |ns: &str, kind, pose, scale, color| Marker {
            header: header(),
            ns: ns.into(),
            id: 0,
            kind,
            pose,
            scale,
            color,
            points: Vec::new(),
            colors: Vec::new(),
        };
        let r = self.scene.target_radius_m;
        let t = f.target;
        let target = marker(
            "target",
            MarkerKind::Cylinder,
            Pose::at([t[0], t[1], TARGET_DISK_HEIGHT_M * 0.5]),
            [2.0 * r, 2.0 * r, TARGET_DISK_HEIGHT_M],
            rgba(60, 60, 60, 0.18),
        );
        let leader = marker(
            "virtual_leader",
            MarkerKind::Sphere,
            Pose::at(f.p_d),
            [LEADER_DIAMETER_M; 3],
            rgba(20, 20, 20, 1.0),
        );
        let mut slots = marker(
            "slots",
            MarkerKind::SphereList,
            Pose::at([0.0; 3]),
            [SLOT_DIAMETER_M; 3],
            agent_color(1, 0.35),
        );
        for (i, s) in f.slots.iter().enumerate() {
            slots.points.push(*s);
            slots.colors.push(agent_color(i + 1, 0.35));
        }
        let mut graph = marker(
            "graph",
            MarkerKind::LineList,
            Pose::at([0.0; 3]),
            [LINK_WIDTH_M, 0.0, 0.0],
            link_color(LinkState::Up),
        );
        for (k, &(a, b)) in self.scene.edges.iter().enumerate() {
            let (Some(pa), Some(pb)) = (f.agents.get(a), f.agents.get(b)) else {
                continue;
            };
            let c = link_color(f.links.get(k).copied().unwrap_or(LinkState::Up));
            graph.points.extend([pa.position, pb.position]);
            graph.colors.extend([c, c]);
        }
        let mut leader_links = marker(
            "leader_links",
            MarkerKind::LineList,
            Pose::at([0.0; 3]),
            [LEADER_LINK_WIDTH_M, 0.0, 0.0],
            rgba(110, 110, 110, 0.6),
        );
        for &i in &self.scene.leader_links {
            if let Some(a) = f.agents.get(i) {
                leader_links.points.extend([f.p_d, a.position]);
            }
        }
        MarkerArray {
            markers: vec![target, leader, slots, graph, leader_links],
        }
    }

    /// An accepted injection at `time_ns` as `/formation/events` (`json`: its event as text).
    pub fn event(&mut self, json: &str, mut out: impl FnMut(usize, &[u8])) {
        let m = StringMsg { data: json.into() };
        self.emit(EVENTS, &m, &mut out);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_frame_gives_clock_every_pose_tf_reference_and_markers_once() {
        let scene = Scene {
            n_agents: 2,
            edges: vec![(0, 1)],
            leader_links: vec![0],
            target_radius_m: 1.0,
        };
        let mut enc = Encoder::new(scene);
        assert_eq!(enc.topics().len(), POSES + 2);
        assert_eq!(enc.topics()[POSES + 1].name, "/formation/agent_2/pose");
        let agents = [
            AgentPose {
                position: [1.0, 0.0, 2.0],
                attitude: [0.0; 3],
            },
            AgentPose {
                position: [0.0, 1.0, 2.0],
                attitude: [0.0, 0.0, 0.3],
            },
        ];
        let mut seen = Vec::new();
        enc.frame(
            &Frame {
                time_ns: 1_500_000_000,
                p_d: [0.0; 3],
                target: [0.0; 3],
                agents: &agents,
                slots: &[[1.0, 0.0, 2.0], [0.0, 1.0, 2.0]],
                links: &[LinkState::Down],
            },
            |t, b| seen.push((t, b.to_vec())),
        );
        let topics: Vec<usize> = seen.iter().map(|(t, _)| *t).collect();
        assert_eq!(topics, [CLOCK, POSES, POSES + 1, TF, REFERENCE, MARKERS]);
        assert_eq!(
            &seen[0].1[4..],
            &[1, 0, 0, 0, 0x00, 0x65, 0xcd, 0x1d][..],
            "1.5 s"
        );
    }

    #[test]
    fn the_quaternion_of_a_yaw_turns_about_z() {
        let q = quaternion([0.0, 0.0, std::f64::consts::FRAC_PI_2]);
        let h = std::f64::consts::FRAC_1_SQRT_2;
        for (a, b) in q.iter().zip([0.0, 0.0, h, h]) {
            assert!((a - b).abs() < 1e-12);
        }
    }
}
