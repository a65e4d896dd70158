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

use super::takeover::{Death, FIRST_AGENT};

/// How often the children are checked for an unexpected exit.
const SUPERVISE_EVERY: Duration = Duration::from_millis(50);
/// Longest wait for every role process to be ready.
const START_TIMEOUT: Duration = Duration::from_secs(30);

/// The parts of a started run that the driver acts on: its ports and node, its role processes,
/// their supervision and the Ctrl-C flag.
pub struct Crew<'r> {
    /// The orchestrator's ports.
    pub ports: &'r Ports,
    /// The orchestrator's iceoryx2 node (the successors of a takeover open their ports on it).
    pub node: &'r RunNode,
    /// Plant, leader, then the agents ([`FIRST_AGENT`]).
    pub children: &'r mut [RoleProcess],
    /// The supervision: deaths, hangs, restarts.
    pub takeover: &'r mut super::takeover::Takeover,
    /// Set by Ctrl-C.
    pub interrupted: &'r AtomicBool,
}

/// Where the steps go: the recorder, the live registry and injections, the step timing.
pub struct Outputs<'r> {
    /// Writes every step (trajectory.csv and the other sinks).
    pub recorder: &'r mut Recorder,
    /// The registry record (`formation ps`) and the injections of `formation inject`.
    pub live: &'r mut super::Live,
    /// The wall time of each batch of steps.
    pub step_timing: &'r mut super::step_timing::StepTiming,
}

/// What the supervision looks at, once per [`SUPERVISE_EVERY`].
#[derive(Debug, Clone, Copy)]
struct Watch {
    /// The stall timeout, if the run has one.
    stall: Option<Duration>,
    /// Wall time since the last step recorded.
    since_progress: Duration,
    /// Wall time since the last check.
    since_check: Duration,
    /// Steps recorded.
    recorded: u64,
    /// Realtime: an agent whose commands have been missing for the stall timeout, and for how
    /// long.
    silent: Option<(usize, Duration)>,
}

