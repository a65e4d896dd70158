"""A ROS 2 subscriber on another DDS implementation (PyPI `cyclonedds`, Eclipse Cyclone DDS; no
ROS 2 install): subscribes to a formation run's `/formation/agent_<i>/pose`, `/tf` and `/clock`
the way a ROS 2 node does (DDS topics `rt/...`, ROS 2's DDS type names, CDR) and prints, as JSON,
what it received: per agent the pose count and the last pose (by stamp), the tf child frames, the
clock count and latest clock.

It prints `ready` once its readers exist, then reads until it has seen a pose stamped at or after
END_NS for every agent, or for TIMEOUT_S seconds.

usage: ros2_subscriber.py N_AGENTS END_NS TIMEOUT_S   (domain: ROS_DOMAIN_ID)
"""

import json
import os
import sys
import time
from dataclasses import dataclass

from cyclonedds.core import Policy, Qos
from cyclonedds.domain import DomainParticipant
from cyclonedds.idl import IdlStruct
from cyclonedds.idl.types import float64, int32, sequence, uint32
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration


@dataclass
class Time(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    sec: int32
    nanosec: uint32


@dataclass
class Header(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
    stamp: Time
    frame_id: str


@dataclass
class Point(IdlStruct, typename="geometry_msgs::msg::dds_::Point_"):
    x: float64
    y: float64
    z: float64


@dataclass
class Quaternion(IdlStruct, typename="geometry_msgs::msg::dds_::Quaternion_"):
    x: float64
    y: float64
    z: float64
    w: float64


@dataclass
class Pose(IdlStruct, typename="geometry_msgs::msg::dds_::Pose_"):
    position: Point
    orientation: Quaternion


@dataclass
class PoseStamped(IdlStruct, typename="geometry_msgs::msg::dds_::PoseStamped_"):
    header: Header
    pose: Pose


@dataclass
class Vector3(IdlStruct, typename="geometry_msgs::msg::dds_::Vector3_"):
    x: float64
    y: float64
    z: float64


@dataclass
class Transform(IdlStruct, typename="geometry_msgs::msg::dds_::Transform_"):
    translation: Vector3
    rotation: Quaternion


@dataclass
class TransformStamped(IdlStruct, typename="geometry_msgs::msg::dds_::TransformStamped_"):
    header: Header
    child_frame_id: str
    transform: Transform


@dataclass
class TFMessage(IdlStruct, typename="tf2_msgs::msg::dds_::TFMessage_"):
    transforms: sequence[TransformStamped]


@dataclass
class Clock(IdlStruct, typename="rosgraph_msgs::msg::dds_::Clock_"):
    clock: Time


def stamp_ns(t):
    return t.sec * 1_000_000_000 + t.nanosec


def valid(samples):
    """The samples that carry data (a writer leaving the domain yields an `InvalidSample`: an
    instance-state change without data)."""
    return [m for m in samples if type(m).__name__ != "InvalidSample"]


def main():
    n, end_ns, timeout_s = int(sys.argv[1]), int(sys.argv[2]), float(sys.argv[3])
    dp = DomainParticipant(int(os.environ.get("ROS_DOMAIN_ID", "0")))
    qos = Qos(
        Policy.Reliability.Reliable(duration(seconds=1)),
        Policy.History.KeepLast(1000),
        Policy.Durability.Volatile,
    )
    poses = [
        DataReader(dp, Topic(dp, f"rt/formation/agent_{i}/pose", PoseStamped), qos=qos)
        for i in range(1, n + 1)
    ]
    tf = DataReader(dp, Topic(dp, "rt/tf", TFMessage), qos=qos)
    clock = DataReader(dp, Topic(dp, "rt/clock", Clock), qos=qos)
    print("ready", flush=True)
    counts = [0] * n
    last = [None] * n
    frames = set()
    clocks, last_clock = 0, -1
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        for i, r in enumerate(poses):
            for m in valid(r.take(N=1000)):
                counts[i] += 1
                s = stamp_ns(m.header.stamp)
                if last[i] is None or s >= last[i]["stamp_ns"]:
                    p = m.pose.position
                    last[i] = {
                        "stamp_ns": s,
                        "frame_id": m.header.frame_id,
                        "position": [p.x, p.y, p.z],
                    }
        for m in valid(tf.take(N=1000)):
            for t in m.transforms:
                frames.add((t.header.frame_id, t.child_frame_id))
        for m in valid(clock.take(N=1000)):
            clocks += 1
            last_clock = max(last_clock, stamp_ns(m.clock))
        if all(p is not None and p["stamp_ns"] >= end_ns for p in last):
            break
        time.sleep(0.05)
    print(
        json.dumps(
            {
                "pose_counts": counts,
                "last_pose": last,
                "tf_frames": sorted(list(f) for f in frames),
                "clock_count": clocks,
                "last_clock_ns": last_clock,
            }
        ),
        flush=True,
    )


if __name__ == "__main__":
    main()
