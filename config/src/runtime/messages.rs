//! Messages of the run protocol (besides the simulation messages of [`crate::wire`]).

use crate::wire::{ControlCommand, PlantTruth};
use iceoryx2::prelude::ZeroCopySend;

/// [`RunControl::kind`]: stop now and exit.
pub const CONTROL_STOP: u32 = 1;

/// Orchestrator -> every role process.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("formation.v1.RunControl")]
pub struct RunControl {
    /// What to do ([`CONTROL_STOP`]).
    pub kind: u32,
    /// Padding, zero.
    pub _pad: u32,
    /// Steps recorded when the message was sent.
    pub step: u64,
}

/// Orchestrator -> plant and leader: how many steps have been recorded (the pacing reference; the
/// first one is the start signal).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("formation.v1.RunProgress")]
pub struct RunProgress {
    /// Number of steps recorded so far.
    pub recorded: u64,
}

/// [`Hello::role`] of the plant.
pub const ROLE_PLANT: u32 = 0;
/// [`Hello::role`] of the leader.
pub const ROLE_LEADER: u32 = 1;
/// [`Hello::role`] of an agent.
pub const ROLE_AGENT: u32 = 2;

/// Role process -> orchestrator: all my ports exist.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("formation.v1.Hello")]
pub struct Hello {
    /// [`ROLE_PLANT`], [`ROLE_LEADER`] or [`ROLE_AGENT`].
    pub role: u32,
    /// Agent index (agents only).
    pub agent: u32,
    /// Process id.
    pub pid: u32,
    /// Padding, zero.
    pub _pad: u32,
}

/// Plant -> orchestrator: what quadrotor i did at one step (an element of the per-step slice).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("formation.v1.StepEntry")]
pub struct StepEntry {
    /// The plant's truth after applying the command.
    pub truth: PlantTruth,
    /// The command the agent sent for this step.
    pub command: ControlCommand,
}
