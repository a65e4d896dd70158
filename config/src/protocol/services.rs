//! The service table: every service of a run, declared once — its name pattern, its message type,
//! who publishes and who subscribes, and the limits it is created with.
//!
//! A [`Topic<T>`] ties a name to its message type `T`: ports are opened from the topic
//! (`node::ports::publisher(node, &VEHICLE_STATE.at(i))` gives a `Publisher<VehicleState>`), so a
//! name used with the wrong type does not compile. The orchestrator creates every service by walking
//! the table ([`visit`]) with limits sized for the run ([`Sizing`]); the role processes only open
//! them: an iceoryx2 service's limits (publishers, subscribers, buffers) are set by the process
//! that creates it (docs/runtime.md).
//!
//! Names are relative to the run's iceoryx2 prefix ([`run_prefix`]), so concurrent runs never see
//! each other. Per-agent names carry the 0-based agent index (`formation/agent/0/state` is agent 1's).

use super::layout::WireLayout;
use super::messages::{Hello, InjectRequest, RunControl, RunProgress, RuntimeEvent, StepEntry};
use super::pacing::{
    realtime_steps_buffer, CONTROL_BUFFER, LOCKSTEP_BUFFER, REFERENCE_BUFFER, STEPS_BUFFER,
};
use super::wire::{
    AgentTelemetry, ControlCommand, DelayInjection, FaultInjection, NeighbourState, ReferenceFrame,
    VehicleState,
};
use core::marker::PhantomData;

/// iceoryx2 global prefix of a run: `fm<run_id>_` (short: it becomes part of file names in /dev/shm).
pub fn run_prefix(run_id: &str) -> String {
    format!("fm{run_id}_")
}

/// Most concurrent client processes (`formation inspect`, `ps`, `inject`) a run admits.
pub const MAX_CLIENTS: usize = 8;

/// Default number of outside observers a run admits (`formation run --observers K`): spare
/// subscriber / listener slots on every service and spare node slots, for programs the run does
/// not know about (a Python client, `iox2 service subscribe`, `iox2 service listen`). A few cost
/// little (shared memory for their buffers) and leave room to watch while `formation inspect` runs.
pub const DEFAULT_OBSERVERS: usize = 4;

/// Most outside observers `formation run --observers` accepts (each one adds a subscriber buffer
/// to every service; on a realtime run the step records alone take 1024 samples x N x 696 B per
/// observer, 3.6 MB at N = 5).
pub const MAX_OBSERVERS: usize = 64;

/// A message type that crosses a process boundary: `#[repr(C)]`, `Copy`, and (feature `ipc`)
/// iceoryx2's `ZeroCopySend` with an explicit, versioned type name; its field table is
/// [`WireLayout`].
#[cfg(feature = "ipc")]
pub trait Message:
    core::fmt::Debug + Copy + iceoryx2::prelude::ZeroCopySend + WireLayout + 'static
{
}
/// A message type that crosses a process boundary: `#[repr(C)]`, `Copy`, and (feature `ipc`)
/// iceoryx2's `ZeroCopySend` with an explicit, versioned type name.
#[cfg(not(feature = "ipc"))]
pub trait Message: core::fmt::Debug + Copy + WireLayout + 'static {}

macro_rules! messages {
    ($($t:ty),* $(,)?) => { $(impl Message for $t {})* };
}
messages!(
    VehicleState,
    NeighbourState,
    ReferenceFrame,
    ControlCommand,
    FaultInjection,
    DelayInjection,
    AgentTelemetry,
    RunControl,
    RunProgress,
    Hello,
    StepEntry,
    InjectRequest,
    RuntimeEvent,
);

/// The iceoryx2 type name of a message (its `#[type_name("formation.vN.X")]`): what an outside
/// client must declare to open the service.
#[cfg(feature = "ipc")]
pub fn wire_type_name<T: Message>() -> &'static str {
    // SAFETY: reading the name has no precondition; the trait's safety contract binds the
    // implementer (the layout behind the name), which `Message` types uphold with `#[repr(C)]`.
    unsafe { <T as iceoryx2::prelude::ZeroCopySend>::type_name() }
}

