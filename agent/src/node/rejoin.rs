//! The agent process's side of a warm restart: writing checkpoints, and rebuilding the controller
//! from the last one and the recorded states when it is a new process taking over
//! (`formation_agent::restart`, `docs/failures.md`).

use crate::restart::{rebuild as rebuild_from, Rejoin};
use crate::Agent;
use formation_config::node::boot::Boot;
use formation_config::node::error::NodeError;
use formation_config::node::restart::{self, Checkpoint, RejoinFile};
use formation_config::protocol::wire::ReferenceFrame;
use std::path::PathBuf;

/// Where and when this process checkpoints.
pub struct Checkpoints {
    path: PathBuf,
    scenario_hash: u64,
    every: u64,
    /// The next step whose checkpoint is due.
    next: u64,
    agent: usize,
}

impl Checkpoints {
    /// Checkpoints of agent i every `runtime.checkpoint_every_s`, and at its first step `first`.
    pub fn new(b: &Boot, i: usize, first: u64) -> Checkpoints {
        Checkpoints {
            path: restart::checkpoint_path(&b.args.run_dir, i),
            scenario_hash: b.scenario_hash,
            every: b
                .scenario
                .runtime
                .checkpoint_steps(b.scenario.simulation.dt_s),
            next: first,
            agent: i,
        }
    }

    /// Writes the checkpoint of step k if one is due (before its control): at the first step,
    /// then at the first step computed at or after each multiple of the period (in lockstep every
    /// step is computed, so exactly at the multiples; a realtime agent may skip steps). A failed
    /// write is logged and the run goes on: only a later warm restart would miss it.
    pub fn before_step(&mut self, agent: &Agent, k: u64) {
        if k < self.next {
            return;
        }
        self.next = (k / self.every + 1) * self.every;
        let written = agent
            .checkpoint()
            .map_err(|e| e.to_string())
            .and_then(|state| {
                restart::write_checkpoint(
                    &self.path,
                    self.agent,
                    self.scenario_hash,
                    &Checkpoint { step: k, state },
                )
                .map_err(|e| e.to_string())
            });
        if let Err(e) = written {
            tracing::warn!(
                agent = self.agent + 1,
                step = k,
                "cannot write the checkpoint: {e}"
            );
        }
    }
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
