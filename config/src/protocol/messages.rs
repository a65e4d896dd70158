//! Messages of the run protocol (besides the simulation messages of [`super::wire`]).

use crate::protocol::wire::{ControlCommand, PlantTruth};
#[cfg(feature = "ipc")]
use iceoryx2::prelude::ZeroCopySend;

/// [`RunControl::kind`]: stop now and exit.
pub const CONTROL_STOP: u32 = 1;

/// Orchestrator -> every role process.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq)]
#[cfg_attr(
    feature = "ipc",
    derive(ZeroCopySend),
    type_name("formation.v1.RunControl")
)]
pub struct RunControl {
    /// What to do ([`CONTROL_STOP`]).
    pub kind: u32,
    /// Padding, zero.
    pub _pad: u32,
    /// Steps recorded when the message was sent.
    pub step: u64,
}

crate::wire_fields!(RunControl {
    kind: u32 => "-",
    _pad: u32 => "-",
    step: u64 => "-",
});

/// Orchestrator -> plant and leader: how many steps have been recorded (the pacing reference; the
/// first one is the start signal).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq)]
#[cfg_attr(
    feature = "ipc",
    derive(ZeroCopySend),
    type_name("formation.v1.RunProgress")
)]
pub struct RunProgress {
    /// Number of steps recorded so far.
    pub recorded: u64,
}

crate::wire_fields!(RunProgress {
    recorded: u64 => "-",
});

/// A role process of a run. On the wire (as [`Hello::role`]) it is its `u32` discriminant.
#[repr(u32)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Role {
    /// The plant: integrates every quadrotor.
    Plant = 0,
    /// The leader: publishes the reference.
    Leader = 1,
    /// One quadrotor's controller.
    Agent = 2,
}

impl Role {
    /// Every role, in start order.
    pub const ALL: [Role; 3] = [Role::Plant, Role::Leader, Role::Agent];

    /// Its name on the command line (`formation node <name>`), in log file and process names.
    pub const fn name(self) -> &'static str {
        match self {
            Role::Plant => "plant",
            Role::Leader => "leader",
            Role::Agent => "agent",
        }
    }

    /// The role named `name` ([`Role::name`]).
    pub fn from_name(name: &str) -> Option<Role> {
        Role::ALL.into_iter().find(|r| r.name() == name)
    }

    /// The role of a wire discriminant ([`Hello::role`]).
    pub fn from_wire(code: u32) -> Option<Role> {
        Role::ALL.into_iter().find(|r| *r as u32 == code)
    }

    /// The process name (`ps -o comm`): `fm-plant`, `fm-leader`, `fm-agent-<id>` with the 1-based
    /// agent id.
    pub fn process_name(self, agent: Option<usize>) -> String {
        match agent {
            Some(i) => format!("fm-{}-{}", self.name(), i + 1),
            None => format!("fm-{}", self.name()),
        }
    }
}

impl core::fmt::Display for Role {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(self.name())
    }
}

/// Role process -> orchestrator: all my ports exist.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq)]
#[cfg_attr(feature = "ipc", derive(ZeroCopySend), type_name("formation.v1.Hello"))]
pub struct Hello {
    /// The sender's [`Role`] as its `u32` discriminant.
    pub role: u32,
    /// Agent index (agents only).
    pub agent: u32,
    /// Process id.
    pub pid: u32,
    /// Padding, zero.
    pub _pad: u32,
}

crate::wire_fields!(Hello {
    role: u32 => "-",
    agent: u32 => "-",
    pid: u32 => "-",
    _pad: u32 => "-",
});

/// Plant -> orchestrator: what quadrotor i did at one step (an element of the per-step slice).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq)]
#[cfg_attr(
    feature = "ipc",
    derive(ZeroCopySend),
    type_name("formation.v3.StepEntry")
)]
pub struct StepEntry {
    /// The plant's truth after applying the command.
    pub truth: PlantTruth,
    /// The command the agent sent for this step.
    pub command: ControlCommand,
}

crate::wire_fields!(StepEntry {
    truth: PlantTruth => "-",
    command: ControlCommand => "-",
});

/// [`InjectRequest::kind`]: an actuator fault (to the plant).
pub const INJECT_FAULT: u32 = 1;
/// [`InjectRequest::kind`]: a delay profile (to the agents).
pub const INJECT_DELAY: u32 = 2;
/// [`InjectRequest::kind`]: a crash of an agent process for `down_s` (SIGKILL, then a new one).
pub const INJECT_CRASH: u32 = 3;
/// [`InjectRequest::kind`]: a hang of an agent process for `down_s` (SIGSTOP, then a new one).
pub const INJECT_HANG: u32 = 4;
/// [`InjectRequest::kind`]: the edge {agent, other} goes down.
pub const INJECT_LINK_DOWN: u32 = 5;
/// [`InjectRequest::kind`]: the edge {agent, other} comes back.
pub const INJECT_LINK_UP: u32 = 6;
/// [`InjectRequest::at_step`] when no step was asked for: "as soon as deterministically possible".
pub const INJECT_ASAP: u64 = u64::MAX;

