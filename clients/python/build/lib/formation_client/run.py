"""Finding a run and opening its services (iceoryx2 0.10 Python binding, PyPI `iceoryx2==0.10.0`).

A run is found from its registry record (`<runs dir>/<id>.json`, written by `formation run`) or
from its output directory, which holds the run's iceoryx2 config `iox2/config/iceoryx2.toml`
(the run's prefix `fm<run id>_`): a node created with it sees exactly that run's services.
"""

import ctypes
import json
import os
from pathlib import Path

from . import wire

RECORD_FORMAT = "formation-run-record/1"
CONFIG = Path("iox2") / "config" / "iceoryx2.toml"


class RunNotFound(Exception):
    """No run matches (or several do and none was named)."""


def runs_dir():
    """The runs folder `formation run` registers in: $FORMATION_RUNS_DIR, else
    $XDG_RUNTIME_DIR/formation/runs, else /tmp/formation-runs-<uid>."""
    d = os.environ.get("FORMATION_RUNS_DIR")
    if d:
        return Path(d)
    x = os.environ.get("XDG_RUNTIME_DIR")
    if x:
        return Path(x) / "formation" / "runs"
    return Path(f"/tmp/formation-runs-{os.getuid()}")


def _alive(pid):
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def live_runs():
    """The records of the runs whose orchestrator is alive, oldest first."""
    out = []
    d = runs_dir()
    if not d.is_dir():
        return out
    for p in sorted(d.glob("*.json")):
        try:
            r = json.loads(p.read_text())
        except (OSError, ValueError):
            continue
        if r.get("format") != RECORD_FORMAT or not r.get("processes"):
            continue
        if _alive(r["processes"][0]["pid"]):
            out.append(r)
    return sorted(out, key=lambda r: r.get("started_unix_s", 0.0))


def _resolve(run_dir_or_id):
    """(output directory, record or None) of the run named by an id, a directory or nothing."""
    if run_dir_or_id is not None and (Path(run_dir_or_id) / CONFIG).is_file():
        d = Path(run_dir_or_id).resolve()
        rec = next((r for r in live_runs() if Path(r["out_dir"]).resolve() == d), None)
        return d, rec
    runs = live_runs()
    if run_dir_or_id is None:
        if len(runs) != 1:
            raise RunNotFound(
                f"{len(runs)} runs are running in {runs_dir()}: name one by its id or directory"
            )
        return Path(runs[0]["out_dir"]), runs[0]
    rec = next((r for r in runs if r["id"] == run_dir_or_id), None)
    if rec is None:
        raise RunNotFound(f"no running run with id or directory {run_dir_or_id!r}")
    return Path(rec["out_dir"]), rec


class Subscription:
    """A subscriber on one service with its message class (keeps the service open).
    `receive()` returns an instance of `message` (a list of them for a slice service such as
    `formation/plant/steps`, one per agent)."""

    def __init__(self, service, subscriber, message, is_slice=False):
        self.service = service
        self.subscriber = subscriber
        self.message = message
        self.is_slice = is_slice

    def close(self):
        """Releases the subscriber and the service."""
        self.subscriber = self.service = None

    def receive(self):
        """The next sample copied out of shared memory (a ctypes value), or None."""
        sample = self.subscriber.receive()
        if sample is None:
            return None
        size = ctypes.sizeof(self.message)
        if self.is_slice:
            items = sample.payload()
            value = [
                self.message.from_buffer_copy(ctypes.string_at(sample.payload_ptr + k * size, size))
                for k in range(items.number_of_elements)
            ]
        else:
            value = self.message.from_buffer_copy(ctypes.string_at(sample.payload_ptr, size))
        sample.delete()
        return value