/// A process (or set of processes) that opens ports on a service.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Party {
    /// `formation run`'s own process.
    Orchestrator,
    /// The plant process.
    Plant,
    /// The leader process.
    Leader,
    /// Agent i, for a per-agent service; every agent for a run-wide one.
    Agent,
    /// The agents that have agent i as a neighbour (per-agent services).
    Neighbours,
    /// Client processes: `formation inspect`, `formation inject`, outside observers.
    Clients,
}

impl Party {
    /// How it is written in the docs and in `formation schema`.
    pub const fn name(self) -> &'static str {
        match self {
            Party::Orchestrator => "orchestrator",
            Party::Plant => "plant",
            Party::Leader => "leader",
            Party::Agent => "agent",
            Party::Neighbours => "neighbours",
            Party::Clients => "clients",
        }
    }
}

/// Whether a service exists once per run or once per agent.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Scope {
    /// One service per run; its pattern is its name.
    Run,
    /// One service per agent; `{i}` in the pattern is the 0-based agent index.
    PerAgent,
}

/// What a run's services are sized for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Sizing {
    /// Number of agents N.
    pub n: usize,
    /// Client processes admitted besides the run's own ([`MAX_CLIENTS`]).
    pub clients: usize,
    /// Outside observers K: every service gets K receivers (subscribers or listeners) and K nodes
    /// more than the run and its clients need ([`DEFAULT_OBSERVERS`], `formation run --observers`).
    pub observers: usize,
    /// Realtime mode: the plant does not wait for the recorder (deeper step-record buffer).
    pub realtime: bool,
    /// Most neighbours of one agent (the communication graph's largest degree d_max): it sizes
    /// the neighbour-share services ([`Sizing::share_subscribers`]). [`Sizing::run`] assumes any
    /// graph (N - 1); a run sets its graph's ([`Sizing::with_neighbours`]).
    pub neighbours: usize,
}

impl Sizing {
    /// A run of `n` agents with the default numbers of clients and observers.
    pub fn run(n: usize, realtime: bool) -> Sizing {
        Sizing {
            n,
            clients: MAX_CLIENTS,
            observers: DEFAULT_OBSERVERS,
            realtime,
            neighbours: n.saturating_sub(1),
        }
    }

    /// What every service of a run of `scenario` is sized for: its N, room for `observers`
    /// outside observers, its graph's largest degree for the neighbour shares, and in realtime
    /// mode (the plant does not wait for the recorder) a deeper step-record buffer. Every host
    /// of a run creates or opens its services with this one value.
    pub fn for_scenario(
        scenario: &crate::scenario::Scenario,
        realtime: bool,
        observers: usize,
    ) -> Sizing {
        let n = scenario.n_agents();
        Sizing::run(n, realtime)
            .with_observers(observers)
            .with_neighbours(scenario.graph.max_degree(n))
    }

    /// The same run for a graph whose agents have at most `d_max` neighbours
    /// (`Graph::max_degree`).
    pub fn with_neighbours(self, d_max: usize) -> Sizing {
        Sizing {
            neighbours: d_max,
            ..self
        }
    }

    /// Subscribers of one agent's neighbour share ([`NEIGHBOUR_STATE`]), observers aside: each
    /// neighbour's, the same again for neighbours restarted while the subscriber of the process
    /// they replace is not yet cleaned up, and one for the host bridge of a multi-host run.
    /// A publisher walks every subscriber slot of its service on each send (iceoryx2 0.10
    /// `Sender::deliver_offset`, twice more to reclaim returned chunks), so the share is sized
    /// by the graph and not by N: 2 d_max + 1 slots (5 on a ring) rather than N (docs/runtime.md,
    /// "Cost of a step at scale").
    pub fn share_subscribers(&self) -> usize {
        2 * self.neighbours + 1
    }

    /// The same run with room for `k` outside observers.
    pub fn with_observers(self, k: usize) -> Sizing {
        Sizing {
            observers: k,
            ..self
        }
    }

    /// Nodes that may open any service: N agents, plant, leader, orchestrator, one spare, the
    /// clients and the observers.
    pub fn nodes(&self) -> usize {
        self.n + 4 + self.clients + self.observers
    }

    /// `receivers` are the run's own (and its clients'); the observers' slots are added here.
    fn limits(&self, senders: usize, receivers: usize, buffer: usize) -> Limits {
        Limits {
            nodes: self.nodes(),
            senders,
            receivers: receivers + self.observers,
            buffer,
        }
    }
}

