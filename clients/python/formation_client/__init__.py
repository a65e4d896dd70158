"""Client SDK for formation runs: watch a live run's iceoryx2 services from Python.

    import formation_client as fc
    run = fc.connect()                     # the one running run, a run id, or its output directory
    sub = run.subscriber("formation/agent/{i}/telemetry", agent=2)   # 1-based agent id
    sample = run.receive(sub)              # an AgentTelemetry (ctypes) or None

The ctypes structures (`formation_client.wire`) are generated from `formation schema --json`
and carry the exact iceoryx2 type names; tests check them against the schema.
"""

from . import wire
from .run import Run, RunNotFound, connect, live_runs, runs_dir
from .wire import *  # noqa: F401,F403  (the wire types)

__all__ = ["Run", "RunNotFound", "connect", "live_runs", "runs_dir", "wire", "to_dict"]


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