/// Watches children, Ctrl-C and the progress of the run: a dead agent is handled by the
/// supervision (`takeover`), and so is one found stopped once the run has made no progress for the
/// stall timeout, and (realtime, where the plant flies on) one whose commands have been missing
/// from the step records for the stall timeout (`silent`); returns the reason to stop, if any.
fn supervise(crew: &mut Crew, w: &Watch) -> Option<Outcome> {
    if crew.interrupted.load(Ordering::SeqCst) {
        return Some(Outcome::Interrupted);
    }
    let children = &mut *crew.children;
    let takeover = &mut *crew.takeover;
    // Every child found dead now (the agents of a lost host die together), then a silent or
    // stopped one.
    let found: Vec<(usize, String)> =
        std::iter::from_fn(|| spawn::check_indexed(children)).collect();
    let mut deaths: Vec<Death> = found
        .into_iter()
        .map(|(idx, line)| Death {
            idx,
            line,
            hung: false,
            since_seen: w.since_check,
            port_held: children[idx].exit_code() == Some(i32::from(crate::cli::EXIT_PORT_HELD)),
        })
        .collect();
    if let (true, Some((i, quiet))) = (deaths.is_empty(), w.silent) {
        let c = &mut children[FIRST_AGENT + i];
        let line = format!(
            "{} (pid {}) sent no command for {} ms{}",
            c.label,
            c.pid(),
            quiet.as_millis(),
            if c.is_stopped() { " (stopped)" } else { "" }
        );
        c.kill_and_reap();
        deaths.push(Death {
            idx: FIRST_AGENT + i,
            line,
            hung: true,
            since_seen: quiet,
            port_held: false,
        });
    }
    let still = takeover.still_for(w.since_progress);
    if let Some(limit) = w
        .stall
        .map(|l| takeover.stall_limit(l))
        .filter(|l| deaths.is_empty() && still >= *l)
    {
        let hung = (0..children.len()).find(|&idx| {
            let expected = idx >= FIRST_AGENT && takeover.expects_gone(idx - FIRST_AGENT);
            !expected && children[idx].is_stopped()
        });
        let Some(idx) = hung else {
            let line = format!(
                "the run made no progress for {} ms at step {} and no role process is stopped; stopping the run",
                still.as_millis(),
                w.recorded
            );
            eprintln!("error: {line}");
            return Some(Outcome::Died(line));
        };
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
        deaths.push(Death {
            idx,
            line,
            hung: true,
            since_seen: limit,
            port_held: false,
        });
    }
    for death in deaths {
        if let Err(line) = takeover.on_death(death, w.recorded, crew.node, children) {
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
pub fn wait_for_hellos(crew: &mut Crew, n: usize) -> Result<Duration, Outcome> {
    let start = Instant::now();
    // Plant, leader, then the agents.
    let mut ready = vec![false; n + 2];
    // Agents started afresh: only their new process's hello counts (the lost one's may still be
    // queued).
    let mut relaunched = vec![false; n + 2];
    while ready.iter().any(|r| !r) {
        if crew.interrupted.load(Ordering::SeqCst) {
            return Err(Outcome::Interrupted);
        }
        while let Some((idx, line)) = spawn::check_indexed(crew.children) {
            match crew
                .takeover
                .on_death_at_start(idx, line, crew.node, crew.children)
            {
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
        crew.ports
            .wake
            .wait(SUPERVISE_EVERY)
            .map_err(|e| Outcome::Failed(e.to_string()))?;
        while let Ok(Some(h)) = crew.ports.hello.receive() {
            let idx = match h.role {
                r if r == Role::Plant as u32 => Some(0),
                r if r == Role::Leader as u32 => Some(1),
                r if r == Role::Agent as u32 => Some(FIRST_AGENT + h.agent as usize),
                _ => None,
            };
            let idx = idx.filter(|&k| {
                k < ready.len() && (!relaunched[k] || crew.children[k].pid() == h.pid)
            });
            if let Some(r) = idx.and_then(|k| ready.get_mut(k)) {
                *r = true;
                if h.role == Role::Agent as u32 {
                    crew.takeover.on_hello_at_start(h.agent as usize);
                }
            }
        }
    }
    Ok(start.elapsed())
}

/// Drives the run to its end (or divergence, interruption, failure); returns the outcome and the
/// number of steps recorded.
pub fn drive(
    crew: Crew,
    outputs: Outputs,
    scenario: &formation_config::Scenario,
) -> (Outcome, u64) {
    let mut d = Driver::new(crew, outputs, scenario);
    if let Err(e) = d.crew.ports.announce(0) {
        return (Outcome::Failed(e.to_string()), 0);
    }
    loop {
        if let Err(outcome) = d.on_wake() {
            return (outcome, d.recorded);
        }
    }
}

/// `Err`: the run ends with this outcome (completed included).
type Going<T> = Result<T, Outcome>;

/// The orchestrator while the steps run: a state machine that reacts to each wake-up (step
/// records, hellos, injections, the supervision's period).
struct Driver<'r> {
    crew: Crew<'r>,
    out: Outputs<'r>,
    /// The reference of step k is a pure function of (k, t_k): the recorder computes it with the
    /// same code as the leader process (bit-identical), instead of depending on the leader's
    /// stream.
    mission: formation_leader::Mission,
    /// Agents N.
    n: usize,
    /// Steps of the run.
    steps: u64,
    /// Step, s.
    dt: f64,
    /// The stall timeout, if the run has one.
    stall: Option<Duration>,
    /// A realtime run (the plant keeps its own clock).
    realtime: bool,
    /// Steps recorded.
    recorded: u64,
    reference: ReferenceFrame,
    truths: Vec<PlantTruth>,
    commands: Vec<ControlCommand>,
    progress: Progress,
    /// When a step was last recorded.
    last_progress: Instant,
    /// When the supervision last looked.
    last_check: Instant,
    /// Realtime: when each agent's command was last in a step record (its own, not the
    /// fallback's: those carry no send stamp); None before its first.
    heard: Vec<Option<Instant>>,
    /// The agents whose new process said hello at this wake-up.
    hellos: Vec<u32>,
}

impl<'r> Driver<'r> {
    fn new(crew: Crew<'r>, out: Outputs<'r>, scenario: &formation_config::Scenario) -> Self {
        let stall = crew.takeover.stall_timeout(&scenario.runtime);
        let n = scenario.n_agents();
        let (steps, dt) = (scenario.n_steps(), scenario.simulation.dt_s);
        let realtime = !crew.ports.wake_plant_on_progress;
        Driver {
            crew,
            out,
            mission: formation_leader::Mission::from_scenario(scenario),
            n,
            steps,
            dt,
            stall,
            realtime,
            recorded: 0,
            reference: ReferenceFrame::default(),
            truths: vec![PlantTruth::default(); n],
            commands: vec![ControlCommand::default(); n],
            progress: Progress::new(steps, dt),
            last_progress: Instant::now(),
            last_check: Instant::now(),
            heard: vec![None; n],
            hellos: Vec::new(),
        }
    }

    /// One wake-up: records the steps that arrived, follows new processes, forwards injections,
    /// lets the plant move on, and supervises once per [`SUPERVISE_EVERY`].
    fn on_wake(&mut self) -> Going<()> {
        let ports = self.crew.ports;
        ports
            .wake
            .wait(SUPERVISE_EVERY)
            .map_err(|e| Outcome::Failed(e.to_string()))?;
        let got = self.record_steps()?;
        if got > 0 {
            self.out
                .step_timing
                .on_recorded(Instant::now(), self.recorded);
            self.last_progress = Instant::now();
        }
        self.receive_hellos();
        if let Err(e) = self.crew.takeover.poll(
            self.recorded,
            &self.hellos,
            self.crew.node,
            self.crew.children,
        ) {
            eprintln!("error: {e}");
            return Err(Outcome::Died(e));
        }
        if !self.hellos.is_empty() {
            // A new agent process has its ports: `formation ps` lists it from now on.
            self.out
                .live
                .registration
                .follow_processes(self.crew.children.iter().map(|c| (c.pid(), c.host())));
        }
        if self.recorded >= self.steps {
            self.progress.finish(self.recorded);
            return Err(Outcome::Completed);
        }
        // Injections are forwarded before the progress that lets the plant move on.
        self.forward_injections()?;
        self.out.live.registration.update(self.recorded);
        if got > 0 {
            ports
                .announce(self.recorded)
                .map_err(|e| Outcome::Failed(e.to_string()))?;
        }
        if self.last_check.elapsed() >= SUPERVISE_EVERY {
            self.check()?;
        }
        Ok(())
    }

    /// Records every step record that arrived; returns how many.
    fn record_steps(&mut self) -> Going<usize> {
        let mut got = 0;
        while let Ok(Some(s)) = self.crew.ports.steps.receive() {
            let entries = s.payload();
            let k = self.recorded;
            let stamped = entries.first().map_or(k, |e| e.truth.state.step);
            if let Some(msg) = protocol_error(entries.len(), self.n, stamped, k) {
                return Err(Outcome::Failed(msg));
            }
            for (e, (t, c)) in entries
                .iter()
                .zip(self.truths.iter_mut().zip(self.commands.iter_mut()))
            {
                *t = e.truth;
                *c = e.command;
            }
            self.crew.takeover.on_record(k, entries);
            if self.realtime {
                let now = Instant::now();
                for (h, e) in self.heard.iter_mut().zip(entries) {
                    if e.command.sent_ns != 0 {
                        *h = Some(now);
                    }
                }
            }
            drop(s);
            got += 1;
            self.mission
                .reference(k, k as f64 * self.dt, &mut self.reference);
            self.recorded = k + 1;
            match self
                .out
                .recorder
                .record(k, &self.reference, &self.truths, &self.commands)
            {
                Ok(Some(_divergence)) => return Err(Outcome::Completed),
                Ok(None) => {}
                Err(e) => {
                    let msg = format!("cannot write trajectory.csv: {e}");
                    return Err(Outcome::Failed(msg));
                }
            }
        }
        Ok(got)
    }

    /// Reads the hellos of new agent processes; their silence counts from their hello.
    fn receive_hellos(&mut self) {
        self.hellos.clear();
        while let Ok(Some(h)) = self.crew.ports.hello.receive() {
            if h.role == Role::Agent as u32 {
                self.hellos.push(h.agent);
                if let Some(t) = self.heard.get_mut(h.agent as usize) {
                    *t = Some(Instant::now());
                }
            }
        }
    }

    /// Forwards the injections of `formation inject` to the processes and logs them in the
    /// recording.
    fn forward_injections(&mut self) -> Going<()> {
        let events = self
            .out
            .live
            .injections
            .poll(self.recorded)
            .map_err(|e| Outcome::Failed(e.to_string()))?;
        for e in events {
            self.crew.takeover.publish(e).map_err(Outcome::Failed)?;
        }
        for line in self.out.live.injections.take_logged() {
            self.out
                .recorder
                .event(&line)
                .map_err(|e| Outcome::Failed(format!("cannot write run.mcap: {e}")))?;
        }
        Ok(())
    }

    /// The supervision's period: names a silent agent (realtime), then [`supervise`]s.
    fn check(&mut self) -> Going<()> {
        let since_check = self.last_check.elapsed();
        self.last_check = Instant::now();
        let silent = self.stall.filter(|_| self.realtime).and_then(|limit| {
            let now = Instant::now();
            let takeover = &*self.crew.takeover;
            first_silent(&self.heard, now, limit, |i| takeover.expects_gone(i))
        });
        if let Some((i, _)) = silent {
            // Named once: a new process restarts the count at its hello.
            self.heard[i] = None;
        }
        let watch = Watch {
            stall: self.stall,
            since_progress: self.last_progress.elapsed(),
            since_check,
            recorded: self.recorded,
            silent,
        };
        if let Some(o) = supervise(&mut self.crew, &watch) {
            self.progress.finish(self.recorded);
            return Err(o);
        }
        self.progress.show(self.recorded);
        Ok(())
    }
}

/// Why a step record breaks the protocol, if it does: it must hold one entry per agent (`n`) and
/// be the step expected next (`stamped`: the step its first entry carries).
fn protocol_error(entries: usize, n: usize, stamped: u64, expected: u64) -> Option<String> {
    if entries != n {
        return Some(format!(
            "protocol error: step record with {entries} entries"
        ));
    }
    (stamped != expected)
        .then(|| format!("protocol error: record of step {stamped} while expecting {expected}"))
}

/// Realtime: the first agent whose own commands have been missing from the step records for at
/// least `limit` at `now` (`heard`: when each was last heard, `None` before its first or once
/// named) and that is not expected gone; with how long it has been quiet.
fn first_silent(
    heard: &[Option<Instant>],
    now: Instant,
    limit: Duration,
    expects_gone: impl Fn(usize) -> bool,
) -> Option<(usize, Duration)> {
    heard.iter().enumerate().find_map(|(i, t)| {
        let quiet = now.saturating_duration_since((*t)?);
        (quiet >= limit && !expects_gone(i)).then_some((i, quiet))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_record_with_the_wrong_number_of_entries_or_step_breaks_the_protocol() {
        assert_eq!(protocol_error(5, 5, 7, 7), None);
        assert_eq!(
            protocol_error(4, 5, 7, 7).as_deref(),
            Some("protocol error: step record with 4 entries")
        );
        assert_eq!(
            protocol_error(5, 5, 8, 7).as_deref(),
            Some("protocol error: record of step 8 while expecting 7")
        );
    }

    #[test]
    fn the_first_agent_quiet_for_the_limit_and_not_expected_gone_is_silent() {
        let now = Instant::now() + Duration::from_secs(10);
        let ago = |ms| Some(now - Duration::from_millis(ms));
        let heard = [ago(100), None, ago(900), ago(1200)];
        let limit = Duration::from_millis(800);
        assert_eq!(
            first_silent(&heard, now, limit, |_| false),
            Some((2, Duration::from_millis(900)))
        );
        assert_eq!(
            first_silent(&heard, now, limit, |i| i == 2),
            Some((3, Duration::from_millis(1200)))
        );
        assert_eq!(first_silent(&heard, now, limit, |i| i >= 2), None);
        assert_eq!(first_silent(&[None, None], now, limit, |_| false), None);
    }
}
