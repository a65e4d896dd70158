//! A rosbag2 recording in MCAP storage: the `.mcap` file (profile `ros2`, one schema per type
//! with encoding `ros2msg` and the type's definition, one channel per topic with message encoding
//! `cdr` and its offered QoS, CDR messages) and the text of `metadata.yaml` (rosbag2 metadata
//! version 8: topics with types, QoS, type hashes and message counts, time span, files), which
//! `ros2 bag info`, `ros2 bag play` and other rosbag2 readers need beside it.
//!
//! Log and publish times are the messages' simulation times (a run starts at t = 0, so the bag
//! starts at the epoch: `ros2 bag play --clock` replays simulation time).

use crate::scene::{Qos, Reliability, Topic};
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::io::{Seek, Write};

/// The rosbag2 metadata version written (ROS 2 Jazzy's; Humble and later read the fields they know).
pub const METADATA_VERSION: u32 = 8;

/// What a finished recording holds.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BagSummary {
    /// Messages per topic, in the order of the topics given to [`BagWriter::create`].
    pub counts: Vec<u64>,
    /// Earliest and latest log time, ns (both 0 when empty).
    pub span_ns: (u64, u64),
}

/// Writer of one rosbag2 recording's MCAP file.
pub struct BagWriter<W: Write + Seek> {
    writer: mcap::Writer<W>,
    file_name: String,
    topics: Vec<Topic>,
    channels: Vec<u16>,
    counts: Vec<u64>,
    first_ns: Option<u64>,
    last_ns: u64,
}

fn mcap_error(e: mcap::McapError) -> std::io::Error {
    match e {
        mcap::McapError::Io(e) => e,
        e => std::io::Error::other(format!("rosbag2: {e}")),
    }
}

impl<W: Write + Seek> BagWriter<W> {
    /// Starts the MCAP file `file_name` (its name in `metadata.yaml`) on `out`, with a schema
    /// per type and a channel per topic.
    pub fn create(out: W, file_name: &str, topics: &[Topic]) -> std::io::Result<BagWriter<W>> {
        let mut writer = mcap::WriteOptions::new()
            .compression(None)
            .profile("ros2")
            .library("formation")
            .create(out)
            .map_err(mcap_error)?;
        let mut schemas: BTreeMap<&str, u16> = BTreeMap::new();
        let mut channels = Vec::with_capacity(topics.len());
        for t in topics {
            let schema = match schemas.get(t.type_name) {
                Some(id) => *id,
                None => {
                    let id = writer
                        .add_schema(t.type_name, "ros2msg", t.definition.as_bytes())
                        .map_err(mcap_error)?;
                    schemas.insert(t.type_name, id);
                    id
                }
            };
            let metadata = BTreeMap::from([
                ("offered_qos_profiles".to_string(), qos_profiles(&t.qos)),
                ("topic_type_hash".to_string(), t.type_hash.to_string()),
            ]);
            channels.push(
                writer
                    .add_channel(schema, &t.name, "cdr", &metadata)
                    .map_err(mcap_error)?,
            );
        }
        Ok(BagWriter {
            writer,
            file_name: file_name.to_string(),
            topics: topics.to_vec(),
            channels,
            counts: vec![0; topics.len()],
            first_ns: None,
            last_ns: 0,
        })
    }

    /// Records a CDR message of topic `topic` (index in the topics given) at `time_ns`.
    pub fn write(&mut self, topic: usize, time_ns: u64, data: &[u8]) -> std::io::Result<()> {
        let header = mcap::records::MessageHeader {
            channel_id: self.channels[topic],
            sequence: self.counts[topic] as u32,
            log_time: time_ns,
            publish_time: time_ns,
        };
        self.writer
            .write_to_known_channel(&header, data)
            .map_err(mcap_error)?;
        self.counts[topic] += 1;
        self.first_ns = Some(self.first_ns.map_or(time_ns, |f| f.min(time_ns)));
        self.last_ns = self.last_ns.max(time_ns);
        Ok(())
    }

    /// Closes the MCAP file; returns the writer, the text of `metadata.yaml` and the counts.
    pub fn finish(mut self) -> std::io::Result<(W, String, BagSummary)> {
        let span_ns = (self.first_ns.unwrap_or(0), self.last_ns);
        let info = self.metadata(span_ns);
        // rosbag2 keeps the same text (without its top-level key) in the MCAP file.
        let inner: String = info
            .lines()
            .skip(1)
            .map(|l| format!("{}\n", l.strip_prefix("  ").unwrap_or(l)))
            .collect();
        self.writer
            .write_metadata(&mcap::records::Metadata {
                name: "rosbag2".into(),
                metadata: BTreeMap::from([("serialized_metadata".to_string(), inner)]),
            })
            .map_err(mcap_error)?;
        self.writer.finish().map_err(mcap_error)?;
        let summary = BagSummary {
            counts: self.counts.clone(),
            span_ns,
        };
        Ok((self.writer.into_inner(), info, summary))
    }

