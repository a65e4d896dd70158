//! The ROS 2 messages of a run, with their CDR encoding ([`super::cdr`]) and, for rosbag2, their
//! definitions in the `ros2msg` form (the type's `.msg` text followed by every type it uses, each
//! after a line of 80 `=` and `MSG: package/Type`, as rosbag2 stores them) and their ROS 2 type
//! hashes (`RIHS01_...`, the type description hash of ROS 2 Iron and later).
//!
//! The definitions are those of ROS 2 Jazzy's `common_interfaces` (the same layout as Humble's).

use crate::cdr::CdrWriter;

/// A ROS 2 message type: its names, definition and encoding.
pub trait Message {
    /// ROS 2 type name, e.g. `geometry_msgs/msg/PoseStamped`.
    const TYPE: &'static str;
    /// `ros2msg` definition with its dependencies.
    const DEFINITION: &'static str;
    /// Type description hash (`RIHS01_` and 64 hex digits).
    const TYPE_HASH: &'static str;
    /// Writes the fields (after the encapsulation header).
    fn encode(&self, w: &mut CdrWriter);
}

/// The DDS type name of ROS 2 type `pkg/msg/Type`: `pkg::msg::dds_::Type_`.
pub fn dds_type_name(ros_type: &str) -> String {
    let mut parts = ros_type.split('/');
    let (pkg, kind, name) = (
        parts.next().unwrap_or_default(),
        parts.next().unwrap_or_default(),
        parts.next().unwrap_or_default(),
    );
    format!("{pkg}::{kind}::dds_::{name}_")
}

/// `builtin_interfaces/msg/Time`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Time {
    /// Whole seconds.
    pub sec: i32,
    /// Nanoseconds within the second.
    pub nanosec: u32,
}

impl Time {
    /// The time `ns` nanoseconds after zero (simulation time: a run starts at 0).
    pub fn from_nanos(ns: u64) -> Time {
        Time {
            sec: (ns / 1_000_000_000).min(i32::MAX as u64) as i32,
            nanosec: (ns % 1_000_000_000) as u32,
        }
    }

    fn encode(&self, w: &mut CdrWriter) {
        w.i32(self.sec);
        w.u32(self.nanosec);
    }
}

/// `std_msgs/msg/Header`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Header {
    /// Time stamp.
    pub stamp: Time,
    /// Frame the data is expressed in.
    pub frame_id: String,
}

impl Header {
    fn encode(&self, w: &mut CdrWriter) {
        self.stamp.encode(w);
        w.string(&self.frame_id);
    }
}

fn vec3(w: &mut CdrWriter, v: &[f64; 3]) {
    for x in v {
        w.f64(*x);
    }
}

/// `geometry_msgs/msg/Pose`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    /// Position, m.
    pub position: [f64; 3],
    /// Orientation as a unit quaternion [x, y, z, w].
    pub orientation: [f64; 4],
}

impl Pose {
    /// The pose at `p` with no rotation.
    pub fn at(p: [f64; 3]) -> Pose {
        Pose {
            position: p,
            orientation: [0.0, 0.0, 0.0, 1.0],
        }
    }

    fn encode(&self, w: &mut CdrWriter) {
        vec3(w, &self.position);
        for x in &self.orientation {
            w.f64(*x);
        }
    }
}

/// `geometry_msgs/msg/PoseStamped`.
#[derive(Debug, Clone, PartialEq)]
pub struct PoseStamped {
    /// Stamp and frame.
    pub header: Header,
    /// The pose.
    pub pose: Pose,
}

impl Message for PoseStamped {
    const TYPE: &'static str = "geometry_msgs/msg/PoseStamped";
    const DEFINITION: &'static str = include_str!("../msgdefs/geometry_msgs__PoseStamped.msg");
    const TYPE_HASH: &'static str =
        "RIHS01_10f3786d7d40fd2b54367835614bff85d4ad3b5dab62bf8bca0cc232d73b4cd8";
    fn encode(&self, w: &mut CdrWriter) {
        self.header.encode(w);
        self.pose.encode(w);
    }
}

/// `geometry_msgs/msg/PoseArray`.
#[derive(Debug, Clone, PartialEq)]
pub struct PoseArray {
    /// Stamp and frame.
    pub header: Header,
    /// The poses.
    pub poses: Vec<Pose>,
}

impl Message for PoseArray {
    const TYPE: &'static str = "geometry_msgs/msg/PoseArray";
    const DEFINITION: &'static str = include_str!("../msgdefs/geometry_msgs__PoseArray.msg");
    const TYPE_HASH: &'static str =
        "RIHS01_af0cc36d190e104d546d168d6b39df04fa4b4ccecf59cb4c9ed328d3d5004aa0";
    fn encode(&self, w: &mut CdrWriter) {
        self.header.encode(w);
        w.sequence_len(self.poses.len());
        for p in &self.poses {
            p.encode(w);
        }
    }
}