/// Upper bounds a service is created with. Openers of an existing service cannot raise them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Limits {
    /// Nodes that may open the service.
    pub nodes: usize,
    /// Publishers (publish-subscribe) or notifiers (event).
    pub senders: usize,
    /// Subscribers (publish-subscribe) or listeners (event).
    pub receivers: usize,
    /// Samples a subscriber can hold before the oldest is overwritten (publish-subscribe only).
    pub buffer: usize,
}

impl Limits {
    /// Limits for a service that `processes` processes open, each with at most one port of each
    /// kind: every process may send and receive, and a subscriber buffers one sample per sender.
    pub fn for_processes(processes: usize) -> Self {
        let p = processes.max(1);
        Limits {
            nodes: p + 1,
            senders: p,
            receivers: p,
            buffer: p.max(2),
        }
    }
}

/// Marker: each sample is one `T`.
#[derive(Debug, Clone, Copy)]
pub struct One;
/// Marker: each sample is a slice of `T` (one element per agent).
#[derive(Debug, Clone, Copy)]
pub struct Slice;

/// A publish-subscribe service carrying `T` (or slices of `T`, with `S = Slice`).
#[derive(Debug)]
pub struct Topic<T, S = One> {
    /// Name pattern (`{i}`: 0-based agent index for [`Scope::PerAgent`]).
    pub pattern: &'static str,
    /// Once per run or once per agent.
    pub scope: Scope,
    /// Who publishes.
    pub publishers: &'static [Party],
    /// Who subscribes.
    pub subscribers: &'static [Party],
    /// Samples kept for a subscriber that arrives late (0: none).
    pub history: usize,
    /// What it carries, in one line.
    pub doc: &'static str,
    limits: fn(&Sizing) -> Limits,
    _message: PhantomData<fn() -> (T, S)>,
}

/// An event service (wake-ups; every notification carries event id 0).
#[derive(Debug)]
pub struct Event {
    /// Name pattern (`{i}`: 0-based agent index for [`Scope::PerAgent`]).
    pub pattern: &'static str,
    /// Once per run or once per agent.
    pub scope: Scope,
    /// Who notifies.
    pub notifiers: &'static [Party],
    /// Who listens (sleeps on it).
    pub listeners: &'static [Party],
    /// What it wakes, in one line.
    pub doc: &'static str,
    limits: fn(&Sizing) -> Limits,
}

/// One service of the table with its concrete name (the agent index filled in).
#[derive(Debug)]
pub struct Named<D: 'static> {
    /// The service name, relative to the run prefix.
    pub name: String,
    /// Its declaration.
    pub spec: &'static D,
}

fn named<D>(spec: &'static D, pattern: &str, scope: Scope, i: usize) -> Named<D> {
    let name = match scope {
        Scope::PerAgent => pattern.replace("{i}", &i.to_string()),
        Scope::Run => pattern.to_string(),
    };
    Named { name, spec }
}

impl<T, S> Topic<T, S> {
    /// The run-wide service (or agent 0's, for a per-agent one).
    pub fn named(&'static self) -> Named<Self> {
        self.at(0)
    }

    /// Agent `i`'s service (0-based index); the pattern itself for a run-wide one.
    pub fn at(&'static self, i: usize) -> Named<Self> {
        named(self, self.pattern, self.scope, i)
    }

    /// Limits it is created with for a run of this size.
    pub fn limits(&self, sizing: &Sizing) -> Limits {
        (self.limits)(sizing)
    }

    /// The message type's size and alignment in bytes.
    pub fn layout(&self) -> (usize, usize) {
        (core::mem::size_of::<T>(), core::mem::align_of::<T>())
    }
}

impl Event {
    /// The run-wide event.
    pub fn named(&'static self) -> Named<Self> {
        self.at(0)
    }

    /// Agent `i`'s event (0-based index).
    pub fn at(&'static self, i: usize) -> Named<Self> {
        named(self, self.pattern, self.scope, i)
    }

    /// Limits it is created with for a run of this size.
    pub fn limits(&self, sizing: &Sizing) -> Limits {
        (self.limits)(sizing)
    }
}

