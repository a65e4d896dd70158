//! The orchestrator's side of the lockstep: wait for every role process to say hello, start the run,
//! feed every step's records to the [`Recorder`], pace plant and leader, and watch the children.

use super::progress::Progress;
use super::spawn::{self, RoleProcess};
use crate::record::Recorder;
use formation_config::node::error::PortError;
use formation_config::node::ports::{
    notifier, poke, publisher, slice_subscriber, subscriber, Input, Output, RunNode, Sub, Svc, Wake,
};
use formation_config::protocol::messages::{
    Hello, Role, RunControl, RunProgress, StepEntry, CONTROL_STOP,
};
use formation_config::protocol::services;
use formation_config::protocol::wire::{ControlCommand, PlantTruth, ReferenceFrame};
use iceoryx2::port::notifier::Notifier;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// How the run ended.
#[derive(Debug)]
pub enum Outcome {
    /// Every step recorded, or the run diverged (recorded up to that step).
    Completed,
    /// Ctrl-C.
    Interrupted,
    /// A role process died or the protocol broke: the message.
    Failed(String),
    /// A role process exited or died: the line naming it, printed on stderr when it was detected
    /// (and in the log through `Debug`).
    Died(#[allow(dead_code)] String),
}

/// The orchestrator's ports.
pub struct Ports {
    hello: Input<Hello>,
    steps: Sub<[StepEntry]>,
    control: Output<RunControl>,
    progress: Output<RunProgress>,
    wakes: Vec<Notifier<Svc>>,
    wake: Wake,
    /// Lockstep: progress paces the plant, so it is woken; realtime: the plant keeps its own clock.
    wake_plant_on_progress: bool,
}

impl Ports {
    /// Makes the orchestrator's ports on the created services.
    pub fn open(
        node: &RunNode,
        n: usize,
        wake_plant_on_progress: bool,
    ) -> Result<Ports, PortError> {
        let mut wakes = vec![
            notifier(node, &services::WAKE_PLANT.named())?,
            notifier(node, &services::WAKE_LEADER.named())?,
        ];
        for i in 0..n {
            wakes.push(notifier(node, &services::WAKE_AGENT.at(i))?);
        }
        Ok(Ports {
            hello: subscriber(node, &services::HELLO.named())?,
            steps: slice_subscriber(node, &services::STEPS.named())?,
            control: publisher(node, &services::CONTROL.named())?,
            progress: publisher(node, &services::PROGRESS.named())?,
            wakes,
            wake: Wake::open(node, &services::WAKE_ORCHESTRATOR.named())?,
            wake_plant_on_progress,
        })
    }

    /// Tells every role process to stop.
    pub fn stop(&self, recorded: u64) {
        let _ = formation_config::node::ports::send(
            &self.control,
            RunControl {
                kind: CONTROL_STOP,
                _pad: 0,
                step: recorded,
            },
        );
        self.wakes.iter().for_each(poke);
    }

