"""Reads DIR/run.mcap with the `mcap` package (PyPI) and checks it against DIR/trajectory.csv.

Usage: python mcap_check.py DIR

Every `/agent/{id}/state` message must equal the row of its step and agent in trajectory.csv
(step, t, position, velocity, attitude, body rate: the same floats, compared exactly), every row
must have its message, every channel must be JSON with a JSON Schema whose required fields each
message holds (except the 3D scene's, on Foxglove's protobuf schemas, which mcap_scene_check.py
decodes), and log times must be t_k in nanoseconds. Prints one JSON line with the counts;
exits 1 on any mismatch (listing the first ones on stderr), 2 on bad usage.
"""

import csv
import json
import sys
from pathlib import Path

from mcap.reader import make_reader

STATE_COLUMNS = {
    "position": ["px", "py", "pz"],
    "velocity": ["vx", "vy", "vz"],
    "attitude": ["phi", "theta", "psi"],
    "rate": ["p", "q", "r"],
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
    problems = []
    seen = set()
    per_topic = {}
    with open(run_dir / "run.mcap", "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        schemas = {}
        scene = set()
        for channel in summary.channels.values():
            schema = summary.schemas[channel.schema_id]
            if (channel.message_encoding, schema.encoding) == ("protobuf", "protobuf") and \
                    schema.name.startswith("foxglove."):
                # The 3D scene's channels (Foxglove's schemas): mcap_scene_check.py decodes them.
                scene.add(channel.id)
                continue
            if channel.message_encoding != "json" or schema.encoding != "jsonschema":
                problems.append(f"{channel.topic}: {channel.message_encoding}/{schema.encoding}")
            schemas[channel.id] = json.loads(schema.data)
        for _schema, channel, message in reader.iter_messages():
            per_topic[channel.topic] = per_topic.get(channel.topic, 0) + 1
            if channel.id in scene:
                continue
            data = json.loads(message.data)
            required = schemas[channel.id].get("required", [])
            missing = [k for k in required if k not in data]
            extra = [k for k in data if k not in schemas[channel.id]["properties"]]
            if missing or extra:
                problems.append(f"{channel.topic}: missing {missing}, undeclared {extra}")
            if message.log_time != round(data["t"] * 1e9) and abs(
                message.log_time - data["t"] * 1e9
            ) > 1:
                problems.append(f"{channel.topic} step {data['step']}: log_time {message.log_time}")
            if not (channel.topic.startswith("/agent/") and channel.topic.endswith("/state")):
                continue
            agent = int(channel.topic.split("/")[2])
            key = (data["step"], agent)
            row = rows.get(key)
            if row is None:
                problems.append(f"state of step {key[0]} agent {agent}: no row in trajectory.csv")
                continue
            seen.add(key)
            if data["agent"] != agent or data["t"] != float(row["t"]):
                problems.append(f"step {key[0]} agent {agent}: agent/t differ")
            for field, cols in STATE_COLUMNS.items():
                want = [float(row[c]) for c in cols]
                if data[field] != want:
                    problems.append(f"step {key[0]} agent {agent} {field}: {data[field]} != {want}")
    for key in sorted(set(rows) - seen):
        problems.append(f"row step {key[0]} agent {key[1]}: no state message")
    print(json.dumps({
        "rows": len(rows),
        "states_compared": len(seen),
        "channels": len(schemas) + len(scene),
        "scene_channels": len(scene),
        "messages": per_topic,
        "problems": len(problems),
    }))
    for p in problems[:20]:
        print(p, file=sys.stderr)
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
