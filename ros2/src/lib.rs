//! The ROS 2 view of a formation run, without a ROS 2 install: the run's output steps as ROS 2
//! messages in CDR ([`scene`]: poses, `/tf`, markers, reference, events, `/clock`), recorded as
//! rosbag2 with MCAP storage ([`bag`]) and (feature `dds`) published live on the DDS-RTPS wire
//! ([`dds`]), where `ros2 topic echo`, rviz2 and any DDS implementation see them.
//!
//! The API speaks in plain arrays and strings; the DDS implementation (RustDDS) and the MCAP
//! writer stay inside.

pub mod bag;
pub mod cdr;
#[cfg(feature = "dds")]
pub mod dds;
pub mod msg;
pub mod scene;

pub use scene::{AgentPose, Encoder, Frame, LinkState, Scene, Topic};
