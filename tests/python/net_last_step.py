"""A reader that keeps up with a live run over the network, for tests/tests/python_zenoh.rs:
connects with `formation_client.net` (PyPI `eclipse-zenoh`) to the run's export, subscribes to
every quadrotor's state and to the end marker `formation/<run>/end`, and reads until the end
marker and the last step of every quadrotor are in (or its deadline). Prints one JSON line:
{"info": {...}, "last": {agent: highest step}, "received": r, "gaps": g, "dropped": d,
 "end": {...the end marker...}}. `gaps`: steps missing between two states of one quadrotor.

usage: python net_last_step.py ENDPOINT
"""

import json
import sys
import threading
import time

import formation_client.net as fnet
from net_common import first_run

endpoint = sys.argv[1]
deadline = time.monotonic() + 150
with fnet.connect(endpoint, retry_s=60) as net:
    info = first_run(net, deadline)
    run_id, n, steps = info["run_id"], info["n_agents"], info["steps"]
    states = net.states(run_id)
    end = {}
    ended = threading.Event()

    def on_end(sample):
        end.update(json.loads(sample.payload.to_bytes()))
        ended.set()

    end_sub = net.session.declare_subscriber(f"formation/{run_id}/end", on_end)
    last = {a: -1 for a in range(1, n + 1)}
    received = gaps = 0
    while time.monotonic() < deadline:
        r = states.receive(timeout=0.2)
        if r is not None:
            received += 1
            step = r.value.step
            if step > last[r.agent] + 1:
                gaps += step - last[r.agent] - 1
            last[r.agent] = max(last[r.agent], step)
        elif ended.is_set():
            break
    end_sub.undeclare()
    print(json.dumps({"info": {"run_id": run_id, "steps": steps}, "last": last,
                      "received": received, "gaps": gaps, "dropped": states.dropped,
                      "end": end}), flush=True)
