"""Reading a run from another machine over Zenoh (PyPI `eclipse-zenoh`, the extra `net`:
`pip install './clients/python[net]'`), beside the iceoryx2 connection of `formation_client.run`.

A run exports its telemetry when started with `formation run --zenoh-listen ENDPOINT`
(docs/multi-host.md, "Outside clients over the network"). Keys, under `formation/<run id>/`:
`info` (a queryable answering JSON), `state/<agent>` (VehicleState, every step), `steps` (N
StepEntry per step), `reference` (ReferenceFrame), `events` (RuntimeEvent), `telemetry/<agent>`
(AgentTelemetry); agent ids are 1-based. Payloads are the run's `#[repr(C)]` wire bytes, decoded
here by the same ctypes classes as the iceoryx2 path (`formation_client.wire`); the encoding is
`application/octet-stream;<wire type name>`.

    import formation_client.net as fnet
    with fnet.connect("tcp/127.0.0.1:7448") as net:
        info = net.runs()[0]                           # every run reachable, as its info JSON
        states = net.states(info["run_id"])            # every quadrotor's state, every step
        got = states.receive(timeout=5.0)              # a Received: .agent, .value (VehicleState)
        print(got.agent, got.value.step, list(got.value.position))
"""

import collections
import ctypes
import json
import threading
import time
from pathlib import Path

from . import wire

#: Where `formation run --zenoh-listen` is usually asked to listen in the docs' examples.
DEFAULT_ENDPOINT = "tcp/127.0.0.1:7448"
#: The `format` of the info a run answers.
INFO_FORMAT = "formation-zenoh-info/1"
#: Samples a subscription keeps before it drops the oldest (a slow reader loses the oldest).
DEFAULT_QUEUE = 4096

#: Every wire type by its versioned type name (`VehicleState.type_name()`, ...).
TYPES = {
    cls.type_name(): cls
    for cls in vars(wire).values()
    if isinstance(cls, type) and issubclass(cls, ctypes.Structure) and hasattr(cls, "type_name")
}


class NetError(Exception):
    """A payload that is not what its encoding says, or no run answered."""