/// `formation inject` -> orchestrator: a validated injection request; the orchestrator picks the
/// step it applies at, records it in `events.jsonl` (with `nonce`) and forwards it.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq)]
#[cfg_attr(
    feature = "ipc",
    derive(ZeroCopySend),
    type_name("formation.v2.InjectRequest")
)]
pub struct InjectRequest {
    /// Random id chosen by the client; echoed in `events.jsonl`.
    pub nonce: u64,
    /// Requested first step, or [`INJECT_ASAP`].
    pub at_step: u64,
    /// [`INJECT_FAULT`] or [`INJECT_DELAY`].
    pub kind: u32,
    /// Agent index i (0-based).
    pub agent: u32,
    /// Fault: Gamma_i (diagonal).
    pub gamma: [f64; 3],
    /// Fault: delta_i, N m.
    pub delta: [f64; 3],
    /// Delay: tau_i(t) = base + amplitude sin(rate t), base in s.
    pub base_s: f64,
    /// Delay amplitude, s.
    pub amplitude_s: f64,
    /// Delay angular rate, rad/s.
    pub angular_rate_rad_s: f64,
    /// Link: the other agent index (0-based).
    pub other: u32,
    /// Padding, zero.
    pub _pad: u32,
    /// Crash, hang: how long the agent is down, s.
    pub down_s: f64,
}

/// [`RuntimeEvent::kind`]: agent `agent` crashes at `step` for `down_steps` (a timeline `crash`).
pub const EVENT_CRASH: u32 = 1;
/// [`RuntimeEvent::kind`]: agent `agent` hangs at `step` for `down_steps`.
pub const EVENT_HANG: u32 = 2;
/// [`RuntimeEvent::kind`]: the edge {agent, other} carries nothing from `step` on.
pub const EVENT_LINK_DOWN: u32 = 3;
/// [`RuntimeEvent::kind`]: the edge {agent, other} carries shares again from `step` on.
pub const EVENT_LINK_UP: u32 = 4;
/// [`RuntimeEvent::kind`]: shares agent -> other (both [`EVENT_ANY`]: every edge) are lost with
/// `probability` from `step` for `down_steps` steps (u64::MAX: to the end).
pub const EVENT_MESSAGE_LOSS: u32 = 5;
/// [`RuntimeEvent::kind`], plant -> all: agent `agent`'s process died or hung outside the timeline;
/// it is down from `step` (its shares from `step` on are not delivered).
pub const EVENT_DOWN: u32 = 6;
/// [`RuntimeEvent::kind`], orchestrator -> all: agent `agent`'s new process takes over at `step`.
pub const EVENT_UP_AGAIN: u32 = 7;
/// [`RuntimeEvent::kind`], orchestrator -> plant: agent `agent`'s new process for step `step` has
/// its ports (the plant may send it the states of that step).
pub const EVENT_JOINED: u32 = 8;
/// [`RuntimeEvent::kind`], orchestrator -> plant: agent `agent`'s process is gone; take it down at
/// the first step whose command is missing and say so with [`EVENT_DOWN`].
pub const EVENT_DOWN_REQUEST: u32 = 9;
/// [`RuntimeEvent::other`] when no second agent is named.
pub const EVENT_ANY: u32 = u32::MAX;

/// A runtime event of the fault timeline or of the supervision (`docs/failures.md`): published
/// ahead of its step by the orchestrator (live injections, restarts) or by the plant (the step a
/// dead process is taken down at), so every process adds it to its timeline before it matters.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize, serde::Deserialize)]
#[cfg_attr(
    feature = "ipc",
    derive(ZeroCopySend),
    type_name("formation.v1.RuntimeEvent")
)]
pub struct RuntimeEvent {
    /// The step it applies at.
    pub step: u64,
    /// One of the `EVENT_*` kinds.
    pub kind: u32,
    /// Agent index (0-based).
    pub agent: u32,
    /// Second agent index (0-based) of a link or loss, or [`EVENT_ANY`].
    pub other: u32,
    /// Padding, zero.
    pub _pad: u32,
    /// Crash, hang: steps down; message loss: steps it lasts (u64::MAX: to the end).
    pub down_steps: u64,
    /// Message loss: probability per share.
    pub probability: f64,
    /// Message loss: seed of the pattern.
    pub seed: u64,
}

