//! The agent process's side of a warm restart: writing checkpoints, and rebuilding the controller
//! from the last one and the recorded states when it is a new process taking over
//! (`formation_agent::restart`, `docs/failures.md`).

use crate::restart::{rebuild as rebuild_from, Rejoin};
use crate::Agent;
use formation_config::node::boot::Boot;
use formation_config::node::error::NodeError;
use formation_config::node::restart::{self, Checkpoint, RejoinFile};
use formation_config::node::sched;
use formation_config::protocol::wire::ReferenceFrame;
use std::path::PathBuf;
use std::sync::mpsc;

/// Where and when this process checkpoints.
pub struct Checkpoints {
    path: PathBuf,
    scenario_hash: u64,
    every: u64,
    /// The next step whose checkpoint is due.
    next: u64,
    agent: usize,
    /// A checkpoint taken before a control and not written yet ([`Checkpoints::take`]).
    taken: Option<Checkpoint>,
    /// The writing thread of a realtime agent ([`Checkpoints::write_in_background`]).
    writer: Option<Writer>,
}

/// A thread that writes the checkpoints handed to it, under the normal policy at background nice:
/// below the plant and the agents' control threads (`SCHED_FIFO` in realtime), so a write never
/// takes a CPU from a step.
struct Writer {
    /// One checkpoint in flight at most: the next is due a checkpoint period later.
    to: Option<mpsc::SyncSender<Checkpoint>>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Checkpoints {
    /// Checkpoints of agent i every `runtime.checkpoint_every_s`, and at its first step `first`.
    pub fn new(b: &Boot, i: usize, first: u64) -> Checkpoints {
        Checkpoints::at(
            restart::checkpoint_path(&b.args.run_dir, i),
            b.scenario_hash,
            b.scenario
                .runtime
                .checkpoint_steps(b.scenario.simulation.dt_s),
            (i, first),
        )
    }

    /// Checkpoints of agent `who.0` to `path` every `every` steps, the first at step `who.1`.
    fn at(path: PathBuf, scenario_hash: u64, every: u64, who: (usize, u64)) -> Checkpoints {
        Checkpoints {
            path,
            scenario_hash,
            every,
            next: who.1,
            agent: who.0,
            taken: None,
            writer: None,
        }
    }

    /// Writes the checkpoint of step k if one is due (before its control): at the first step,
    /// then at the first step computed at or after each multiple of the period (in lockstep every
    /// step is computed, so exactly at the multiples; a realtime agent may skip steps). A failed
    /// write is logged and the run goes on: only a later warm restart would miss it.
    pub fn before_step(&mut self, agent: &Agent, k: u64) {
        self.take(agent, k);
        self.write_taken();
    }

    /// Takes the checkpoint of step k if one is due (the same steps as [`Self::before_step`]) and
    /// keeps it for [`Self::write_taken`]: a realtime agent encodes its state before the control
    /// of k and writes the file once its command is out, so the file system (a create, a write
    /// of some 60-80 kB and a rename, at times longer than a step) never holds a command back.
    /// A process that dies in between leaves the previous checkpoint, which a warm restart
    /// replays from as it would from any other.
    pub fn take(&mut self, agent: &Agent, k: u64) {
        if k < self.next {
            return;
        }
        self.next = (k / self.every + 1) * self.every;
        match agent.checkpoint() {
            Ok(state) => self.taken = Some(Checkpoint { step: k, state }),
            Err(e) => warn(self.agent, k, &e.to_string()),
        }
    }

    /// Writes the checkpoint [`Self::take`] kept, if any: here, or handed to the writing thread
    /// when there is one ([`Self::write_in_background`]; one still busy with the previous
    /// checkpoint, a period ago, has this one dropped and logged).
    pub fn write_taken(&mut self) {
        let Some(c) = self.taken.take() else {
            return;
        };
        if let Some(to) = self.writer.as_ref().and_then(|w| w.to.as_ref()) {
            if let Err(e) = to.try_send(c) {
                let step = match &e {
                    mpsc::TrySendError::Full(c) | mpsc::TrySendError::Disconnected(c) => c.step,
                };
                warn(
                    self.agent,
                    step,
                    "the writing thread is still busy with the previous one",
                );
            }
            return;
        }
        if let Err(e) = restart::write_checkpoint(&self.path, self.agent, self.scenario_hash, &c) {
            warn(self.agent, c.step, &e.to_string());
        }
    }

    /// From now on the checkpoints are written by a thread of their own under the normal policy
    /// at nice [`sched::BACKGROUND_NICE`] (a realtime agent: its control thread runs under
    /// `SCHED_FIFO`, and a write of 60-80 kB on the same CPU would hold back the plant or another
    /// agent for its duration). The thread ends, after its last write, when `self` is dropped.
    pub fn write_in_background(&mut self) -> std::io::Result<()> {
        let (to, from) = mpsc::sync_channel::<Checkpoint>(1);
        let (path, agent, hash) = (self.path.clone(), self.agent, self.scenario_hash);
        let thread = std::thread::Builder::new()
            .name("checkpoint".into())
            .spawn(move || {
                // Best effort: a thread left at the control's policy still writes.
                let _ = sched::other_policy();
                sched::background_thread();
                for c in from {
                    if let Err(e) = restart::write_checkpoint(&path, agent, hash, &c) {
                        warn(agent, c.step, &e.to_string());
                    }
                }
            })?;
        self.writer = Some(Writer {
            to: Some(to),
            thread: Some(thread),
        });
        Ok(())
    }
}

impl Drop for Writer {
    fn drop(&mut self) {
        drop(self.to.take());
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

fn warn(agent: usize, k: u64, e: &str) {
    tracing::warn!(
        agent = agent + 1,
        step = k,
        "cannot write the checkpoint: {e}"
    );
}

/// Rebuilds agent i for taking over at step `r` from `DIR/checkpoints/agent-<id>.rejoin` (and the
/// checkpoint it names): restores, replays, refills the histories, and applies the runtime events
/// published so far to its timeline.
pub fn rebuild(b: &Boot, i: usize, agent: &mut Agent, r: u64) -> Result<(), NodeError> {
    let dir = &b.args.run_dir;
    let path = restart::rejoin_path(dir, i);
    let plan: RejoinFile = restart::read_rejoin(&path, i, b.scenario_hash, r)
        .map_err(|e| NodeError::Args(e.to_string()))?;
    for e in &plan.events {
        e.apply(agent.timeline_mut());
    }
    let mut checkpoint = None;
    if let Some(s) = plan.checkpoint {
        let cpath = restart::checkpoint_path(dir, i);
        let c: Checkpoint = restart::read_checkpoint(&cpath, i, b.scenario_hash)
            .map_err(|e| NodeError::Args(e.to_string()))?;
        if c.step != s {
            return Err(NodeError::Args(format!(
                "{} holds step {}, the rejoin plan step {s}",
                cpath.display(),
                c.step
            )));
        }
        agent
            .restore(&c.state)
            .map_err(|e| NodeError::Args(format!("{}: {e}", cpath.display())))?;
        checkpoint = Some(s);
    }
    let mission = formation_leader::Mission::from_scenario(&b.scenario);
    let dt = b.scenario.simulation.dt_s;
    let replayed = rebuild_from(
        agent,
        &Rejoin {
            checkpoint,
            down_from: plan.down_from,
            rejoin_at: r,
            recorded_from: plan.first,
        },
        |k| {
            let mut f = ReferenceFrame::default();
            mission.reference(k, k as f64 * dt, &mut f);
            f
        },
        |k, j| plan.state(k, j),
        |k| plan.flown_command(k),
    );
    if b.args.realtime {
        // Its own down window, open until its first live answer (`realtime::LiveReEntry`): there
        // its controller re-arms its reference generator from where the failsafe left it, as a
        // lockstep successor does at the return its timeline names.
        agent.set_down(i, plan.down_from);
    }
    // A realtime agent's commands depend on when its inputs arrived, which the replay from the
    // recorded states cannot reproduce: there the count is informative only.
    if replayed.mismatches > 0 && !b.args.realtime {
        tracing::warn!(
            agent = i + 1,
            replayed = replayed.steps,
            mismatches = replayed.mismatches,
            "warm restore: replayed commands differ from the recorded ones"
        );
    }
    tracing::info!(
        agent = i + 1,
        rejoin_at = r,
        checkpoint = ?checkpoint,
        down_from = plan.down_from,
        replayed = replayed.steps,
        mismatches = replayed.mismatches,
        "taking over"
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use formation_config::scenario::Scenario;
    use formation_config::Variant;

    #[test]
    fn a_taken_checkpoint_is_on_disk_only_once_written_and_holds_the_state_before_the_control() {
        let dir = std::env::temp_dir().join(format!("fm-ckpt-test-{}", std::process::id()));
        let path = restart::checkpoint_path(&dir, 1);
        let agent = Agent::new(&Scenario::paper(), 1, Variant::Proposed);
        let mut c = Checkpoints::at(path.clone(), 7, 1000, (1, 0));
        c.take(&agent, 0);
        assert!(!path.exists(), "taken, not written yet");
        c.write_taken();
        let read = restart::read_checkpoint(&path, 1, 7).expect("written");
        assert_eq!(read.step, 0);
        assert_eq!(read.state, agent.checkpoint().unwrap());
        // Not due before step 1000; due at the first step computed at or after it.
        c.take(&agent, 999);
        assert!(c.taken.is_none());
        c.take(&agent, 1003);
        assert_eq!(c.taken.as_ref().map(|t| t.step), Some(1003));
        c.write_taken();
        assert_eq!(restart::read_checkpoint(&path, 1, 7).unwrap().step, 1003);
        c.write_taken();
        assert_eq!(c.next, 2000);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_background_writer_writes_every_checkpoint_handed_to_it_before_it_ends() {
        let dir = std::env::temp_dir().join(format!("fm-ckpt-bg-{}", std::process::id()));
        let path = restart::checkpoint_path(&dir, 2);
        let agent = Agent::new(&Scenario::paper(), 2, Variant::Proposed);
        let mut c = Checkpoints::at(path.clone(), 9, 1000, (2, 0));
        c.write_in_background().unwrap();
        c.take(&agent, 0);
        c.write_taken();
        drop(c); // joins the thread after its last write
        assert_eq!(restart::read_checkpoint(&path, 2, 9).unwrap().step, 0);
        let _ = std::fs::remove_dir_all(&dir);
    }
}