use Party::{Agent, Clients, Leader, Neighbours, Orchestrator, Plant};

/// Leader -> agents, plant and orchestrator: the reference of each step.
pub static REFERENCE: Topic<ReferenceFrame> = Topic {
    pattern: "formation/reference",
    scope: Scope::Run,
    publishers: &[Leader],
    subscribers: &[Agent, Orchestrator],
    history: 0,
    doc: "the leader's reference of each step (P_d, its derivatives, the formation shape)",
    limits: |s| s.limits(1, s.n + 1, REFERENCE_BUFFER),
    _message: PhantomData,
};

/// Orchestrator -> plant: actuator faults injected at run time.
pub static FAULT_INJECTION: Topic<FaultInjection> = Topic {
    pattern: "formation/inject/fault",
    scope: Scope::Run,
    publishers: &[Orchestrator],
    subscribers: &[Plant],
    history: 0,
    doc: "an actuator fault (Gamma, delta) applied from a given step",
    limits: |s| s.limits(1, 1, CONTROL_BUFFER),
    _message: PhantomData,
};

/// Orchestrator -> agents: delay profiles injected at run time.
pub static DELAY_INJECTION: Topic<DelayInjection> = Topic {
    pattern: "formation/inject/delay",
    scope: Scope::Run,
    publishers: &[Orchestrator],
    subscribers: &[Agent],
    history: 0,
    doc: "a delay profile tau_i(t) applied from a given step",
    limits: |s| s.limits(1, s.n, CONTROL_BUFFER),
    _message: PhantomData,
};

/// Clients (`formation inject`) -> orchestrator: requests to inject.
pub static INJECT_REQUEST: Topic<InjectRequest> = Topic {
    pattern: "formation/inject/request",
    scope: Scope::Run,
    publishers: &[Clients],
    subscribers: &[Orchestrator],
    history: 0,
    doc: "a client's request to inject a fault or a delay",
    limits: |s| s.limits(s.clients, 1, CONTROL_BUFFER),
    _message: PhantomData,
};

/// Orchestrator -> every role process: stop.
pub static CONTROL: Topic<RunControl> = Topic {
    pattern: "formation/run/control",
    scope: Scope::Run,
    publishers: &[Orchestrator],
    subscribers: &[Plant, Leader, Agent],
    history: 0,
    doc: "run control (stop)",
    limits: |s| s.limits(1, s.n + 2, CONTROL_BUFFER),
    _message: PhantomData,
};

/// Orchestrator -> plant and leader: steps recorded so far (the pacing reference).
pub static PROGRESS: Topic<RunProgress> = Topic {
    pattern: "formation/run/progress",
    scope: Scope::Run,
    publishers: &[Orchestrator],
    subscribers: &[Plant, Leader],
    history: 0,
    doc: "how many steps the orchestrator has recorded (the first one starts the run)",
    limits: |s| s.limits(1, 2, CONTROL_BUFFER),
    _message: PhantomData,
};

/// Orchestrator and plant -> every role process: runtime events of the timeline and of the
/// supervision (crashes, hangs, links, losses, a process taken down, a new one taking over).
pub static RUNTIME_EVENTS: Topic<RuntimeEvent> = Topic {
    pattern: "formation/run/events",
    scope: Scope::Run,
    publishers: &[Orchestrator, Plant],
    subscribers: &[Plant, Agent, Orchestrator, Clients],
    history: 0,
    doc: "runtime events: crash, hang, link, loss, an agent taken down or taking over (docs/failures.md)",
    limits: |s| s.limits(2, s.n + 2 + s.clients, CONTROL_BUFFER),
    _message: PhantomData,
};

/// Role processes -> orchestrator: all my ports exist.
pub static HELLO: Topic<Hello> = Topic {
    pattern: "formation/run/hello",
    scope: Scope::Run,
    publishers: &[Plant, Leader, Agent],
    subscribers: &[Orchestrator],
    history: 0,
    doc: "a role process is ready (role, agent, pid)",
    limits: |s| s.limits(s.n + 2, 1, s.n + 2),
    _message: PhantomData,
};