impl RuntimeEvent {
    /// The timeline event of a crash, hang, link or loss event (`None` for the supervision kinds),
    /// for a step `dt`.
    pub fn to_event(&self, dt: f64) -> Option<crate::scenario::events::Event> {
        use crate::scenario::events::{Event, EventKind as K};
        let kind = match self.kind {
            EVENT_CRASH => K::Crash,
            EVENT_HANG => K::Hang,
            EVENT_LINK_DOWN => K::LinkDown,
            EVENT_LINK_UP => K::LinkUp,
            EVENT_MESSAGE_LOSS => K::MessageLoss,
            _ => return None,
        };
        let mut e = Event::new(self.step as f64 * dt, kind);
        let one = |i: u32| (i != EVENT_ANY).then_some(i as usize + 1);
        let secs = |n: u64| (n != u64::MAX).then_some(n as f64 * dt);
        match kind {
            K::Crash | K::Hang => {
                e.agent = one(self.agent);
                e.down_s = secs(self.down_steps);
            }
            K::LinkDown | K::LinkUp => {
                e.agents = Some([self.agent as usize + 1, self.other as usize + 1])
            }
            _ => {
                e.from = one(self.agent);
                e.to = one(self.other);
                e.probability = Some(self.probability);
                e.seed = Some(self.seed);
                e.duration_s = secs(self.down_steps);
            }
        }
        Some(e)
    }

    /// The runtime event of a timeline crash, hang, link or loss event (`None` for fault and
    /// delay, which have messages of their own), for a step `dt`.
    pub fn from_event(e: &crate::scenario::events::Event, dt: f64) -> Option<RuntimeEvent> {
        use crate::scenario::events::EventKind as K;
        let idx = |a: Option<usize>| a.map_or(EVENT_ANY, |a| a.saturating_sub(1) as u32);
        let steps = |s: Option<f64>| s.map_or(u64::MAX, |s| (s / dt).round().max(1.0) as u64);
        let mut r = RuntimeEvent {
            step: e.step(dt),
            ..RuntimeEvent::default()
        };
        match e.kind {
            K::Crash | K::Hang => {
                r.kind = if e.kind == K::Crash {
                    EVENT_CRASH
                } else {
                    EVENT_HANG
                };
                r.agent = idx(e.agent);
                r.other = EVENT_ANY;
                r.down_steps = steps(e.down_s);
            }
            K::LinkDown | K::LinkUp => {
                r.kind = if e.kind == K::LinkDown {
                    EVENT_LINK_DOWN
                } else {
                    EVENT_LINK_UP
                };
                let [a, b] = e.agents?;
                r.agent = a.saturating_sub(1) as u32;
                r.other = b.saturating_sub(1) as u32;
            }
            K::MessageLoss => {
                r.kind = EVENT_MESSAGE_LOSS;
                r.agent = idx(e.from);
                r.other = idx(e.to);
                r.probability = e.probability.unwrap_or(0.0);
                r.seed = e.seed.unwrap_or(0);
                r.down_steps = steps(e.duration_s);
            }
            K::Fault | K::Delay => return None,
        }
        Some(r)
    }

    /// Applies it to a timeline (the supervision kinds DOWN and UP_AGAIN included).
    pub fn apply(&self, t: &mut crate::scenario::events::Timeline) {
        use crate::scenario::events::EventKind;
        match self.kind {
            EVENT_DOWN => t.set_down(self.agent as usize, self.step, EventKind::Crash),
            EVENT_UP_AGAIN => t.set_up_again(self.agent as usize, self.step),
            _ => {
                if let Some(e) = self.to_event(t.dt()) {
                    t.add(&e);
                }
            }
        }
    }
}

crate::wire_fields!(InjectRequest {
    nonce: u64 => "-",
    at_step: u64 => "-",
    kind: u32 => "-",
    agent: u32 => "-",
    gamma: [f64; 3] => "-",
    delta: [f64; 3] => "N m",
    base_s: f64 => "s",
    amplitude_s: f64 => "s",
    angular_rate_rad_s: f64 => "rad/s",
    other: u32 => "-",
    _pad: u32 => "-",
    down_s: f64 => "s",
});

crate::wire_fields!(RuntimeEvent {
    step: u64 => "-",
    kind: u32 => "-",
    agent: u32 => "-",
    other: u32 => "-",
    _pad: u32 => "-",
    down_steps: u64 => "steps",
    probability: f64 => "-",
    seed: u64 => "-",
});
