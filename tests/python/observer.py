"""Outside observer of a live run, for tests/tests/python_client.rs: attaches with the SDK
(clients/python) to agent 2's telemetry, to the states of agents 1 and 2 (extra subscribers next
to the agents' own), to agent 1's wake-up event (a listener next to the agent's own) and to the
run control, and prints one JSON line per sample until the run publishes its stop:
{"telemetry": {...}}, {"state": {...}} (each with "raw": the sample's bytes in hex, which the test
reads back into the Rust struct: exact floats, whatever a JSON parser rounds), then
{"end": {"stop_step": k, "wakeups": w}}.

usage: python observer.py RUN_ID
"""

import json
import sys
import time

import formation_client as fc

run = fc.connect(sys.argv[1], node_name="fm-test-observer")
# The services exist before the run is listed, so they open at once.
telemetry = run.subscriber("formation/agent/{i}/telemetry", agent=2)
states = [run.subscriber("formation/agent/{i}/state", agent=a) for a in (1, 2)]
wake = run.listener("formation/wake/agent/{i}", agent=1)
control = run.subscriber("formation/run/control")
print(json.dumps({"attached": run.id}), flush=True)
wakeups = 0
deadline = time.monotonic() + 600
while time.monotonic() < deadline:
    wakeups += wake.wait(0.001)
    while (s := run.receive(telemetry)) is not None:
        print(json.dumps({"telemetry": fc.to_dict(s), "raw": bytes(s).hex()}), flush=True)
    for sub in states:
        while (s := run.receive(sub)) is not None:
            print(json.dumps({"state": fc.to_dict(s), "raw": bytes(s).hex()}), flush=True)
    c = run.receive(control)
    if c is not None and c.kind == 1:
        print(json.dumps({"end": {"stop_step": c.step, "wakeups": wakeups}}), flush=True)
        break
run.close()
