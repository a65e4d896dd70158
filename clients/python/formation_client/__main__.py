"""`python -m formation_client COMMAND ...` (installed: `formation-client COMMAND ...`): the client
SDK's command line. Commands:

  ps        the live runs (id, directory, agents, orchestrator pid)
  inspect   agent I's live telemetry, as `formation inspect` (read with the iceoryx2 binding)
  inject    fault | delay | crash | hang | link: the same request as `formation inject`
  summary   a finished run's summary.json and trajectory.csv, in brief

Agent ids are 1-based. Exit codes: 0 success, 1 failure (no sample in time, injection rejected),
2 bad input or no run found.
"""

import argparse
import json
import math
import sys
import time

from . import RunNotFound, connect, live_runs, runs_dir, to_dict
from .inject import InjectRejected
from .results import load_summary, load_trajectory

#: How long to wait for the first sample, s (the service keeps the latest one, so a live run
#: answers at once).
FIRST_SAMPLE_S = 10.0
#: Poll interval while waiting, s.
POLL_S = 0.01


def _norm(v):
    # The same operations in the same order as `formation inspect`: the same float.
    return math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])


def agent_process(record, agent):
    """The process entry of agent `agent` (1-based) in a run's record, or None; its `host` is
    "local" for the launching machine (and in records written without hosts)."""
    for p in (record or {}).get("processes", []):
        if p.get("role") == "agent" and p.get("agent") == agent:
            return dict(p, host=p.get("host", "local"))
    return None


def telemetry_json(run_id, s, process=None):
    """A sample as `formation inspect --json` prints it (same keys, agent 1-based; `host` and
    `pid` of the agent's process from the run's record, None when it does not list it)."""
    d = to_dict(s)
    controller = d.pop("controller")
    d.update(controller)
    d["attitude_norm"] = _norm(d["attitude"])
    d["rate_norm"] = _norm(d["rate"])
    d["agent"] = s.agent + 1
    d["run"] = run_id
    d["host"] = process["host"] if process else None
    d["pid"] = process["pid"] if process else None
    return d


def _inspect_args(p):
    p.add_argument("--agent", type=int, required=True, help="agent id, 1-based")
    p.add_argument("--run", help="run id (formation ps) or the run's output directory")
    p.add_argument("--json", action="store_true", help="one JSON object per sample")
    p.add_argument("--follow", action="store_true", help="keep printing until the run ends")
    p.add_argument("--count", type=int, default=1, help="samples to print without --follow")


def inspect(a):
    """`inspect`: prints samples; the exit code."""
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


def ps(_a):
    """`ps`: one line (or JSON object with --json) per live run."""
    runs = live_runs()
    if getattr(_a, "json", False):
        print(json.dumps([{k: r.get(k) for k in ("id", "out_dir", "n_agents", "prefix")}
                          for r in runs]))
        return 0
    if not runs:
        print(f"no live run in {runs_dir()}")
    for r in runs:
        print(f"{r['id']}  {r.get('n_agents')} agents  pid {r['processes'][0]['pid']}  {r['out_dir']}")
    return 0


def _floats(text):
    return [float(v) for v in text.split(",")]


def _tau(text):
    """`0.03` or `base+amp*sin(w*t)` -> (base, amplitude, rate), as `formation inject delay`."""
    t = text.replace(" ", "")
    if "sin(" not in t:
        return float(t), 0.0, 0.0
    base, _, rest = t.partition("+")
    amp, _, rest = rest.partition("*sin(")
    rate = rest.split("*t)")[0]
    return float(base), float(amp), float(rate)


def inject_cmd(a):
    """`inject KIND`: sends the request, prints the run's confirmation line."""
    try:
        run = connect(a.run)
    except RunNotFound as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    with run:
        try:
            if a.kind == "fault":
                line = run.inject_fault(a.agent, _floats(a.gamma), _floats(a.delta), at=a.at)
            elif a.kind == "delay":
                base, amp, rate = _tau(a.tau)
                line = run.inject_delay(a.agent, base, amp, rate, at=a.at)
            elif a.kind in ("crash", "hang"):
                f = run.inject_crash if a.kind == "crash" else run.inject_hang
                line = f(a.agent, a.down, at=a.at)
            else:
                i, j = (int(v) for v in a.agents.split(","))
                line = run.inject_link(i, j, up=(a.state == "up"), at=a.at)
        except ValueError as e:
            print(f"error: {e}", file=sys.stderr)
            return 2
        except InjectRejected as e:
            print(f"error: {e}", file=sys.stderr)
            return 1
    if a.json:
        line["run"] = run.id
        print(json.dumps(line))
    else:
        print(f"{line['event']} injection of run {run.id} applies at step {line['step']} "
              f"(t = {line['t']:.3f} s)")
    return 0