/// `geometry_msgs/msg/TransformStamped`: the pose of `child_frame_id` in `header.frame_id`.
#[derive(Debug, Clone, PartialEq)]
pub struct TransformStamped {
    /// Stamp and parent frame.
    pub header: Header,
    /// The child frame.
    pub child_frame_id: String,
    /// Translation, m.
    pub translation: [f64; 3],
    /// Rotation as a unit quaternion [x, y, z, w].
    pub rotation: [f64; 4],
}

/// `tf2_msgs/msg/TFMessage`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct TfMessage {
    /// The transforms.
    pub transforms: Vec<TransformStamped>,
}

impl Message for TfMessage {
    const TYPE: &'static str = "tf2_msgs/msg/TFMessage";
    const DEFINITION: &'static str = include_str!("../msgdefs/tf2_msgs__TFMessage.msg");
    const TYPE_HASH: &'static str =
        "RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087";
    fn encode(&self, w: &mut CdrWriter) {
        w.sequence_len(self.transforms.len());
        for t in &self.transforms {
            t.header.encode(w);
            w.string(&t.child_frame_id);
            Pose {
                position: t.translation,
                orientation: t.rotation,
            }
            .encode(w);
        }
    }
}

/// `rosgraph_msgs/msg/Clock`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Clock {
    /// The current time.
    pub clock: Time,
}

impl Message for Clock {
    const TYPE: &'static str = "rosgraph_msgs/msg/Clock";
    const DEFINITION: &'static str = include_str!("../msgdefs/rosgraph_msgs__Clock.msg");
    const TYPE_HASH: &'static str =
        "RIHS01_692f7a66e93a3c83e71765d033b60349ba68023a8c689a79e48078bcb5c58564";
    fn encode(&self, w: &mut CdrWriter) {
        self.clock.encode(w);
    }
}

/// `std_msgs/msg/String`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct StringMsg {
    /// The text.
    pub data: String,
}

impl Message for StringMsg {
    const TYPE: &'static str = "std_msgs/msg/String";
    const DEFINITION: &'static str = include_str!("../msgdefs/std_msgs__String.msg");
    const TYPE_HASH: &'static str =
        "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18";
    fn encode(&self, w: &mut CdrWriter) {
        w.string(&self.data);
    }
}

/// `std_msgs/msg/ColorRGBA`: r, g, b, a in [0, 1].
pub type Color = [f32; 4];

/// The kinds of `visualization_msgs/msg/Marker` used here (its `type` constants).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(i32)]
pub enum MarkerKind {
    /// `SPHERE`.
    Sphere = 2,
    /// `CYLINDER`.
    Cylinder = 3,
    /// `LINE_LIST`: a segment per pair of points.
    LineList = 5,
    /// `SPHERE_LIST`: a sphere per point.
    SphereList = 7,
}

/// `visualization_msgs/msg/Marker` (action `ADD`, no lifetime, no texture or mesh).
#[derive(Debug, Clone, PartialEq)]
pub struct Marker {
    /// Stamp and frame.
    pub header: Header,
    /// Namespace.
    pub ns: String,
    /// Id within the namespace.
    pub id: i32,
    /// Shape.
    pub kind: MarkerKind,
    /// Pose of the shape.
    pub pose: Pose,
    /// Size, m (line lists: `x` is the line width).
    pub scale: [f64; 3],
    /// Colour of the whole marker.
    pub color: Color,
    /// Points of list markers.
    pub points: Vec<[f64; 3]>,
    /// Colour of each point of list markers (empty: `color`).
    pub colors: Vec<Color>,
}

/// `visualization_msgs/msg/Marker`'s action `ADD`.
const MARKER_ADD: i32 = 0;

impl Marker {
    fn encode(&self, w: &mut CdrWriter) {
        self.header.encode(w);
        w.string(&self.ns);
        w.i32(self.id);
        w.i32(self.kind as i32);
        w.i32(MARKER_ADD);
        self.pose.encode(w);
        vec3(w, &self.scale);
        color(w, &self.color);
        // lifetime: 0 (forever), frame_locked: false.
        Time::default().encode(w);
        w.bool(false);
        w.sequence_len(self.points.len());
        for p in &self.points {
            vec3(w, p);
        }
        w.sequence_len(self.colors.len());
        for c in &self.colors {
            color(w, c);
        }
        // texture_resource, texture (sensor_msgs/CompressedImage: header, format, data),
        // uv_coordinates, text, mesh_resource, mesh_file (filename, data),
        // mesh_use_embedded_materials: all empty.
        w.string("");
        Header::default().encode(w);
        w.string("");
        w.sequence_len(0);
        w.sequence_len(0);
        w.string("");
        w.string("");
        w.string("");
        w.sequence_len(0);
        w.bool(false);
    }
}

fn color(w: &mut CdrWriter, c: &Color) {
    for x in c {
        w.f32(*x);
    }
}

