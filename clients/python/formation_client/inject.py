"""Injections into a live run: the same `InjectRequest` as `formation inject` publishes on
`formation/inject/request`, a wake-up of the orchestrator, then the run's confirmation (its line of
`DIR/events.jsonl`, found by the request's nonce).

    import formation_client as fc
    with fc.connect() as run:
        line = run.inject_fault(agent=2, gamma=[0.5, 0.5, 0.5], delta=[0, 0, 0.1], at=20.0)
        print(line["step"], line["t"])       # where the run applies it

Agent ids are 1-based. `at` is simulation time in s: the run applies the injection at that step if
it is still ahead of it, else a few steps from now (as `formation inject`). The run validates every
request against its scenario; a rejected one raises `InjectRejected` with the run's reason.
"""

import json
import os
import time

from . import wire

# Request kinds (formation_config::protocol::messages::INJECT_*; checked against the Rust
# constants by tests/tests/python_sdk.rs).
INJECT_FAULT = 1
INJECT_DELAY = 2
INJECT_CRASH = 3
INJECT_HANG = 4
INJECT_LINK_DOWN = 5
INJECT_LINK_UP = 6
#: `at_step` of a request to apply as soon as possible.
INJECT_ASAP = 2**64 - 1

#: How long to wait for the run's confirmation, s (as `formation inject`).
CONFIRM_S = 10.0


class InjectRejected(Exception):
    """The run rejected the request (its `events.jsonl` line says why) or did not confirm it."""


def _nonce():
    return (time.time_ns() ^ (os.getpid() << 40)) & (2**64 - 1)


def _dt(run):
    """The run's step dt, s, from DIR/scenario.toml (`[simulation] dt_s`)."""
    section = None
    for line in (run.out_dir / "scenario.toml").read_text().splitlines():
        line = line.split("#", 1)[0].strip()
        if line.startswith("["):
            section = line.strip("[]").strip()
        elif section == "simulation" and line.startswith("dt_s"):
            return float(line.split("=", 1)[1])
    raise InjectRejected(f"{run.out_dir / 'scenario.toml'} has no [simulation] dt_s")


def _three(name, v):
    v = [float(x) for x in v]
    if len(v) != 3:
        raise ValueError(f"{name}: expected three values, got {len(v)}")
    return v


def request(run, kind, agent, at=None, **fields):
    """The `InjectRequest` of `kind` for agent `agent` (1-based) at `at` s (None: as soon as
    possible), with the kind's fields (gamma, delta, base_s, amplitude_s, angular_rate_rad_s,
    other (1-based), down_s)."""
    n = run.n_agents
    if agent < 1 or (n is not None and agent > n):
        raise ValueError(f"agent {agent}: must be within 1..={n}")
    r = wire.InjectRequest()
    r.nonce = _nonce()
    r.kind = kind
    r.agent = agent - 1
    if at is None:
        r.at_step = INJECT_ASAP
    else:
        if at < 0:
            raise ValueError(f"at {at}: must be >= 0 (simulation time, s)")
        r.at_step = round(at / _dt(run))
    for k in ("gamma", "delta"):
        if k in fields:
            getattr(r, k)[:] = _three(k, fields.pop(k))
    if "other" in fields:
        other = fields.pop("other")
        if other < 1 or (n is not None and other > n):
            raise ValueError(f"agent {other}: must be within 1..={n}")
        r.other = other - 1
    for k, v in fields.items():
        setattr(r, k, float(v))
    return r


def send(run, r, timeout=CONFIRM_S):
    """Publishes request `r`, wakes the orchestrator and returns the run's confirmation: its line
    of `events.jsonl` as a dict (`event`, `agent`, `step`, `t`, ...). Raises InjectRejected."""
    iox2 = run.iox2
    name = iox2.ServiceName.new("formation/inject/request")
    svc = run.node.service_builder(name).publish_subscribe(wire.InjectRequest).open()
    publisher = svc.publisher_builder().create()
    wake_name = iox2.ServiceName.new("formation/wake/orchestrator")
    wake_svc = run.node.service_builder(wake_name).event().open()
    notifier = wake_svc.notifier_builder().create()
    try:
        publisher.send_copy(r)
        notifier.notify()
        events = run.out_dir / "events.jsonl"
        needle = f'"nonce":{r.nonce}'
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            try:
                text = events.read_text()
            except OSError:
                text = ""
            for line in text.split("\n")[:-1]:  # whole lines only
                if needle in line:
                    v = json.loads(line)
                    if v.get("event") == "rejected":
                        raise InjectRejected(f"the run rejected the injection: {v.get('error')}")
                    return v
            time.sleep(0.02)
        raise InjectRejected(f"the run did not confirm the injection within {timeout} s")
    finally:
        # The publisher lives until the confirmation: the sample cannot be lost.
        del publisher, notifier, svc, wake_svc


def fault(run, agent, gamma, delta, at=None):
    """Actuator fault of `agent`: Gamma (each in (0, 1]) and delta (N m) from the apply step on."""
    return send(run, request(run, INJECT_FAULT, agent, at, gamma=gamma, delta=delta))


def delay(run, agent, base_s, amplitude_s=0.0, angular_rate_rad_s=0.0, at=None):
    """Delay profile tau(t) = base + amplitude sin(rate t) of `agent`, s."""
    return send(run, request(run, INJECT_DELAY, agent, at, base_s=base_s,
                             amplitude_s=amplitude_s, angular_rate_rad_s=angular_rate_rad_s))


def crash(run, agent, down_s, at=None):
    """`agent`'s process is killed at the apply step; a new one takes over `down_s` s later."""
    return send(run, request(run, INJECT_CRASH, agent, at, down_s=down_s))


def hang(run, agent, down_s, at=None):
    """`agent`'s process is stopped at the apply step and replaced `down_s` s later."""
    return send(run, request(run, INJECT_HANG, agent, at, down_s=down_s))


def link(run, a, b, up, at=None):
    """The graph edge {a, b} (1-based) goes down (`up=False`) or comes back (`up=True`)."""
    kind = INJECT_LINK_UP if up else INJECT_LINK_DOWN
    return send(run, request(run, kind, a, at, other=b))
