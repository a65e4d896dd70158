"""Decodes the 3D scene channels of DIR/run.mcap with Foxglove's own schemas from PyPI
(`foxglove-schemas-protobuf`) and reads them back with the `mcap` package.

Usage: python mcap_scene_check.py DIR

Every message of a channel whose schema is a `foxglove.*` protobuf schema is decoded with the
package's class of that name (and the schema stored in the file must describe that message);
`/agent/{i}/plot` is JSON. Each `/tf` translation is compared exactly with the row of its step
and agent in trajectory.csv. Prints one JSON object: channels (topic -> schema, encoding), message
counts, decode failures, the first mismatches, the `/log` lines (log time, level, text), per
`/scene/events` message its log time and marker texts, and per `/scene/links` message its log
time and the colours of the graph's edges. Exits 2 on bad usage.
"""

import csv
import json
import sys
from pathlib import Path

from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms
from foxglove_schemas_protobuf.Log_pb2 import Log
from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate
from google.protobuf.descriptor_pb2 import FileDescriptorSet
from mcap.reader import make_reader

CLASSES = {
    "foxglove.FrameTransforms": FrameTransforms,
    "foxglove.SceneUpdate": SceneUpdate,
    "foxglove.Log": Log,
}


def main(argv):
    if len(argv) != 2:
        print(__doc__, file=sys.stderr)
        return 2
    run_dir = Path(argv[1])
    rows = {}
    with open(run_dir / "trajectory.csv", newline="") as f:
        for row in csv.DictReader(f):
            rows[(int(row["step"]), int(row["agent"]))] = row
    dt_ns = None
    report = {
        "channels": {},
        "counts": {},
        "decode_failures": 0,
        "schema_mismatches": [],
        "tf_compared": 0,
        "tf_mismatches": [],
        "plots_compared": 0,
        "logs": [],
        "events": [],
        "links": [],
        "entity_ids": {},
    }
    with open(run_dir / "run.mcap", "rb") as f:
        reader = make_reader(f)
        for md in reader.iter_metadata():
            if md.name == "formation":
                dt_ns = round(float(md.metadata["dt_s"]) * 1e9)
        f.seek(0)
        reader = make_reader(f)
        for schema, channel, message in reader.iter_messages():
            if not (channel.topic.startswith("/scene/") or channel.topic in ("/tf", "/log")
                    or channel.topic.endswith("/plot")):
                continue
            report["channels"][channel.topic] = [schema.name, schema.encoding,
                                                 channel.message_encoding]
            report["counts"][channel.topic] = report["counts"].get(channel.topic, 0) + 1
            if channel.message_encoding == "json":
                msg = json.loads(message.data)
                row = rows.get((msg["step"], msg["agent"]))
                pos = [float(row[c]) for c in ("px", "py", "pz")] if row else None
                if pos != msg["position"] or message.log_time != msg["step"] * dt_ns:
                    report["tf_mismatches"].append(["plot", channel.topic, msg["step"]])
                report["plots_compared"] += 1
                continue
            cls = CLASSES.get(schema.name)
            if cls is None or schema.encoding != "protobuf":
                report["schema_mismatches"].append([channel.topic, schema.name, schema.encoding])
                continue
            fds = FileDescriptorSet.FromString(schema.data)
            names = {f"{fd.package}.{m.name}" for fd in fds.file for m in fd.message_type}
            if schema.name not in names:
                report["schema_mismatches"].append([channel.topic, schema.name, "not in its schema"])
            try:
                msg = cls.FromString(message.data)
            except Exception as e:  # noqa: BLE001 (any decode error counts)
                report["decode_failures"] += 1
                print(f"{channel.topic}: {e}", file=sys.stderr)
                continue
            if channel.topic == "/tf":
                for t in msg.transforms:
                    step = (t.timestamp.seconds * 1_000_000_000 + t.timestamp.nanos) // dt_ns
                    agent = int(t.child_frame_id.split("/")[1])
                    row = rows.get((step, agent))
                    want = [float(row[c]) for c in ("px", "py", "pz")] if row else None
                    got = [t.translation.x, t.translation.y, t.translation.z]
                    if want != got or message.log_time != step * dt_ns:
                        report["tf_mismatches"].append([step, agent, got, want])
                    report["tf_compared"] += 1
            elif channel.topic == "/log":
                report["logs"].append([message.log_time, msg.level, msg.message])
            else:
                ids = report["entity_ids"].setdefault(channel.topic, [])
                for e in msg.entities:
                    if e.id not in ids:
                        ids.append(e.id)
                if channel.topic == "/scene/events":
                    texts = [t.text for e in msg.entities for t in e.texts]
                    report["events"].append([message.log_time, texts])
                elif channel.topic == "/scene/links":
                    graph = [e for e in msg.entities if e.id == "graph"]
                    colors = [[c.r, c.g, c.b] for c in graph[0].lines[0].colors] if graph else []
                    report["links"].append([message.log_time, colors])
    report["tf_mismatches"] = report["tf_mismatches"][:10]
    print(json.dumps(report))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