/// `visualization_msgs/msg/MarkerArray`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct MarkerArray {
    /// The markers.
    pub markers: Vec<Marker>,
}

impl Message for MarkerArray {
    const TYPE: &'static str = "visualization_msgs/msg/MarkerArray";
    const DEFINITION: &'static str = include_str!("../msgdefs/visualization_msgs__MarkerArray.msg");
    const TYPE_HASH: &'static str =
        "RIHS01_86cb8800b6fb05b5eff1abd7a56f62a5641d3ae9a1c29e78e67e704f1d067dcf";
    fn encode(&self, w: &mut CdrWriter) {
        w.sequence_len(self.markers.len());
        for m in &self.markers {
            m.encode(w);
        }
    }
}

/// `msg` encoded as a CDR message (header and body) into `w`.
pub fn encode<M: Message>(msg: &M, w: &mut CdrWriter) {
    w.start();
    msg.encode(w);
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hex(b: &[u8]) -> String {
        b.iter().map(|x| format!("{x:02x}")).collect()
    }

    #[test]
    fn a_clock_encodes_as_ros_2_does() {
        // rosbags' serialize_cdr of Clock(clock=Time(sec=1, nanosec=2)).
        let mut w = CdrWriter::new();
        encode(
            &Clock {
                clock: Time { sec: 1, nanosec: 2 },
            },
            &mut w,
        );
        assert_eq!(hex(w.bytes()), "000100000100000002000000");
    }

    #[test]
    fn a_pose_stamped_encodes_as_ros_2_does() {
        // rosbags' serialize_cdr of the same message.
        let mut w = CdrWriter::new();
        encode(
            &PoseStamped {
                header: Header {
                    stamp: Time { sec: 3, nanosec: 5 },
                    frame_id: "world".into(),
                },
                pose: Pose::at([1.0, 2.0, 3.0]),
            },
            &mut w,
        );
        assert_eq!(
            hex(w.bytes()),
            "00010000030000000500000006000000776f726c6400000000000000000000000000f03f000000000000\
             00400000000000000840000000000000000000000000000000000000000000000000000000000000f03f"
        );
    }

    #[test]
    fn a_marker_array_encodes_as_ros_2_does_with_every_field_of_marker() {
        // rosbags' serialize_cdr of the same message (ROS 2 Jazzy's Marker: texture, uv
        // coordinates and mesh file empty).
        let mut w = CdrWriter::new();
        encode(
            &MarkerArray {
                markers: vec![Marker {
                    header: Header {
                        stamp: Time {
                            sec: 0,
                            nanosec: 10,
                        },
                        frame_id: "world".into(),
                    },
                    ns: "graph".into(),
                    id: 1,
                    kind: MarkerKind::LineList,
                    pose: Pose::at([0.0; 3]),
                    scale: [0.5, 0.0, 0.0],
                    color: [1.0, 0.5, 0.25, 1.0],
                    points: vec![[1.0, 2.0, 3.0]],
                    colors: vec![[0.0, 1.0, 0.0, 0.5]],
                }],
            },
            &mut w,
        );
        assert_eq!(
            hex(w.bytes()),
            "0001000001000000000000000a00000006000000776f726c640000000600000067726170680000000100\
             000005000000000000000000000000000000000000000000000000000000000000000000000000000000\
             00000000000000000000000000000000000000000000f03f000000000000e03f00000000000000000000\
             0000000000000000803f0000003f0000803e0000803f0000000000000000000000000100000000000000\
             0000f03f0000000000000040000000000000084001000000000000000000803f000000000000003f0100\
             000000000000000000000000000001000000000000000100000000000000000000000000000001000000\
             00000000010000000000000001000000000000000000000000"
        );
    }

    #[test]
    fn the_dds_type_name_is_the_ros_2_mangled_one() {
        assert_eq!(
            dds_type_name(PoseStamped::TYPE),
            "geometry_msgs::msg::dds_::PoseStamped_"
        );
    }

    #[test]
    fn simulation_time_splits_into_seconds_and_nanoseconds() {
        assert_eq!(
            Time::from_nanos(61_250_000_001),
            Time {
                sec: 61,
                nanosec: 250_000_001
            }
        );
    }

    #[test]
    fn every_definition_starts_with_its_own_fields_and_names_its_dependencies() {
        assert!(PoseStamped::DEFINITION.starts_with("std_msgs/Header header\n"));
        assert!(PoseStamped::DEFINITION.contains("\nMSG: geometry_msgs/Quaternion\n"));
        assert!(MarkerArray::DEFINITION.contains("\nMSG: visualization_msgs/Marker\n"));
        for hash in [
            PoseStamped::TYPE_HASH,
            PoseArray::TYPE_HASH,
            TfMessage::TYPE_HASH,
            Clock::TYPE_HASH,
            StringMsg::TYPE_HASH,
            MarkerArray::TYPE_HASH,
        ] {
            assert_eq!(hash.len(), "RIHS01_".len() + 64);
        }
    }
}