def decode(encoding, payload):
    """The ctypes value(s) of a payload: one instance for a payload of one sample, a list for a
    payload of several back to back (the `steps` key: N StepEntry). `encoding` is the sample's
    encoding as text, `application/octet-stream;<wire type name>`."""
    schema = str(encoding).partition(";")[2]
    cls = TYPES.get(schema)
    if cls is None:
        raise NetError(f"unknown wire type {schema!r} (encoding {encoding!s})")
    size = ctypes.sizeof(cls)
    data = bytes(payload)
    if len(data) == size:
        return cls.from_buffer_copy(data)
    if data and len(data) % size == 0:
        return [cls.from_buffer_copy(data, k * size) for k in range(len(data) // size)]
    raise NetError(f"{len(data)} bytes are not a whole number of {schema} ({size} bytes each)")


class Received:
    """One sample: its key, the topic (`state`, `steps`, ...), the 1-based agent id of a
    per-agent key (else None) and the decoded value."""

    __slots__ = ("key", "topic", "agent", "value")

    def __init__(self, key, topic, agent, value):
        self.key, self.topic, self.agent, self.value = key, topic, agent, value

    def __repr__(self):
        return f"Received({self.key!r}, agent={self.agent})"


def _parse_key(key):
    """(run id, topic, agent or None) of `formation/<run>/<topic>[/<agent>]`."""
    parts = str(key).split("/")
    agent = int(parts[3]) if len(parts) > 3 and parts[3].isdigit() else None
    return parts[1], parts[2], agent


class Subscription:
    """A Zenoh subscriber on one key expression; samples wait in a bounded queue (the oldest is
    dropped when it is full: `dropped` counts them)."""

    def __init__(self, session, key_expr, capacity=DEFAULT_QUEUE):
        self.key_expr = key_expr
        self.dropped = 0
        self._queue = collections.deque()
        self._capacity = capacity
        self._ready = threading.Condition()
        self._sub = session.declare_subscriber(key_expr, self._on_sample)

    def _on_sample(self, sample):
        item = (str(sample.key_expr), str(sample.encoding), sample.payload.to_bytes())
        with self._ready:
            if len(self._queue) >= self._capacity:
                self._queue.popleft()
                self.dropped += 1
            self._queue.append(item)
            self._ready.notify()

    def receive(self, timeout=None):
        """The next sample as a Received, waiting up to `timeout` s (None: no wait); None if
        nothing came."""
        with self._ready:
            if not self._queue and timeout:
                self._ready.wait_for(lambda: self._queue, timeout)
            if not self._queue:
                return None
            key, encoding, payload = self._queue.popleft()
        _run, topic, agent = _parse_key(key)
        return Received(key, topic, agent, decode(encoding, payload))

    def close(self):
        """Undeclares the subscriber."""
        if self._sub is not None:
            self._sub.undeclare()
            self._sub = None


def _credentials(auth):
    """(user, password) from a `user:password` file (its first line) or a pair."""
    if auth is None or isinstance(auth, (tuple, list)):
        return auth
    for line in Path(auth).read_text().splitlines():
        user, sep, password = line.strip().partition(":")
        if sep and user and password:
            return user, password
    raise NetError(f"{auth}: expected user:password lines")


class Connection:
    """A Zenoh session connected to a run's export (`formation run --zenoh-listen`)."""

    def __init__(self, endpoint=DEFAULT_ENDPOINT, auth=None, mode="client"):
        import zenoh

        self.zenoh = zenoh
        self.endpoint = endpoint
        conf = zenoh.Config()
        conf.insert_json5("mode", json.dumps(mode))
        conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
        conf.insert_json5("scouting/multicast/enabled", "false")
        creds = _credentials(auth)
        if creds:
            conf.insert_json5("transport/auth/usrpwd/user", json.dumps(creds[0]))
            conf.insert_json5("transport/auth/usrpwd/password", json.dumps(creds[1]))
        self.session = zenoh.open(conf)
        self._subs = []

    def runs(self, timeout=2.0):
        """The info (a dict) of every run reachable, oldest id first."""
        out = []
        for reply in self.session.get("formation/*/info", timeout=timeout):
            sample = reply.ok
            if sample is None:
                continue
            info = json.loads(sample.payload.to_bytes())
            if info.get("format") == INFO_FORMAT:
                out.append(info)
        return sorted(out, key=lambda i: i["run_id"])

    def info(self, run_id=None, timeout=2.0):
        """The info of run `run_id`, or of the only run reachable; NetError otherwise."""
        runs = [i for i in self.runs(timeout) if run_id is None or i["run_id"] == run_id]
        if len(runs) != 1:
            raise NetError(
                f"{len(runs)} runs answer at {self.endpoint}"
                + (f" with id {run_id}" if run_id else ": name one by its id")
            )
        return runs[0]

    def subscribe(self, run_id, topic, agent=None, capacity=DEFAULT_QUEUE):
        """A Subscription to `formation/<run_id>/<topic>[/<agent>]`; a per-agent topic without
        `agent` subscribes to every agent (`/*`)."""
        key = f"formation/{run_id}/{topic}"
        if topic in ("state", "telemetry"):
            key += f"/{agent if agent is not None else '*'}"
        sub = Subscription(self.session, key, capacity)
        self._subs.append(sub)
        return sub

    def states(self, run_id, agent=None):
        """VehicleState of quadrotor `agent` (1-based; None: every quadrotor), every step."""
        return self.subscribe(run_id, "state", agent)

    def steps(self, run_id):
        """The step records: a list of N StepEntry per step (plant truth and command)."""
        return self.subscribe(run_id, "steps")

    def reference(self, run_id):
        """The leader's ReferenceFrame of every step."""
        return self.subscribe(run_id, "reference")

    def events(self, run_id):
        """RuntimeEvent: crashes, hangs, links, losses, takeovers."""
        return self.subscribe(run_id, "events")

    def telemetry(self, run_id, agent=None):
        """AgentTelemetry of agent `agent` (1-based; None: every agent)."""
        return self.subscribe(run_id, "telemetry", agent)

    def close(self):
        """Undeclares every subscription and closes the session."""
        for s in self._subs:
            s.close()
        self._subs = []
        if self.session is not None:
            self.session.close()
            self.session = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def connect(endpoint=DEFAULT_ENDPOINT, auth=None, retry_s=0.0):
    """A Connection to the export listening at `endpoint`; `auth` is the `user:password` file
    (or pair) of an export listening beyond loopback. Retries for up to `retry_s` s while nothing
    listens there yet."""
    deadline = time.monotonic() + retry_s
    while True:
        try:
            return Connection(endpoint, auth)
        except Exception:  # zenoh.ZError: nothing listens there (yet)
            if time.monotonic() >= deadline:
                raise
            time.sleep(0.05)