    /// The text of `metadata.yaml`.
    fn metadata(&self, (start, end): (u64, u64)) -> String {
        let total: u64 = self.counts.iter().sum();
        let duration = end - start;
        let mut y = String::new();
        let _ = writeln!(y, "rosbag2_bagfile_information:");
        let _ = writeln!(y, "  version: {METADATA_VERSION}");
        let _ = writeln!(y, "  storage_identifier: mcap");
        let _ = writeln!(y, "  duration:\n    nanoseconds: {duration}");
        let _ = writeln!(y, "  starting_time:\n    nanoseconds_since_epoch: {start}");
        let _ = writeln!(y, "  message_count: {total}");
        let _ = writeln!(y, "  topics_with_message_count:");
        for (t, n) in self.topics.iter().zip(&self.counts) {
            let _ = writeln!(y, "    - topic_metadata:");
            let _ = writeln!(y, "        name: {}", quoted(&t.name));
            let _ = writeln!(y, "        type: {}", quoted(t.type_name));
            let _ = writeln!(y, "        serialization_format: cdr");
            let _ = writeln!(
                y,
                "        offered_qos_profiles: {}",
                quoted(&qos_profiles(&t.qos))
            );
            let _ = writeln!(y, "        type_description_hash: {}", t.type_hash);
            let _ = writeln!(y, "      message_count: {n}");
        }
        let _ = writeln!(y, "  compression_format: \"\"");
        let _ = writeln!(y, "  compression_mode: \"\"");
        let _ = writeln!(y, "  relative_file_paths:");
        let _ = writeln!(y, "    - {}", quoted(&self.file_name));
        let _ = writeln!(y, "  files:");
        let _ = writeln!(y, "    - path: {}", quoted(&self.file_name));
        let _ = writeln!(
            y,
            "      starting_time:\n        nanoseconds_since_epoch: {start}"
        );
        let _ = writeln!(y, "      duration:\n        nanoseconds: {duration}");
        let _ = writeln!(y, "      message_count: {total}");
        let _ = writeln!(y, "  custom_data: ~");
        let _ = writeln!(y, "  ros_distro: \"\"");
        y
    }
}

/// A YAML double-quoted scalar.
fn quoted(s: &str) -> String {
    let mut q = String::with_capacity(s.len() + 2);
    q.push('"');
    for c in s.chars() {
        match c {
            '"' => q.push_str("\\\""),
            '\\' => q.push_str("\\\\"),
            '\n' => q.push_str("\\n"),
            c if c.is_control() => {
                let _ = write!(q, "\\u{:04x}", c as u32);
            }
            c => q.push(c),
        }
    }
    q.push('"');
    q
}

/// rosbag2's `offered_qos_profiles` of one writer: a YAML list in a string. Durations 0/0 are
/// "unspecified" (no deadline, lifespan or lease). Enum values as rmw's: history KEEP_LAST = 1,
/// reliability RELIABLE = 1 / BEST_EFFORT = 2, durability VOLATILE = 2, liveliness AUTOMATIC = 1.
fn qos_profiles(q: &Qos) -> String {
    let reliability = match q.reliability {
        Reliability::Reliable => 1,
        Reliability::BestEffort => 2,
    };
    let zero = "\n    sec: 0\n    nsec: 0";
    format!(
        "- history: 1\n  depth: {}\n  reliability: {reliability}\n  durability: 2\n  deadline:{zero}\n  lifespan:{zero}\n  liveliness: 1\n  liveliness_lease_duration:{zero}\n  avoid_ros_namespace_conventions: false",
        q.depth
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{Encoder, Scene, CLOCK};

    #[test]
    fn a_bag_counts_its_messages_per_topic_and_names_its_file() {
        let enc = Encoder::new(Scene {
            n_agents: 1,
            edges: vec![],
            leader_links: vec![],
            target_radius_m: 1.0,
        });
        let mut bag =
            BagWriter::create(std::io::Cursor::new(Vec::new()), "b_0.mcap", enc.topics()).unwrap();
        bag.write(CLOCK, 10, b"\0\x01\0\0\0\0\0\0\0\0\0\0").unwrap();
        bag.write(CLOCK, 20, b"\0\x01\0\0\0\0\0\0\0\0\0\0").unwrap();
        let (out, yaml, summary) = bag.finish().unwrap();
        assert_eq!(summary.counts[CLOCK], 2);
        assert_eq!(summary.span_ns, (10, 20));
        assert!(yaml.contains("  message_count: 2\n"));
        assert!(yaml.contains("    - path: \"b_0.mcap\"\n"));
        assert!(yaml.contains("        type: \"rosgraph_msgs/msg/Clock\"\n"));
        assert!(out.into_inner().starts_with(b"\x89MCAP0\r\n"));
    }

    #[test]
    fn a_yaml_string_escapes_quotes_and_newlines() {
        assert_eq!(quoted("a\"b\nc"), "\"a\\\"b\\nc\"");
    }
}
