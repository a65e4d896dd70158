//! The lockstep protocol of `formation run`: who paces whom, the control messages, the extra service
//! names, and the plumbing every role process (plant, leader, agent) shares.
//!
//! Pacing (all counts in simulation steps; `recorded` is the number of steps the orchestrator has
//! recorded, announced in [`messages::RunProgress`]):
//! * the plant starts step k only when `k < recorded + PLANT_LEAD`;
//! * the leader publishes the reference of step k only when `k < recorded + LEADER_LEAD`
//!   (`LEADER_LEAD > PLANT_LEAD`, so references are always ahead of the plant);
//! * the plant wakes the orchestrator every [`ACK_EVERY`] steps (and when it has to wait), and the
//!   orchestrator answers with a new progress value, waking plant and leader.
//!
//! Subscriber buffers are sized from these leads, so no sample is ever overwritten.

pub mod args;
pub mod boot;
pub mod clock;
pub mod files;
pub mod logging;
pub mod members;
pub mod messages;
pub mod ports;
pub mod process;
pub mod sched;
pub mod timing;

use std::time::Duration;

/// The plant stays at most this many steps ahead of the orchestrator's recorder.
pub const PLANT_LEAD: u64 = 48;
/// The leader stays at most this many steps ahead of the orchestrator's recorder.
pub const LEADER_LEAD: u64 = 96;
/// The plant wakes the orchestrator every this many steps.
pub const ACK_EVERY: u64 = 16;
/// Plant and agents read their slow inputs (stop, progress, injections, references) every this many
/// steps, and on any wake-up that brought none of their per-step inputs; the per-step inputs
/// (commands, own state, neighbour shares) are read on every wake-up.
pub const HOUSEKEEPING_EVERY: u64 = ACK_EVERY;
/// Longest a role process sleeps before it rechecks its parent and its stop flags.
pub const CHILD_WAIT: Duration = Duration::from_millis(100);

/// Orchestrator -> everyone: [`messages::RunControl`].
pub const CONTROL: &str = "formation/run/control";
/// Orchestrator -> plant and leader: [`messages::RunProgress`].
pub const PROGRESS: &str = "formation/run/progress";
/// Role processes -> orchestrator: [`messages::Hello`] once their ports exist.
pub const HELLO: &str = "formation/run/hello";
/// Plant -> orchestrator: one slice of [`messages::StepEntry`] (N entries) per step.
pub const STEPS: &str = "formation/plant/steps";
/// Event the orchestrator sleeps on.
pub const WAKE_ORCHESTRATOR: &str = "formation/wake/orchestrator";
/// Event the plant sleeps on.
pub const WAKE_PLANT: &str = "formation/wake/plant";
/// Event the leader sleeps on.
pub const WAKE_LEADER: &str = "formation/wake/leader";

/// Event agent i sleeps on.
pub fn wake_agent(i: usize) -> String {
    format!("formation/wake/agent/{i}")
}

/// Subscriber buffer of the reference service: everything the leader may publish between two drains of
/// the slowest subscriber (the orchestrator). At one drain the leader may have published only up to the
/// step being recorded (it was descheduled); the orchestrator then records up to PLANT_LEAD + ACK_EVERY
/// more steps and announces them, and the leader may publish up to LEADER_LEAD past that before the next
/// drain: LEADER_LEAD + PLANT_LEAD + 2 ACK_EVERY, plus slack. (Sized from LEADER_LEAD alone it
/// overflowed under load: "no reference frame for step 128".)
pub const REFERENCE_BUFFER: usize = (LEADER_LEAD + PLANT_LEAD + 4 * ACK_EVERY) as usize;
/// Subscriber buffer of the per-step records (plant -> orchestrator), by the same argument for the plant.
pub const STEPS_BUFFER: usize = (2 * PLANT_LEAD + 4 * ACK_EVERY) as usize;
/// Subscriber buffer of the per-step records in realtime mode, where the plant does not wait for
/// the recorder: one second of steps at 1 kHz.
pub const REALTIME_STEPS_BUFFER: usize = 1024;
/// Subscriber buffer of the per-agent state, share and command services.
pub const LOCKSTEP_BUFFER: usize = 8;
/// Subscriber buffer of the injection and control services.
pub const CONTROL_BUFFER: usize = 64;