class Wakeups:
    """A listener on one event service (keeps the service open)."""

    def __init__(self, iox2, service, listener):
        self.iox2 = iox2
        self.service = service
        self.listener = listener

    def close(self):
        """Releases the listener and the service."""
        self.listener = self.service = None

    def wait(self, seconds):
        """Sleeps until a wake-up or `seconds`; the number of wake-ups received."""
        return len(self.listener.timed_wait(self.iox2.Duration.from_secs_f64(seconds)))

    def take(self):
        """The number of wake-ups received since the last call, without waiting."""
        return len(self.listener.try_wait())


class Run:
    """A connection to a live run: one iceoryx2 node under the run's prefix."""

    def __init__(self, out_dir, record, node_name):
        import iceoryx2 as iox2

        self.iox2 = iox2
        self.out_dir = Path(out_dir)
        self.record = record
        self.id = record["id"] if record else None
        self.n_agents = record["n_agents"] if record else None
        self.prefix = record["prefix"] if record else _prefix_of(self.out_dir / CONFIG)
        iox2.set_log_level_from_env_or(iox2.LogLevel.Error)
        self.config = iox2.config.from_file(iox2.FilePath.new(str(self.out_dir / CONFIG)))
        self._ports = []
        self.node = (
            iox2.NodeBuilder.new()
            .config(self.config)
            .name(iox2.NodeName.new(node_name))
            .create(iox2.ServiceType.Ipc)
        )

    @staticmethod
    def service_name(pattern, agent=None):
        """The name of a service of the table; `agent` is the 1-based agent id for a per-agent one."""
        if "{i}" in pattern:
            if agent is None:
                raise ValueError(f"{pattern} is per agent: give agent=<1-based id>")
            return pattern.replace("{i}", str(agent - 1))
        return pattern

    def subscriber(self, pattern, agent=None):
        """A subscriber on a publish-subscribe service of the table (see `wire.SERVICES`)."""
        _scope, t, is_slice = wire.SERVICES[pattern]
        if t is None:
            raise ValueError(f"{pattern} is an event service: use listener()")
        payload = self.iox2.Slice[t] if is_slice else t
        name = self.iox2.ServiceName.new(self.service_name(pattern, agent))
        svc = self.node.service_builder(name).publish_subscribe(payload).open()
        port = Subscription(svc, svc.subscriber_builder().create(), t, is_slice)
        self._ports.append(port)
        return port

    def listener(self, pattern, agent=None):
        """A listener on an event service of the table (a wake-up)."""
        name = self.iox2.ServiceName.new(self.service_name(pattern, agent))
        svc = self.node.service_builder(name).event().open()
        port = Wakeups(self.iox2, svc, svc.listener_builder().create())
        self._ports.append(port)
        return port

    # Typed subscribers, one per publish-subscribe service of the table (`formation schema`).

    def reference(self):
        """`formation/reference`: ReferenceFrame (virtual leader, target, offsets) per step."""
        return self.subscriber("formation/reference")

    def state(self, agent):
        """`formation/agent/{i}/state`: VehicleState of quadrotor `agent` (1-based)."""
        return self.subscriber("formation/agent/{i}/state", agent=agent)

    def share(self, agent):
        """`formation/agent/{i}/share`: NeighbourState agent `agent` shares with its neighbours."""
        return self.subscriber("formation/agent/{i}/share", agent=agent)

    def command(self, agent):
        """`formation/agent/{i}/command`: ControlCommand of agent `agent`."""
        return self.subscriber("formation/agent/{i}/command", agent=agent)

    def telemetry(self, agent):
        """`formation/agent/{i}/telemetry`: AgentTelemetry of agent `agent`."""
        return self.subscriber("formation/agent/{i}/telemetry", agent=agent)

    def steps(self):
        """`formation/plant/steps`: the step records, a list of N StepEntry per step."""
        return self.subscriber("formation/plant/steps")

    def control(self):
        """`formation/run/control`: RunControl (kind 1: the run stops)."""
        return self.subscriber("formation/run/control")

    def progress(self):
        """`formation/run/progress`: RunProgress (steps recorded)."""
        return self.subscriber("formation/run/progress")

    def hello(self):
        """`formation/run/hello`: Hello of each role process that starts."""
        return self.subscriber("formation/run/hello")

    def runtime_events(self):
        """`formation/run/events`: RuntimeEvent (crashes, hangs, links, losses, restarts)."""
        return self.subscriber("formation/run/events")

    def fault_injections(self):
        """`formation/inject/fault`: FaultInjection forwarded to the plant."""
        return self.subscriber("formation/inject/fault")

    def delay_injections(self):
        """`formation/inject/delay`: DelayInjection forwarded to the agents."""
        return self.subscriber("formation/inject/delay")

    def inject_requests(self):
        """`formation/inject/request`: InjectRequest of every client (as `formation inject`)."""
        return self.subscriber("formation/inject/request")

    # Injections (`formation_client.inject`): each returns the run's events.jsonl line.

    def inject_fault(self, agent, gamma, delta, at=None):
        """Actuator fault of `agent` (1-based): Gamma, delta (N m); `at` in s or None."""
        from . import inject

        return inject.fault(self, agent, gamma, delta, at)

    def inject_delay(self, agent, base_s, amplitude_s=0.0, angular_rate_rad_s=0.0, at=None):
        """Delay tau(t) = base + amplitude sin(rate t) of `agent`, s."""
        from . import inject

        return inject.delay(self, agent, base_s, amplitude_s, angular_rate_rad_s, at)

    def inject_crash(self, agent, down_s, at=None):
        """Crash of `agent`'s process, replaced `down_s` s later."""
        from . import inject

        return inject.crash(self, agent, down_s, at)

    def inject_hang(self, agent, down_s, at=None):
        """Hang of `agent`'s process, replaced `down_s` s later."""
        from . import inject

        return inject.hang(self, agent, down_s, at)

    def inject_link(self, a, b, up, at=None):
        """The edge {a, b} goes down (up=False) or comes back (up=True)."""
        from . import inject

        return inject.link(self, a, b, up, at)

    @staticmethod
    def receive(sub):
        """The next sample of a Subscription (a ctypes value), or None."""
        return sub.receive()

    def close(self):
        """Detaches from the run. When the run is over and no other node of it is alive, also
        removes the shared-memory file iceoryx2 leaves under the run's prefix (the run's own
        clean-up leaves the files of a node still attached to that node)."""
        node = getattr(self, "node", None)
        if node is None:
            return
        config = self.config
        for port in self._ports:
            port.close()
        self._ports = []
        self.node = None
        del node
        import gc

        gc.collect()
        over = self.record is None or not _alive(self.record["processes"][0]["pid"])
        if over and self.prefix and not self.iox2.Node.list(self.iox2.ServiceType.Ipc, config):
            for f in Path("/dev/shm").glob(f"{self.prefix}*"):
                try:
                    f.unlink()
                except OSError:
                    pass

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def wait(self, seconds):
        """Sleeps up to `seconds` (lets Ctrl-C through); False once the node should stop."""
        try:
            self.node.wait(self.iox2.Duration.from_secs_f64(seconds))
        except Exception:
            return False
        return True


def _prefix_of(config_path):
    """The iceoryx2 prefix a run's config file sets (`[global] prefix = 'fm<id>_'`)."""
    for line in config_path.read_text().splitlines():
        k, _, v = line.partition("=")
        if k.strip() == "prefix":
            return v.strip().strip("'\"")
    return None


def connect(run_dir_or_id=None, node_name="fm-observer-py"):
    """Connects to a live run: `run_dir_or_id` is its id (`formation ps`), its output directory, or
    None for the only run running. Raises RunNotFound."""
    d, rec = _resolve(run_dir_or_id)
    if not (d / CONFIG).is_file():
        raise RunNotFound(f"{d / CONFIG} does not exist: not the directory of a run")
    return Run(d, rec, node_name)
