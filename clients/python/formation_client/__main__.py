"""`python -m formation_client inspect --agent I [--run ID|DIR] [--json] [--follow] [--count K]`:
agent I's live telemetry (1-based id), read with the iceoryx2 Python binding. `--json` prints one
object per sample with the keys of `formation inspect --json` (controller fields at the top
level, agent 1-based); without it, a short readable line. Exits 2 on bad input or when no run is
found, 1 when no sample arrives in time.
"""

import argparse
import json
import math
import sys
import time

from . import RunNotFound, connect, to_dict

#: How long to wait for the first sample, s (the service keeps the latest one, so a live run
#: answers at once).
FIRST_SAMPLE_S = 10.0
#: Poll interval while waiting, s.
POLL_S = 0.01


def _norm(v):
    # The same operations in the same order as `formation inspect`: the same float.
    return math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])


def telemetry_json(run_id, s):
    """A sample as `formation inspect --json` prints it (same keys, agent 1-based)."""
    d = to_dict(s)
    controller = d.pop("controller")
    d.update(controller)
    d["attitude_norm"] = _norm(d["attitude"])
    d["rate_norm"] = _norm(d["rate"])
    d["agent"] = s.agent + 1
    d["run"] = run_id
    return d


def inspect(argv):
    """`inspect`: parses `argv`, prints samples; the exit code."""
    p = argparse.ArgumentParser(prog="python -m formation_client inspect")
    p.add_argument("--agent", type=int, required=True, help="agent id, 1-based")
    p.add_argument("--run", help="run id (formation ps) or the run's output directory")
    p.add_argument("--json", action="store_true", help="one JSON object per sample")
    p.add_argument("--follow", action="store_true", help="keep printing until the run ends")
    p.add_argument("--count", type=int, default=1, help="samples to print without --follow")
    a = p.parse_args(argv)
    try:
        run = connect(a.run)
    except RunNotFound as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    if a.agent < 1 or (run.n_agents is not None and a.agent > run.n_agents):
        print(f"error: --agent {a.agent}: must be within 1..={run.n_agents}", file=sys.stderr)
        return 2
    with run:
        return _print_samples(run, a)


def _print_samples(run, a):
    sub = run.subscriber("formation/agent/{i}/telemetry", agent=a.agent)
    control = run.subscriber("formation/run/control")
    printed = 0
    deadline = time.monotonic() + FIRST_SAMPLE_S
    while a.follow or printed < a.count:
        s = run.receive(sub)
        if s is None:
            if run.receive(control) is not None:
                return 0  # the run stopped
            if printed == 0 and time.monotonic() > deadline:
                print(f"error: no telemetry from agent {a.agent} within {FIRST_SAMPLE_S} s",
                      file=sys.stderr)
                return 1
            if not run.wait(POLL_S):
                return 0
            continue
        if a.json:
            print(json.dumps(telemetry_json(run.id, s)), flush=True)
        else:
            print(f"agent {s.agent + 1} step {s.step} t = {s.t:.3f} s  formation error "
                  f"{s.formation_error_m:.4f} m  Gamma-hat {list(s.controller.gamma_hat)}",
                  flush=True)
        printed += 1
    return 0


def main(argv):
    if not argv or argv[0] != "inspect":
        print("usage: python -m formation_client inspect --agent I [--run ID|DIR] [--json]",
              file=sys.stderr)
        return 2
    return inspect(argv[1:])


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
