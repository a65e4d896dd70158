"""Client SDK for formation runs: watch a live run's iceoryx2 services, inject faults, delays,
crashes and link changes into it, and load a run's outputs, from Python.

    import formation_client as fc
    run = fc.connect()                     # the one running run, a run id, or its output directory
    sub = run.telemetry(2)                 # typed subscriber (1-based agent id); every service has one
    sample = sub.receive()                 # an AgentTelemetry (ctypes) or None
    run.inject_fault(2, gamma=[0.5] * 3, delta=[0, 0, 0.1], at=20.0)   # as `formation inject fault`
    tr = fc.load_trajectory("out/paper-proposed")                     # plain lists; .to_pandas()

Install: `pip install ./clients/python` (its only dependency is the PyPI binding iceoryx2 0.10.0).
From another machine, over the network: `formation_client.net` (`pip install './clients/python[net]'`,
the PyPI Zenoh binding) reads a run started with `formation run --zenoh-listen ENDPOINT`.
`python -m formation_client --help` lists the commands.

The ctypes structures (`formation_client.wire`) are generated from `formation schema --json`
and carry the exact iceoryx2 type names; tests check them against the schema.
"""

from . import inject, wire
from .inject import InjectRejected
from .results import Trajectory, load_summary, load_trajectory
from .run import Run, RunNotFound, Subscription, connect, live_runs, runs_dir
from .wire import *  # noqa: F401,F403  (the wire types)

__all__ = [
    "InjectRejected",
    "Run",
    "RunNotFound",
    "Subscription",
    "Trajectory",
    "connect",
    "inject",
    "live_runs",
    "load_summary",
    "load_trajectory",
    "runs_dir",
    "to_dict",
    "wire",
]


def to_dict(value):
    """A ctypes wire value as plain Python data: structures as dicts (without `_pad`), arrays as
    lists, numbers as they are (floats exactly)."""
    import ctypes

    if isinstance(value, ctypes.Structure):
        return {
            name: to_dict(getattr(value, name))
            for name, _ in value._fields_
            if name != "_pad"
        }
    if isinstance(value, ctypes.Array):
        return [to_dict(v) for v in value]
    return value
