#!/usr/bin/env python3
"""Checks the ctypes structures of formation_client.wire against `formation schema --json`:
`python3 check_layout.py schema.json` exits 0 when every type of the schema exists with the same
size, alignment, iceoryx2 type name and fields (names, offsets, sizes, in order), and 1 naming
every difference otherwise. Needs only the standard library (not the iceoryx2 binding)."""

import ctypes
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from formation_client import wire  # noqa: E402


def differences(schema):
    out = []
    for t in schema["types"]:
        name = t["name"]
        cls = getattr(wire, name, None)
        if cls is None:
            out.append(f"{name}: missing")
            continue
        if ctypes.sizeof(cls) != t["size"]:
            out.append(f"{name}: size {ctypes.sizeof(cls)} != {t['size']}")
        if ctypes.alignment(cls) != t["align"]:
            out.append(f"{name}: align {ctypes.alignment(cls)} != {t['align']}")
        iox = t.get("iceoryx2")
        if iox is not None and getattr(cls, "type_name", lambda: None)() != iox:
            out.append(f"{name}: type_name is not {iox}")
        names = [f[0] for f in cls._fields_]
        if names != [f["name"] for f in t["fields"]]:
            out.append(f"{name}: fields {names} != {[f['name'] for f in t['fields']]}")
            continue
        for f in t["fields"]:
            d = getattr(cls, f["name"])
            if (d.offset, d.size) != (f["offset"], f["size"]):
                out.append(f"{name}.{f['name']}: offset/size {(d.offset, d.size)} != "
                           f"{(f['offset'], f['size'])}")
    for pattern, (_, msg, _) in wire.SERVICES.items():
        if not any(s["pattern"] == pattern for s in schema["services"]):
            out.append(f"service {pattern}: not in the schema")
    for s in schema["services"]:
        if s["pattern"] not in wire.SERVICES:
            out.append(f"service {s['pattern']}: missing from wire.SERVICES")
    return out


def main():
    schema = json.loads(Path(sys.argv[1]).read_text())
    diff = differences(schema)
    for d in diff:
        print(d, file=sys.stderr)
    print(f"{len(schema['types'])} types, {len(schema['services'])} services: "
          f"{'ok' if not diff else f'{len(diff)} differences'}")
    return 1 if diff else 0


if __name__ == "__main__":
    sys.exit(main())