/// Plant -> orchestrator: one slice of N step entries per step.
pub static STEPS: Topic<StepEntry, Slice> = Topic {
    pattern: "formation/plant/steps",
    scope: Scope::Run,
    publishers: &[Plant],
    subscribers: &[Orchestrator],
    history: 0,
    doc: "each step's truth and command of every quadrotor (N entries), for the recorder",
    limits: |s| {
        let buffer = if s.realtime {
            realtime_steps_buffer(s.n, core::mem::size_of::<StepEntry>())
        } else {
            STEPS_BUFFER
        };
        s.limits(1, 1, buffer)
    },
    _message: PhantomData,
};

/// Plant -> agent i: the state of quadrotor i.
pub static VEHICLE_STATE: Topic<VehicleState> = Topic {
    pattern: "formation/agent/{i}/state",
    scope: Scope::PerAgent,
    publishers: &[Plant],
    subscribers: &[Agent],
    history: 0,
    doc: "quadrotor i's state at step k (position, velocity, attitude, rate)",
    limits: |s| s.limits(1, 1, LOCKSTEP_BUFFER),
    _message: PhantomData,
};

/// Agent i -> its neighbours: what it shares for consensus.
pub static NEIGHBOUR_STATE: Topic<NeighbourState> = Topic {
    pattern: "formation/agent/{i}/share",
    scope: Scope::PerAgent,
    publishers: &[Agent],
    subscribers: &[Neighbours],
    history: 0,
    doc: "agent i's shared position and velocity, stamped with its step",
    limits: |s| s.limits(1, s.share_subscribers(), LOCKSTEP_BUFFER),
    _message: PhantomData,
};

/// Agent i -> plant: its command.
pub static CONTROL_COMMAND: Topic<ControlCommand> = Topic {
    pattern: "formation/agent/{i}/command",
    scope: Scope::PerAgent,
    publishers: &[Agent],
    subscribers: &[Plant],
    history: 0,
    doc: "agent i's command for step k (thrust and torques) and its controller telemetry",
    limits: |s| s.limits(1, 1, LOCKSTEP_BUFFER),
    _message: PhantomData,
};

/// Agent i -> clients (`formation inspect`): live telemetry, the latest kept for late subscribers.
pub static TELEMETRY: Topic<AgentTelemetry> = Topic {
    pattern: "formation/agent/{i}/telemetry",
    scope: Scope::PerAgent,
    publishers: &[Agent],
    subscribers: &[Clients],
    history: 1,
    doc: "agent i's live telemetry (errors, estimates, constraint margins)",
    limits: |s| s.limits(1, s.clients, 2),
    _message: PhantomData,
};

/// Event the orchestrator sleeps on.
pub static WAKE_ORCHESTRATOR: Event = Event {
    pattern: "formation/wake/orchestrator",
    scope: Scope::Run,
    notifiers: &[Plant, Leader, Agent, Clients],
    listeners: &[Orchestrator],
    doc: "wakes the orchestrator (hello, step records ready, injection requests)",
    limits: |s| s.limits(s.n + 3 + s.clients, 1, 0),
};

/// Event the plant sleeps on.
pub static WAKE_PLANT: Event = Event {
    pattern: "formation/wake/plant",
    scope: Scope::Run,
    notifiers: &[Orchestrator, Leader, Agent],
    listeners: &[Plant],
    doc: "wakes the plant (commands in, progress, stop)",
    limits: |s| s.limits(s.n + 3, 1, 0),
};

/// Event the leader sleeps on.
pub static WAKE_LEADER: Event = Event {
    pattern: "formation/wake/leader",
    scope: Scope::Run,
    notifiers: &[Orchestrator, Plant, Agent],
    listeners: &[Leader],
    doc: "wakes the leader (progress, stop)",
    limits: |s| s.limits(s.n + 3, 1, 0),
};

/// Event agent i sleeps on.
pub static WAKE_AGENT: Event = Event {
    pattern: "formation/wake/agent/{i}",
    scope: Scope::PerAgent,
    notifiers: &[Orchestrator, Plant, Leader, Neighbours],
    listeners: &[Agent],
    doc: "wakes agent i (its state, a neighbour's share, a reference, stop)",
    limits: |s| s.limits(s.n + 3, 1, 0),
};