def summary_cmd(a):
    """`summary DIR`: the run's scenario, duration, and per agent RMS error and violations."""
    try:
        s = load_summary(a.dir)
        tr = load_trajectory(a.dir)
    except (OSError, ValueError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    if a.json:
        print(json.dumps({"summary": s, "rows": len(tr), "columns": tr.columns}))
        return 0
    print(f"{a.dir}: scenario {s.get('scenario')}, variant {s.get('variant')}, "
          f"{len(tr)} rows of {len(tr.agents())} agents")
    for ag in s.get("agents", []):
        rms = ag.get("rms_formation_error_m") or {}
        print(f"  agent {ag.get('id')}: RMS formation error cover {rms.get('cover')} m, "
              f"enclose {rms.get('enclose')} m; violations attitude "
              f"{ag.get('attitude_constraint_violations')}, rate {ag.get('rate_constraint_violations')}")
    return 0


def parser():
    """The command line."""
    p = argparse.ArgumentParser(
        prog="python -m formation_client",
        description="Client SDK of formation runs: watch, inject into and load runs.",
    )
    sub = p.add_subparsers(dest="command", metavar="COMMAND", required=True)
    q = sub.add_parser("ps", help="the live runs")
    q.add_argument("--json", action="store_true")
    q.set_defaults(func=ps)
    q = sub.add_parser("inspect", help="an agent's live telemetry (as formation inspect)")
    _inspect_args(q)
    q.set_defaults(func=inspect)
    q = sub.add_parser("inject", help="inject a fault, delay, crash, hang or link change")
    kinds = q.add_subparsers(dest="kind", metavar="KIND", required=True)
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("--at", type=float, help="simulation time to apply at, s")
    common.add_argument("--run", help="run id (formation ps) or the run's output directory")
    common.add_argument("--json", action="store_true", help="print the run's confirmation")
    k = kinds.add_parser("fault", parents=[common], help="actuator fault Gamma, delta")
    k.add_argument("--agent", type=int, required=True)
    k.add_argument("--gamma", required=True, help="e.g. 0.5,0.5,0.5")
    k.add_argument("--delta", required=True, help="N m, e.g. 0,0,0.1")
    k = kinds.add_parser("delay", parents=[common], help="delay profile tau(t)")
    k.add_argument("--agent", type=int, required=True)
    k.add_argument("--tau", required=True, help="0.03 or 0.02+0.01*sin(0.5*t)")
    for name in ("crash", "hang"):
        k = kinds.add_parser(name, parents=[common], help=f"{name} of an agent's process")
        k.add_argument("--agent", type=int, required=True)
        k.add_argument("--down", type=float, required=True, help="s down")
    k = kinds.add_parser("link", parents=[common], help="a graph edge goes down or up")
    k.add_argument("--agents", required=True, help="the edge, e.g. 2,3")
    k.add_argument("--state", choices=("down", "up"), required=True)
    q.set_defaults(func=inject_cmd)
    q = sub.add_parser("summary", help="a run directory's summary.json and trajectory.csv")
    q.add_argument("dir")
    q.add_argument("--json", action="store_true")
    q.set_defaults(func=summary_cmd)
    return p


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
            process = agent_process(run.record, s.agent + 1)
            print(json.dumps(telemetry_json(run.id, s, process)), flush=True)
        else:
            print(f"agent {s.agent + 1} step {s.step} t = {s.t:.3f} s  formation error "
                  f"{s.formation_error_m:.4f} m  Gamma-hat {list(s.controller.gamma_hat)}",
                  flush=True)
        printed += 1
    return 0


def main(argv):
    a = parser().parse_args(argv)
    return a.func(a)


def run_cli():
    """Entry point of the installed `formation-client` command."""
    sys.exit(main(sys.argv[1:]))


if __name__ == "__main__":
    run_cli()
