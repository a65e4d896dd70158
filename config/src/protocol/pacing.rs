//! Pacing of the lockstep protocol of `formation run`: who paces whom, how far ahead, and the
//! subscriber buffers that follow from it.
//!
//! Pacing (all counts in simulation steps; `recorded` is the number of steps the orchestrator has
//! recorded, announced in [`super::messages::RunProgress`]):
//! * the plant starts step k only when `k < recorded + PLANT_LEAD`;
//! * the leader publishes the reference of step k only when `k < recorded + LEADER_LEAD`
//!   (`LEADER_LEAD > PLANT_LEAD`, so references are always ahead of the plant);
//! * the plant wakes the orchestrator every [`ACK_EVERY`] steps (and when it has to wait), and the
//!   orchestrator answers with a new progress value, waking plant and leader.
//!
//! Subscriber buffers are sized from these leads, so no sample is ever overwritten.

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
/// the recorder: four seconds of steps at 1 kHz, what the orchestrator may spend away from the
/// records while it starts a successor (it writes the successor's rebuild file and forks) on a
/// machine two CPU-bound programs keep busy (one second overflowed there: `record of step 6313
/// while expecting 6234`). Capped by [`REALTIME_STEPS_BYTES`] for large formations, never below
/// [`REALTIME_STEPS_MIN`].
pub const REALTIME_STEPS_BUFFER: usize = 4096;
/// Shared memory the realtime step-record buffer may take, bytes (64 MiB): 4096 records up to
/// about 30 agents (a record of N entries takes N `StepEntry`).
pub const REALTIME_STEPS_BYTES: usize = 64 << 20;
/// Least realtime step-record buffer whatever N: one second of steps at 1 kHz.
pub const REALTIME_STEPS_MIN: usize = 1024;

/// The realtime step-record buffer of a run of `n` agents whose entries take `entry` bytes each:
/// [`REALTIME_STEPS_BUFFER`] records, fewer where they would take more than
/// [`REALTIME_STEPS_BYTES`], never fewer than [`REALTIME_STEPS_MIN`].
pub const fn realtime_steps_buffer(n: usize, entry: usize) -> usize {
    let per_record = if n * entry == 0 { 1 } else { n * entry };
    let fit = REALTIME_STEPS_BYTES / per_record;
    let capped = if fit < REALTIME_STEPS_BUFFER {
        fit
    } else {
        REALTIME_STEPS_BUFFER
    };
    if capped < REALTIME_STEPS_MIN {
        REALTIME_STEPS_MIN
    } else {
        capped
    }
}
/// Subscriber buffer of the per-agent state, share and command services.
pub const LOCKSTEP_BUFFER: usize = 8;
/// Subscriber buffer of the injection and control services.
pub const CONTROL_BUFFER: usize = 64;