/// What walks the table: the orchestrator (creating every service), `formation schema`, the docs.
pub trait Visitor {
    /// What stops the walk.
    type Error;
    /// A publish-subscribe service of single samples.
    fn topic<T: Message>(
        &mut self,
        service: Named<Topic<T>>,
        limits: Limits,
    ) -> Result<(), Self::Error>;
    /// A publish-subscribe service of slices.
    fn slices<T: Message>(
        &mut self,
        service: Named<Topic<T, Slice>>,
        limits: Limits,
    ) -> Result<(), Self::Error>;
    /// An event service.
    fn event(&mut self, service: Named<Event>, limits: Limits) -> Result<(), Self::Error>;
}

/// Walks every service of a run of this size, run-wide ones first, then agent by agent.
pub fn visit<V: Visitor>(sizing: &Sizing, v: &mut V) -> Result<(), V::Error> {
    let s = sizing;
    v.topic(REFERENCE.named(), REFERENCE.limits(s))?;
    v.topic(FAULT_INJECTION.named(), FAULT_INJECTION.limits(s))?;
    v.topic(DELAY_INJECTION.named(), DELAY_INJECTION.limits(s))?;
    v.topic(CONTROL.named(), CONTROL.limits(s))?;
    v.topic(PROGRESS.named(), PROGRESS.limits(s))?;
    v.topic(HELLO.named(), HELLO.limits(s))?;
    v.topic(RUNTIME_EVENTS.named(), RUNTIME_EVENTS.limits(s))?;
    v.slices(STEPS.named(), STEPS.limits(s))?;
    v.topic(INJECT_REQUEST.named(), INJECT_REQUEST.limits(s))?;
    v.event(WAKE_ORCHESTRATOR.named(), WAKE_ORCHESTRATOR.limits(s))?;
    v.event(WAKE_PLANT.named(), WAKE_PLANT.limits(s))?;
    v.event(WAKE_LEADER.named(), WAKE_LEADER.limits(s))?;
    for i in 0..s.n {
        v.topic(VEHICLE_STATE.at(i), VEHICLE_STATE.limits(s))?;
        v.topic(NEIGHBOUR_STATE.at(i), NEIGHBOUR_STATE.limits(s))?;
        v.topic(CONTROL_COMMAND.at(i), CONTROL_COMMAND.limits(s))?;
        v.event(WAKE_AGENT.at(i), WAKE_AGENT.limits(s))?;
        v.topic(TELEMETRY.at(i), TELEMETRY.limits(s))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Collects the names and limits of every service.
    #[derive(Default)]
    struct Names(Vec<(String, Limits)>);

    impl Visitor for Names {
        type Error = ();
        fn topic<T: Message>(&mut self, s: Named<Topic<T>>, l: Limits) -> Result<(), ()> {
            self.0.push((s.name, l));
            Ok(())
        }
        fn slices<T: Message>(&mut self, s: Named<Topic<T, Slice>>, l: Limits) -> Result<(), ()> {
            self.0.push((s.name, l));
            Ok(())
        }
        fn event(&mut self, s: Named<Event>, l: Limits) -> Result<(), ()> {
            self.0.push((s.name, l));
            Ok(())
        }
    }

    #[test]
    fn a_run_has_twelve_run_wide_services_and_five_per_agent_all_with_distinct_names() {
        let mut names = Names::default();
        visit(&Sizing::run(5, false), &mut names).unwrap();
        assert_eq!(names.0.len(), 12 + 5 * 5);
        let mut unique: Vec<&String> = names.0.iter().map(|(n, _)| n).collect();
        unique.sort();
        unique.dedup();
        assert_eq!(unique.len(), names.0.len());
        assert!(names.0.iter().any(|(n, _)| n == "formation/agent/4/state"));
        assert!(names.0.iter().all(|(n, _)| !n.contains('{')));
    }

    #[test]
    fn every_service_admits_every_process_of_the_run_and_its_clients() {
        let s = Sizing::run(7, false);
        let mut names = Names::default();
        visit(&s, &mut names).unwrap();
        for (name, l) in &names.0 {
            assert_eq!(l.nodes, 7 + 4 + MAX_CLIENTS + DEFAULT_OBSERVERS, "{name}");
        }
        assert_eq!(
            TELEMETRY.limits(&s).receivers,
            MAX_CLIENTS + DEFAULT_OBSERVERS
        );
        assert_eq!(WAKE_ORCHESTRATOR.limits(&s).senders, 7 + 3 + MAX_CLIENTS);
    }

    #[test]
    fn every_service_has_k_spare_receivers_and_nodes_for_outside_observers() {
        let own = Sizing::run(5, false).with_observers(0);
        let watched = own.with_observers(3);
        let (mut a, mut b) = (Names::default(), Names::default());
        visit(&own, &mut a).unwrap();
        visit(&watched, &mut b).unwrap();
        assert_eq!(a.0.len(), b.0.len());
        for ((name, l0), (_, l3)) in a.0.iter().zip(&b.0) {
            assert_eq!(l3.receivers, l0.receivers + 3, "{name}");
            assert_eq!(l3.nodes, l0.nodes + 3, "{name}");
            assert_eq!((l3.senders, l3.buffer), (l0.senders, l0.buffer), "{name}");
        }
        // Without observers, the state of agent i has exactly one subscriber (agent i) and its wake
        // event exactly one listener.
        assert_eq!(VEHICLE_STATE.limits(&own).receivers, 1);
        assert_eq!(WAKE_AGENT.limits(&own).receivers, 1);
    }

    #[test]
    fn a_share_has_slots_for_its_graph_neighbours_twice_and_the_bridge_not_for_every_agent() {
        // The paper's path: agents 2..4 have two neighbours.
        let paper = crate::scenario::Scenario::paper();
        let s = Sizing::for_scenario(&paper, false, 0);
        assert_eq!(s.neighbours, 2);
        assert_eq!(NEIGHBOUR_STATE.limits(&s).receivers, 2 * 2 + 1);
        // A 128-agent ring: five slots (plus observers) where N would have given 128.
        let ring = Sizing::run(128, false).with_observers(0).with_neighbours(2);
        assert_eq!(NEIGHBOUR_STATE.limits(&ring).receivers, 5);
        // Without a graph, any graph: every other agent may be a neighbour.
        let any = Sizing::run(128, false).with_observers(0);
        assert!(NEIGHBOUR_STATE.limits(&any).receivers > 127);
        // Only the shares depend on the graph.
        let (mut a, mut b) = (Names::default(), Names::default());
        visit(&ring, &mut a).unwrap();
        visit(&any, &mut b).unwrap();
        for ((name, la), (_, lb)) in a.0.iter().zip(&b.0) {
            if !name.ends_with("/share") {
                assert_eq!(la, lb, "{name}");
            }
        }
    }

    #[test]
    fn realtime_runs_get_a_deeper_step_record_buffer_than_lockstep_runs() {
        let lock = STEPS.limits(&Sizing::run(5, false)).buffer;
        let rt = STEPS.limits(&Sizing::run(5, true)).buffer;
        assert_eq!(lock, STEPS_BUFFER);
        assert_eq!(rt, crate::protocol::pacing::REALTIME_STEPS_BUFFER);
        assert!(rt > lock);
        // A large formation keeps the buffer within its byte budget, never under one second.
        let big = STEPS.limits(&Sizing::run(128, true)).buffer;
        let bytes = big * 128 * core::mem::size_of::<StepEntry>();
        assert!(big >= crate::protocol::pacing::REALTIME_STEPS_MIN);
        assert!(bytes <= crate::protocol::pacing::REALTIME_STEPS_BYTES || big == 1024);
        assert!(big < rt);
    }

    #[cfg(feature = "ipc")]
    #[test]
    fn the_wire_type_name_is_the_declared_versioned_name_not_the_rust_path() {
        assert_eq!(
            wire_type_name::<AgentTelemetry>(),
            "formation.v2.AgentTelemetry"
        );
        assert_eq!(wire_type_name::<StepEntry>(), "formation.v3.StepEntry");
    }

    #[test]
    fn a_per_agent_name_carries_the_zero_based_index_and_a_run_wide_name_is_its_pattern() {
        assert_eq!(TELEMETRY.at(2).name, "formation/agent/2/telemetry");
        assert_eq!(WAKE_AGENT.at(0).name, "formation/wake/agent/0");
        assert_eq!(REFERENCE.at(3).name, "formation/reference");
        assert_eq!(STEPS.named().name, "formation/plant/steps");
    }
}