    fn announce(&self, recorded: u64) -> Result<(), PortError> {
        formation_config::node::ports::send(&self.progress, RunProgress { recorded })?;
        if self.wake_plant_on_progress || recorded == 0 {
            poke(&self.wakes[0]);
        }
        poke(&self.wakes[1]);
        Ok(())
    }
}

use super::takeover::FIRST_AGENT;

/// How often the children are checked for an unexpected exit.
const SUPERVISE_EVERY: Duration = Duration::from_millis(50);
/// Longest wait for every role process to be ready.
const START_TIMEOUT: Duration = Duration::from_secs(30);

/// Watches children, Ctrl-C and the progress of the run: a dead agent is handled by the
/// supervision (`takeover`), and so is one found stopped once the run has made no progress for the
/// stall timeout, and (realtime, where the plant flies on) one whose commands have been missing
/// from the step records for the stall timeout (`silent`: its index and for how long); returns
/// the reason to stop, if any.
#[allow(clippy::too_many_arguments)] // the supervision's inputs, each its own kind
fn supervise(
    children: &mut [RoleProcess],
    interrupted: &AtomicBool,
    takeover: &mut super::takeover::Takeover,
    stall: Option<Duration>,
    since_progress: Duration,
    since_check: Duration,
    recorded: u64,
    node: &RunNode,
    silent: Option<(usize, Duration)>,
) -> Option<Outcome> {
    if interrupted.load(Ordering::SeqCst) {
        return Some(Outcome::Interrupted);
    }
    // Every child found dead now (the agents of a lost host die together), then a silent or
    // stopped one.
    let mut deaths: Vec<(usize, String, bool, Duration)> =
        std::iter::from_fn(|| spawn::check_indexed(children))
            .map(|(idx, line)| (idx, line, false, since_check))
            .collect();
    if let (true, Some((i, quiet))) = (deaths.is_empty(), silent) {
        let c = &mut children[FIRST_AGENT + i];
        let line = format!(
            "{} (pid {}) sent no command for {} ms{}",
            c.label,
            c.pid(),
            quiet.as_millis(),
            if c.is_stopped() { " (stopped)" } else { "" }
        );
        c.kill_and_reap();
        deaths.push((FIRST_AGENT + i, line, true, quiet));
    }
    let still = takeover.still_for(since_progress);
    if let Some(limit) = stall
        .map(|l| takeover.stall_limit(l))
        .filter(|l| deaths.is_empty() && still >= *l)
    {
        let hung = (0..children.len()).find(|&idx| {
            let expected = idx >= 2 && takeover.expects_gone(idx - 2);
            !expected && children[idx].is_stopped()
        });
        match hung {
            Some(idx) => {
                let line = format!(
                    "{} (pid {}{}) made no progress for {} ms (stopped)",
                    children[idx].label,
                    children[idx].pid(),
                    children[idx]
                        .host()
                        .map(|h| format!(" on host {h}"))
                        .unwrap_or_default(),
                    still.as_millis()
                );
                children[idx].kill_and_reap();
                deaths.push((idx, line, true, limit));
            }
            None => {
                let line = format!(
                    "the run made no progress for {} ms at step {recorded} and no role process is stopped; stopping the run",
                    still.as_millis()
                );
                eprintln!("error: {line}");
                return Some(Outcome::Died(line));
            }
        }
    }
    for (idx, line, hung, seen) in deaths {
        if let Err(line) = takeover.on_death(idx, line, hung, seen, recorded, node, children) {
            // Said at once, before the other processes are stopped (which takes up to STOP_GRACE).
            eprintln!("error: {line}");
            return Some(Outcome::Died(line));
        }
    }
    None
}

/// Waits until plant, leader and the N agents have created their ports. An agent lost with its
/// host meanwhile is started afresh here under on-failure (`Takeover::on_death_at_start`) and its
/// hello awaited; any other death stops the run. Returns the measured start-up (from `launched`).
pub fn wait_for_hellos(
    ports: &Ports,
    n: usize,
    children: &mut [RoleProcess],
    interrupted: &AtomicBool,
    takeover: &mut super::takeover::Takeover,
    node: &RunNode,
) -> Result<Duration, Outcome> {
    let start = Instant::now();
    // Plant, leader, then the agents.
    let mut ready = vec![false; n + 2];
    // Agents started afresh: only their new process's hello counts (the lost one's may still be
    // queued).
    let mut relaunched = vec![false; n + 2];
    while ready.iter().any(|r| !r) {
        if interrupted.load(Ordering::SeqCst) {
            return Err(Outcome::Interrupted);
        }
        while let Some((idx, line)) = spawn::check_indexed(children) {
            match takeover.on_death_at_start(idx, line, node, children) {
                Ok(Some(i)) => {
                    ready[FIRST_AGENT + i] = false;
                    relaunched[FIRST_AGENT + i] = true;
                }
                Ok(None) => {}
                Err(line) => {
                    // Said at once, before the other processes are stopped (up to STOP_GRACE).
                    eprintln!("error: {line}");
                    return Err(Outcome::Died(line));
                }
            }
        }
        if start.elapsed() > START_TIMEOUT {
            let seen = ready.iter().filter(|r| **r).count();
            return Err(Outcome::Failed(format!(
                "only {seen} of {} role processes were ready after {} s",
                n + 2,
                START_TIMEOUT.as_secs()
            )));
        }
        ports
            .wake
            .wait(SUPERVISE_EVERY)
            .map_err(|e| Outcome::Failed(e.to_string()))?;
        while let Ok(Some(h)) = ports.hello.receive() {
            let idx = match h.role {
                r if r == Role::Plant as u32 => Some(0),
                r if r == Role::Leader as u32 => Some(1),
                r if r == Role::Agent as u32 => Some(FIRST_AGENT + h.agent as usize),
                _ => None,
            };
            let idx =
                idx.filter(|&k| k < ready.len() && (!relaunched[k] || children[k].pid() == h.pid));
            if let Some(r) = idx.and_then(|k| ready.get_mut(k)) {
                *r = true;
                if h.role == Role::Agent as u32 {
                    takeover.on_hello_at_start(h.agent as usize);
                }
            }
        }
    }
    Ok(start.elapsed())
}

/// Drives the run to its end (or divergence, interruption, failure); returns the outcome and the
/// number of steps recorded.
#[allow(clippy::too_many_arguments)] // the run's parts, each borrowed differently; no natural bundle
pub fn drive(
    ports: &Ports,
    live: &mut super::Live,
    mission: &formation_leader::Mission,
    recorder: &mut Recorder,
    scenario: &formation_config::Scenario,
    children: &mut [RoleProcess],
    interrupted: &AtomicBool,
    step_timing: &mut super::step_timing::StepTiming,
    takeover: &mut super::takeover::Takeover,
    node: &RunNode,
) -> (Outcome, u64) {
    let stall = takeover.stall_timeout(&scenario.runtime);
    let mut last_progress = Instant::now();
    let mut hellos: Vec<u32> = Vec::new();
    let n = scenario.n_agents();
    let steps = scenario.n_steps();
    let dt = scenario.simulation.dt_s;
    let mut recorded: u64 = 0;
    // The reference of step k is a pure function of (k, t_k): the recorder computes it with the same
    // code as the leader process (bit-identical), instead of depending on the leader's stream.
    let mut reference = ReferenceFrame::default();
    let mut truths = vec![PlantTruth::default(); n];
    let mut commands = vec![ControlCommand::default(); n];
    let mut progress = Progress::new(steps, dt);
    let mut last_check = Instant::now();
    // Realtime: when each agent's command was last in a step record (its own, not the fallback's:
    // those carry no send stamp); None before its first.
    let realtime = !ports.wake_plant_on_progress;
    let mut heard: Vec<Option<Instant>> = vec![None; n];
    if let Err(e) = ports.announce(0) {
        return (Outcome::Failed(e.to_string()), 0);
    }
    loop {
        if let Err(e) = ports.wake.wait(SUPERVISE_EVERY) {
            return (Outcome::Failed(e.to_string()), recorded);
        }
        let mut got = 0;
        while let Ok(Some(s)) = ports.steps.receive() {
            let entries = s.payload();
            if entries.len() != n {
                let msg = format!("protocol error: step record with {} entries", entries.len());
                return (Outcome::Failed(msg), recorded);
            }
            let k = recorded;
            let stamped = entries.first().map_or(k, |e| e.truth.state.step);
            if stamped != k {
                let msg = format!("protocol error: record of step {stamped} while expecting {k}");
                return (Outcome::Failed(msg), recorded);
            }
            for (e, (t, c)) in entries
                .iter()
                .zip(truths.iter_mut().zip(commands.iter_mut()))
            {
                *t = e.truth;
                *c = e.command;
            }
            takeover.on_record(k, entries);
            if realtime {
                let now = Instant::now();
                for (h, e) in heard.iter_mut().zip(entries) {
                    if e.command.sent_ns != 0 {
                        *h = Some(now);
                    }
                }
            }
            drop(s);
            got += 1;
            mission.reference(k, k as f64 * dt, &mut reference);
            recorded = k + 1;
            match recorder.record(k, &reference, &truths, &commands) {
                Ok(Some(_divergence)) => return (Outcome::Completed, recorded),
                Ok(None) => {}
                Err(e) => {
                    let msg = format!("cannot write trajectory.csv: {e}");
                    return (Outcome::Failed(msg), recorded);
                }
            }
        }
        if got > 0 {
            step_timing.on_recorded(Instant::now(), recorded);
            last_progress = Instant::now();
        }
        hellos.clear();
        while let Ok(Some(h)) = ports.hello.receive() {
            if h.role == formation_config::protocol::messages::Role::Agent as u32 {
                hellos.push(h.agent);
                if let Some(t) = heard.get_mut(h.agent as usize) {
                    // A new process: its silence counts from its hello.
                    *t = Some(Instant::now());
                }
            }
        }
        if let Err(e) = takeover.poll(recorded, &hellos, node, children) {
            eprintln!("error: {e}");
            return (Outcome::Died(e), recorded);
        }
        if !hellos.is_empty() {
            // A new agent process has its ports: `formation ps` lists it from now on.
            live.registration
                .follow_processes(children.iter().map(|c| (c.pid(), c.host())));
        }
        if recorded >= steps {
            progress.finish(recorded);
            return (Outcome::Completed, recorded);
        }
        // Injections are forwarded before the progress that lets the plant move on.
        match live.injections.poll(recorded) {
            Ok(events) => {
                for e in events {
                    if let Err(e) = takeover.publish(e) {
                        return (Outcome::Failed(e), recorded);
                    }
                }
            }
            Err(e) => return (Outcome::Failed(e.to_string()), recorded),
        }
        for line in live.injections.take_logged() {
            if let Err(e) = recorder.event(&line) {
                return (
                    Outcome::Failed(format!("cannot write run.mcap: {e}")),
                    recorded,
                );
            }
        }
        live.registration.update(recorded);
        if got > 0 {
            if let Err(e) = ports.announce(recorded) {
                return (Outcome::Failed(e.to_string()), recorded);
            }
        }
        if last_check.elapsed() >= SUPERVISE_EVERY {
            let since_check = last_check.elapsed();
            last_check = Instant::now();
            let silent = stall.filter(|_| realtime).and_then(|limit| {
                heard.iter().enumerate().find_map(|(i, t)| {
                    let quiet = (*t)?.elapsed();
                    (quiet >= limit && !takeover.expects_gone(i)).then_some((i, quiet))
                })
            });
            if let Some((i, _)) = silent {
                // Named once: a new process restarts the count at its hello.
                heard[i] = None;
            }
            if let Some(o) = supervise(
                children,
                interrupted,
                takeover,
                stall,
                last_progress.elapsed(),
                since_check,
                recorded,
                node,
                silent,
            ) {
                progress.finish(recorded);
                return (o, recorded);
            }
            progress.show(recorded);
        }
    }
}
