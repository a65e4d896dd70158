"""A reader of a live run over the network, for tests/tests/python_zenoh.rs: connects with
`formation_client.net` (PyPI `eclipse-zenoh`) to the run's export, asks the info, subscribes to
every quadrotor's state and to the step records, and prints JSON lines:
{"info": {...}} once, then {"state": {...}, "raw": hex} for the first STATES states of every agent
whose step is a multiple of EVERY (the steps `trajectory.csv` records), {"steps": k, "n": N,
"positions": [...]} for one step record, and {"end": {"received": r, "dropped": d}}.

usage: python net_reader.py ENDPOINT STATES EVERY
"""

import json
import sys
import time

import formation_client as fc
import formation_client.net as fnet
from net_common import first_run

endpoint, wanted, every = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
deadline = time.monotonic() + 120
with fnet.connect(endpoint, retry_s=60) as net:
    info = first_run(net, deadline)
    print(json.dumps({"info": info}), flush=True)
    run_id, n = info["run_id"], info["n_agents"]
    states = net.states(run_id)
    steps = net.steps(run_id)
    got = {a: 0 for a in range(1, n + 1)}
    received, record = 0, None
    while min(got.values()) < wanted or record is None:
        if time.monotonic() > deadline:
            sys.exit(f"timed out: states per agent {got}, a step record: {record is not None}")
        r = states.receive(timeout=0.5)
        if r is not None:
            received += 1
            s = r.value
            assert s.agent + 1 == r.agent, (s.agent, r.key)
            if s.step % every == 0 and got[r.agent] < wanted:
                got[r.agent] += 1
                print(json.dumps({"state": fc.to_dict(s), "raw": bytes(s).hex()}), flush=True)
        if record is None:
            e = steps.receive()
            if e is not None:
                record = e.value
                print(json.dumps({
                    "steps": record[0].truth.state.step, "n": len(record),
                    "positions": [list(x.truth.state.position) for x in record],
                }), flush=True)
    print(json.dumps({"end": {"received": received, "dropped": states.dropped}}), flush=True)
