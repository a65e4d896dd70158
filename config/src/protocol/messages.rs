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
    type_name("formation.v2.StepEntry")
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
/// [`InjectRequest::at_step`] when no step was asked for: "as soon as deterministically possible".
pub const INJECT_ASAP: u64 = u64::MAX;

/// `formation inject` -> orchestrator: a validated injection request; the orchestrator picks the
/// step it applies at, records it in `events.jsonl` (with `nonce`) and forwards it.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq)]
#[cfg_attr(
    feature = "ipc",
    derive(ZeroCopySend),
    type_name("formation.v1.InjectRequest")
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
});
