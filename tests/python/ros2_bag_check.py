"""Reads a rosbag2 folder written by `formation sim|run --record rosbag2` with two outside
readers (PyPI `rosbags` and `mcap-ros2-support`; neither needs ROS 2 installed) and prints, as
JSON, what they found: per topic its type and message count (every message deserialised by
rosbags), the last pose of each pose topic with its stamp, the tf child frames, and how many
messages mcap-ros2-support decoded.

usage: ros2_bag_check.py BAG_DIR
"""

import json
import sys
from pathlib import Path

from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.highlevel import AnyReader


def stamp_ns(header):
    return header.stamp.sec * 1_000_000_000 + header.stamp.nanosec


def main():
    bag = Path(sys.argv[1])
    topics = {}
    last_pose = {}
    tf_frames = set()
    deserialised = 0
    with AnyReader([bag]) as reader:
        for c in reader.connections:
            topics[c.topic] = {"type": c.msgtype, "count": 0}
        for conn, _timestamp, raw in reader.messages():
            msg = reader.deserialize(raw, conn.msgtype)
            deserialised += 1
            topics[conn.topic]["count"] += 1
            if conn.msgtype == "geometry_msgs/msg/PoseStamped":
                p = msg.pose.position
                last_pose[conn.topic] = {
                    "stamp_ns": stamp_ns(msg.header),
                    "frame_id": msg.header.frame_id,
                    "position": [p.x, p.y, p.z],
                }
            elif conn.msgtype == "tf2_msgs/msg/TFMessage":
                for t in msg.transforms:
                    tf_frames.add((t.header.frame_id, t.child_frame_id))
    decoded = 0
    mcap_files = sorted(bag.glob("*.mcap"))
    for path in mcap_files:
        with open(path, "rb") as f:
            r = make_reader(f, decoder_factories=[DecoderFactory()])
            for _schema, _channel, _message, _ros_msg in r.iter_decoded_messages():
                decoded += 1
    print(
        json.dumps(
            {
                "topics": topics,
                "deserialised": deserialised,
                "last_pose": last_pose,
                "tf_frames": sorted(list(f) for f in tf_frames),
                "mcap_ros2_decoded": decoded,
            }
        )
    )


if __name__ == "__main__":
    main()
