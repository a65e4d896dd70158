//! The orchestrator's side of crashes, hangs and restarts in a lockstep run (`docs/failures.md`):
//! it keeps the recorded states a new agent process rebuilds from, carries out the
//! [`Supervisor`]'s actions on the processes (SIGKILL, SIGSTOP, respawn) and on the runtime-event
//! service, and logs what happened when, for `summary.json`.

use super::spawn::{self, RoleProcess};
use super::supervise::{Action, Ending, Plan, Supervisor};
use crate::history::{self, History};
use formation_config::node::args::ChildArgs;
use formation_config::node::ports::{
    notifier, poke, publisher, send, subscriber, Input, Output, RunNode, Svc,
};
use formation_config::node::restart::{self, RejoinFile};
use formation_config::protocol::messages::{
    Role, RuntimeEvent, StepEntry, EVENT_ANY, EVENT_DOWN, EVENT_DOWN_REQUEST, EVENT_JOINED,
    EVENT_UP_AGAIN,
};
use formation_config::protocol::services;
use formation_config::scenario::events::{RestartPolicy, Runtime};
use formation_config::Scenario;
use iceoryx2::port::notifier::Notifier;
use std::path::PathBuf;
use std::time::{Duration, Instant};

/// Sim time the ring of recorded steps covers beyond a checkpoint period and the delay histories
/// when the timeline has no longer down window, s.
const RESTART_WINDOW_S: f64 = 2.0;

/// Index of agent i among the children (plant, leader, then the agents).
pub(super) const FIRST_AGENT: usize = 2;

/// One handled incident, for `summary.json` (`events`).
#[derive(Debug, Clone, PartialEq)]
pub struct Incident {
    /// `crash`, `hang` (timeline), `died`, `hung`, `host_lost` (detected).
    pub kind: &'static str,
    /// `host_lost`: the host the agent was lost with.
    pub host: Option<String>,
    /// Agent index (0-based).
    pub agent: usize,
    /// First step the agent was down.
    pub down_from: Option<u64>,
    /// Step its new process took over.
    pub rejoin_at: Option<u64>,
    /// Detected death or stall: wall ms from the last time the process was seen working.
    pub detected_after_ms: Option<f64>,
    /// Wall ms from the kill (or detection) to the new process's hello.
    pub restarted_after_ms: Option<f64>,
    started: Instant,
}

/// A child found dead, stopped or silent, for [`Takeover::on_death`].
pub struct Death {
    /// Its index among the children (plant, leader, then the agents from [`FIRST_AGENT`]).
    pub idx: usize,
    /// The line naming it and what happened.
    pub line: String,
    /// Killed by the supervision (stopped or silent), not found dead.
    pub hung: bool,
    /// Wall time since it was last seen working.
    pub since_seen: Duration,
    /// It exited because a predecessor still holds its ports (`cli::EXIT_PORT_HELD`).
    pub port_held: bool,
}

/// How a successor agent process is started: the executable, an agent's command line (its
/// index and rejoin step are set per process), the run's placement, and the other hosts of a
/// multi-host run (agents there are respawned there, their checkpoints fetched first).
pub struct Respawn {
    /// The `formation` executable.
    pub exe: PathBuf,
    /// An agent's command line.
    pub args: ChildArgs,
    /// The run's placement (where a successor starts).
    pub pins: super::governor::Pins,
    /// The other hosts, if any.
    pub remote: Option<std::rc::Rc<super::remote::RemoteRun>>,
}

/// Everything the takeover of agents needs.
pub struct Takeover {
    supervisor: Supervisor,
    history: History,
    /// Every runtime event published or received so far (a new process's timeline).
    published: Vec<RuntimeEvent>,
    events_in: Input<RuntimeEvent>,
    events_out: Output<RuntimeEvent>,
    plant_wake: Notifier<Svc>,
    agent_wakes: Vec<Notifier<Svc>>,
    exe: PathBuf,
    args: ChildArgs,
    pins: super::governor::Pins,
    n: usize,
    capacity: usize,
    /// A realtime run: a dead agent is replaced at once, without take-down or announcement.
    realtime: bool,
    /// Agents on other hosts are respawned there, with their checkpoints fetched first.
    remote: Option<std::rc::Rc<super::remote::RemoteRun>>,
    /// Realtime: when each replaced agent was down (its death seen, its successor joined), as
    /// `EVENT_DOWN` / `EVENT_UP_AGAIN` for the summary only (never sent to the processes).
    realtime_windows: Vec<RuntimeEvent>,
    /// Hash of the run's `scenario.toml`, which its checkpoints must carry.
    scenario_hash: u64,
    /// Checkpoints refused per agent (restarted cold instead).
    checkpoints_refused: Vec<u32>,
    /// `runtime.restart = "on-failure"`: a lost host's agents are taken over here.
    on_failure: bool,
    /// When each agent was last seen working: its command in a step record (lockstep: any record,
    /// every command in one is its agent's own until it is taken down; realtime: a command with
    /// its send stamp, not the plant's fallback).
    last_seen: Vec<Option<Instant>>,
    /// Realtime: the step after the last one whose record holds each agent's own command (with
    /// its send stamp): where its down window starts when it dies or falls silent.
    flown_to: Vec<Option<u64>>,
    /// When the supervision last acted (a death handled, a take-down seen, a successor started or
    /// joined): a stall is counted from it or from the last step recorded, whichever is later.
    last_action: Instant,
    /// The run's measured start-up: from the launch of its processes to every hello.
    startup: Option<Duration>,
    /// Successors waiting out their backoff (`supervise::restart_backoff`): when each starts.
    pending: Vec<(Instant, Plan)>,
    /// What happened, in order.
    pub incidents: Vec<Incident>,
}

impl Takeover {
    /// Opens the ports; `respawn` says how a successor starts, `lead`: steps ahead of the recorder
    /// that an announcement must be (the plant's lead plus slack).
    // String: the supervision stops a run with the line it prints (`Outcome::Died`, `Failed`).
    pub fn open(
        node: &RunNode,
        scenario: &Scenario,
        variant: formation_config::Variant,
        respawn: Respawn,
        lead: u64,
    ) -> Result<Takeover, String> {
        let Respawn {
            exe,
            args,
            pins,
            remote,
        } = respawn;
        let n = scenario.n_agents();
        let timeline = scenario.timeline();
        let dt = scenario.simulation.dt_s;
        let capacity = formation_agent::Agent::new(scenario, 0, variant).history_capacity();
        // A restart under the policy (or a live crash) is down for about the announcement lead plus
        // the detection time: two seconds of steps at least. A longer live crash restarts from what
        // the ring still holds (cold if its checkpoint has left it).
        let longest = history::longest_down(&timeline, scenario.n_steps())
            .max((RESTART_WINDOW_S / dt) as u64);
        let len = history::len(&scenario.runtime, dt, capacity, longest);
        let mut agent_wakes = Vec::with_capacity(n);
        for i in 0..n {
            agent_wakes.push(notifier(node, &services::WAKE_AGENT.at(i))?);
        }
        Ok(Takeover {
            supervisor: Supervisor::new(n, timeline, scenario.runtime.clone(), lead),
            history: History::new(n, len),
            published: Vec::new(),
            events_in: subscriber(node, &services::RUNTIME_EVENTS.named())?,
            events_out: publisher(node, &services::RUNTIME_EVENTS.named())?,
            plant_wake: notifier(node, &services::WAKE_PLANT.named())?,
            agent_wakes,
            exe,
            args,
            pins,
            n,
            capacity,
            realtime: false,
            remote,
            realtime_windows: Vec::new(),
            scenario_hash: restart::scenario_hash(scenario.to_toml_string().as_bytes()),
            checkpoints_refused: vec![0; n],
            last_seen: vec![None; n],
            flown_to: vec![None; n],
            last_action: Instant::now(),
            startup: None,
            on_failure: scenario.runtime.restart == RestartPolicy::OnFailure,
            pending: Vec::new(),
            incidents: Vec::new(),
        })
    }

    /// Supervises a realtime run (`Supervisor::on_dead_realtime`).
    pub fn set_realtime(&mut self, realtime: bool) {
        self.realtime = realtime;
    }

    /// Checkpoints refused per agent (the restart went cold instead).
    pub fn checkpoints_refused(&self) -> &[u32] {
        &self.checkpoints_refused
    }

    /// Restarts under the policy, per agent.
    pub fn restarts(&self) -> &[u32] {
        self.supervisor.restarts()
    }

    /// The runtime events `summary.json` is built from ([`for_summary`]): the live timeline with
    /// every agent's down window closed where its new process took over, in lockstep (the
    /// plant's take-down and the announced rejoin) and realtime (death seen, new process joined).
    pub fn summary_events(&self, dt: f64) -> Vec<RuntimeEvent> {
        for_summary(&self.published, &self.realtime_windows, dt)
    }

    /// The incidents as marks for the recorder.
    pub fn marks(&self) -> Vec<crate::record::recovery::Mark> {
        self.incidents
            .iter()
            .filter_map(|x| {
                Some(crate::record::recovery::Mark {
                    kind: x.kind.to_string(),
                    agent: Some(x.agent),
                    agents: None,
                    step: x.down_from?,
                    detected_after_ms: x.detected_after_ms,
                    restarted_after_ms: x.restarted_after_ms,
                    // A lost host's agents are down until their successors take over, as a crash.
                    back_step: x.rejoin_at.filter(|_| x.host.is_some()),
                    host: x.host.clone(),
                })
            })
            .collect()
    }

    /// Keeps step k's record.
    pub fn on_record(&mut self, k: u64, entries: &[StepEntry]) {
        let now = Instant::now();
        for (i, e) in entries.iter().enumerate() {
            if !self.realtime || e.command.sent_ns != 0 {
                self.last_seen[i] = Some(now);
                self.flown_to[i] = Some(k + 1);
            }
            self.history.set_state(k, i, e.truth.state);
            self.history
                .set_command(k, i, (e.command.thrust_n, e.command.torque_nm));
        }
    }

    /// Publishes a runtime event to every process (a live injection, an announcement).
    // String: the supervision stops a run with the line it prints (`Outcome::Died`, `Failed`).
    pub fn publish(&mut self, e: RuntimeEvent) -> Result<(), String> {
        send(&self.events_out, e)?;
        self.published.push(e);
        self.supervisor.add_event(&e);
        poke(&self.plant_wake);
        self.agent_wakes.iter().for_each(poke);
        Ok(())
    }

    /// After a batch of records (`recorded` steps): reads the plant's take-downs and the hellos of
    /// new processes, and carries out what is due. `Err`: the run must stop (named on stderr).
    // String: the supervision stops a run with the line it prints (`Outcome::Died`, `Failed`).
    pub fn poll(
        &mut self,
        recorded: u64,
        hellos: &[u32],
        node: &RunNode,
        children: &mut [RoleProcess],
    ) -> Result<(), String> {
        let now = Instant::now();
        let (due, wait): (Vec<_>, Vec<_>) = self.pending.drain(..).partition(|(t, _)| *t <= now);
        self.pending = wait;
        for (_, plan) in due {
            self.respawn(plan, node, children)?;
        }
        while let Ok(Some(e)) = self.events_in.receive() {
            let e = *e;
            if e.kind != EVENT_DOWN {
                continue;
            }
            self.published.push(e);
            if let Some(a) = self
                .supervisor
                .on_taken_down(e.agent as usize, e.step, recorded)
            {
                if let Some(inc) = self
                    .incidents
                    .iter_mut()
                    .rev()
                    .find(|x| x.agent == e.agent as usize)
                {
                    inc.down_from = Some(e.step);
                }
                self.carry(a, recorded, node, children)?;
            }
        }
        for &agent in hellos {
            if let Some(a) = self.supervisor.on_hello(agent as usize) {
                self.carry(a, recorded, node, children)?;
            }
        }
        for a in self.supervisor.on_recorded(recorded) {
            self.carry(a, recorded, node, children)?;
        }
        Ok(())
    }

    /// A child exited, died or was killed as hung ([`Death`]): `Ok` when the run goes
    /// on (the timeline killed it, or it is being replaced), `Err` with the line to print.
    // String: the supervision stops a run with the line it prints (`Outcome::Died`, `Failed`).
    pub fn on_death(
        &mut self,
        death: Death,
        recorded: u64,
        node: &RunNode,
        children: &mut [RoleProcess],
    ) -> Result<(), String> {
        let Death {
            idx,
            line,
            hung,
            since_seen,
            port_held,
        } = death;
        let Some(i) = idx.checked_sub(FIRST_AGENT) else {
            return Err(format!(
                "{line}; stopping the run (plant and leader are not restarted)"
            ));
        };
        self.last_action = Instant::now();
        let lost = self.lost_host(idx, children)?;
        let line = self.naming_the_host(line, &lost);
        let ending = if port_held {
            Ending::PortHeld
        } else {
            Ending::Failed
        };
        match self.supervisor.on_death(i, &line, ending) {
            None => Ok(()),
            Some(Action::Fail(m)) => Err(format!("{m}; stopping the run")),
            Some(a) => {
                let mut incident = Incident {
                    kind: if hung { "hung" } else { "died" },
                    host: None,
                    agent: i,
                    down_from: None,
                    rejoin_at: None,
                    detected_after_ms: Some(since_seen.as_secs_f64() * 1e3),
                    restarted_after_ms: None,
                    started: Instant::now(),
                };
                match &lost {
                    Some((host, at)) => {
                        // From the last time it was seen working to the loss of its host.
                        let seen = self.last_seen[i].unwrap_or(*at);
                        incident.kind = "host_lost";
                        incident.host = Some(host.clone());
                        incident.detected_after_ms =
                            Some(at.saturating_duration_since(seen).as_secs_f64() * 1e3);
                        eprintln!(
                            "error: {line}; restarting it on {}",
                            super::remote::TAKEOVER_HOST
                        );
                    }
                    _ if port_held => eprintln!(
                        "error: {line}: its predecessor still holds its ports; starting it again once that one is gone (not counted in runtime.max_restarts)"
                    ),
                    _ => eprintln!("error: {line}; restarting it (runtime.restart = on-failure)"),
                }
                self.incidents.push(incident);
                let a = match a {
                    Action::TakeDown(i) if self.realtime => {
                        self.realtime_windows.push(RuntimeEvent {
                            step: recorded,
                            kind: EVENT_DOWN,
                            agent: i as u32,
                            other: EVENT_ANY,
                            ..RuntimeEvent::default()
                        });
                        children[FIRST_AGENT + i].kill_and_reap();
                        node.try_cleanup_dead_nodes();
                        let from = self.flown_to[i]
                            .unwrap_or(recorded)
                            .max(self.history.oldest());
                        match self.supervisor.on_dead_realtime(i, from, recorded) {
                            Some(a) => a,
                            None => return Err(format!("{line}; stopping the run")),
                        }
                    }
                    a => a,
                };
                self.carry(a, recorded, node, children)
            }
        }
    }

    /// The host child `idx` was lost with, if it was, and when; under on-failure that host's
    /// agents move here first (once per host), whatever the supervisor decides for this one (it
    /// may be parked for a timeline crash, whose successor starts here then). `Err`: the move
    /// failed and the run must stop.
    // String: the supervision stops a run with the line it prints (`Outcome::Died`, `Failed`).
    fn lost_host(
        &mut self,
        idx: usize,
        children: &[RoleProcess],
    ) -> Result<Option<(String, Instant)>, String> {
        let lost = self.remote.as_ref().and_then(|r| {
            let h = children[idx].host()?;
            r.lost_at(h).map(|t| (h.to_string(), t))
        });
        if let (Some((host, _)), Some(r), true) = (&lost, &self.remote, self.on_failure) {
            if let Some(moved) = r.take_over_host(host)? {
                eprintln!(
                    "error: host {host} lost; its agents {} are taken over on {} (runtime.restart = on-failure)",
                    ids(&moved),
                    super::remote::TAKEOVER_HOST
                );
            }
        }
        Ok(lost)
    }

    /// `line` naming, for an agent lost with its host, every agent lost with it.
    fn naming_the_host(&self, line: String, lost: &Option<(String, Instant)>) -> String {
        match (lost, &self.remote) {
            (Some((host, _)), Some(r)) => {
                let all = r.agents_lost_with(host);
                format!(
                    "{line}; host {host} held agent{} {}",
                    if all.len() == 1 { "" } else { "s" },
                    ids(&all)
                )
            }
            _ => line,
        }
    }

    /// Before the run's first step (not every process has said hello): child `idx` exited or died
    /// (`line` naming it). An agent lost with its host is started afresh here under on-failure
    /// (from the scenario's initial state: it has computed nothing yet); `Ok(Some(i))`: agent i
    /// was, and its hello is awaited again. `Err` with the line to print: the run must stop.
    // String: the supervision stops a run with the line it prints (`Outcome::Died`, `Failed`).
    pub fn on_death_at_start(
        &mut self,
        idx: usize,
        line: String,
        node: &RunNode,
        children: &mut [RoleProcess],
    ) -> Result<Option<usize>, String> {
        let Some(i) = idx.checked_sub(FIRST_AGENT) else {
            return Err(format!("{line}; stopping the run"));
        };
        let lost = self.lost_host(idx, children)?;
        let line = self.naming_the_host(line, &lost);
        let Some((host, at)) = lost else {
            return Err(format!("{line}; stopping the run"));
        };
        match self.supervisor.on_lost_at_start(i, &line) {
            Action::Relaunch(i) => {
                eprintln!(
                    "error: {line}; starting it afresh on {}",
                    super::remote::TAKEOVER_HOST
                );
                self.incidents.push(Incident {
                    kind: "host_lost",
                    host: Some(host),
                    agent: i,
                    down_from: Some(0),
                    rejoin_at: Some(0),
                    detected_after_ms: Some(0.0),
                    restarted_after_ms: None,
                    started: at,
                });
                self.carry(Action::Relaunch(i), 0, node, children)?;
                Ok(Some(i))
            }
            Action::Fail(m) => Err(format!("{m}; stopping the run")),
            other => Err(format!("{line}: unexpected {other:?}; stopping the run")),
        }
    }

    /// Agent i's process said hello before the run's first step.
    pub fn on_hello_at_start(&mut self, i: usize) {
        if let Some(inc) = self
            .incidents
            .iter_mut()
            .rev()
            .find(|x| x.agent == i && x.restarted_after_ms.is_none())
        {
            inc.restarted_after_ms = Some(inc.started.elapsed().as_secs_f64() * 1e3);
        }
    }

    /// The run's start-up was measured: `d` from the launch of its processes to every hello.
    pub fn set_startup(&mut self, d: Duration) {
        self.startup = Some(d);
    }

    /// How long the run has been still as a stall counts it: since the later of the last step
    /// recorded (`since_progress` ago) and the supervision's last action.
    pub fn still_for(&self, since_progress: Duration) -> Duration {
        since_progress.min(self.last_action.elapsed())
    }

    /// The stall limit now ([`stall_limit`]).
    pub fn stall_limit(&self, base: Duration) -> Duration {
        stall_limit(base, self.supervisor.taking_over(), self.startup)
    }

    /// Whether agent i's process is stopped or gone on purpose (a timeline hang or crash).
    pub fn expects_gone(&self, i: usize) -> bool {
        self.supervisor.expects_gone(i)
    }

    // String: the supervision stops a run with the line it prints (`Outcome::Died`, `Failed`).
    fn carry(
        &mut self,
        a: Action,
        recorded: u64,
        node: &RunNode,
        children: &mut [RoleProcess],
    ) -> Result<(), String> {
        self.last_action = Instant::now();
        match a {
            Action::Relaunch(i) => {
                children[FIRST_AGENT + i].kill_and_reap();
                node.try_cleanup_dead_nodes();
                let args = ChildArgs {
                    agent: Some(i),
                    ..self.args.clone()
                };
                let label = format!("agent {} (--agent {i})", i + 1);
                let child = self.pins.spawn(super::governor::Place::Agent(i), |cpu| {
                    spawn::spawn(&self.exe, Role::Agent, label, &args, cpu)
                })?;
                eprintln!(
                    "formation run: agent {} taken over at step 0 (t = 0.000 s) by pid {} (cold, from the initial state: lost before the first step)",
                    i + 1,
                    child.pid()
                );
                children[FIRST_AGENT + i] = child;
                Ok(())
            }
            Action::Kill(i) | Action::Stop(i) => {
                let stop = matches!(a, Action::Stop(_));
                let c = &mut children[FIRST_AGENT + i];
                if stop {
                    c.signal(libc::SIGSTOP);
                } else {
                    c.kill_and_reap();
                    node.try_cleanup_dead_nodes();
                }
                tracing::info!(
                    agent = i + 1,
                    recorded,
                    stop,
                    "timeline: agent process {}",
                    if stop { "stopped" } else { "killed" }
                );
                self.incidents.push(Incident {
                    kind: if stop { "hang" } else { "crash" },
                    host: None,
                    agent: i,
                    down_from: None,
                    rejoin_at: None,
                    detected_after_ms: None,
                    restarted_after_ms: None,
                    started: Instant::now(),
                });
                Ok(())
            }
            Action::Respawn(plan) => {
                let wait = self.supervisor.backoff(plan.agent);
                if wait.is_zero() {
                    return self.respawn(plan, node, children);
                }
                eprintln!(
                    "formation run: agent {} starts again in {} ms (backoff after its successor failed to start)",
                    plan.agent + 1,
                    wait.as_millis()
                );
                self.pending.push((Instant::now() + wait, plan));
                Ok(())
            }
            Action::Joined { agent, step } => {
                if let Some(inc) = self.incidents.iter_mut().rev().find(|x| x.agent == agent) {
                    inc.restarted_after_ms = Some(inc.started.elapsed().as_secs_f64() * 1e3);
                }
                tracing::info!(agent = agent + 1, step, "new agent process joined");
                if self.realtime {
                    // The realtime plant does not wait for it: it uses its commands as they come.
                    self.realtime_windows.push(RuntimeEvent {
                        step: recorded,
                        kind: EVENT_UP_AGAIN,
                        agent: agent as u32,
                        other: EVENT_ANY,
                        ..RuntimeEvent::default()
                    });
                    return Ok(());
                }
                send(
                    &self.events_out,
                    RuntimeEvent {
                        step,
                        kind: EVENT_JOINED,
                        agent: agent as u32,
                        other: EVENT_ANY,
                        ..RuntimeEvent::default()
                    },
                )?;
                poke(&self.plant_wake);
                Ok(())
            }
            Action::TakeDown(i) => {
                send(
                    &self.events_out,
                    RuntimeEvent {
                        step: u64::MAX,
                        kind: EVENT_DOWN_REQUEST,
                        agent: i as u32,
                        other: EVENT_ANY,
                        ..RuntimeEvent::default()
                    },
                )?;
                poke(&self.plant_wake);
                // Whatever is left of it is gone before its successor opens its ports.
                children[FIRST_AGENT + i].kill_and_reap();
                node.try_cleanup_dead_nodes();
                Ok(())
            }
            Action::Announce(e) => self.publish(e),
            Action::Fail(m) => Err(m),
        }
    }

    // String: the supervision stops a run with the line it prints (`Outcome::Died`, `Failed`).
    fn respawn(
        &mut self,
        plan: Plan,
        node: &RunNode,
        children: &mut [RoleProcess],
    ) -> Result<(), String> {
        let i = plan.agent;
        // A stopped process (a hang) is replaced like a dead one.
        children[FIRST_AGENT + i].kill_and_reap();
        node.try_cleanup_dead_nodes();
        let run_dir = self.args.run_dir.clone();
        let mut checkpoint = None;
        let remote = self.remote.clone().filter(|r| r.is_remote(i));
        if let (true, Some(r)) = (plan.warm, &remote) {
            if let Err(e) = r.fetch_checkpoint(i, &run_dir) {
                eprintln!("warning: agent {}: cannot fetch its checkpoint: {e}", i + 1);
            }
        }
        if let (true, Some(r)) = (plan.warm, &self.remote) {
            // An agent moved off a lost host: the copy its daemon forwarded.
            match r.restore_checkpoint(i, &run_dir, plan.down_from, self.history.oldest()) {
                Ok(Some(step)) => tracing::info!(
                    agent = i + 1,
                    step,
                    "checkpoint forwarded from its lost host restored"
                ),
                Ok(None) => {}
                Err(e) => eprintln!(
                    "warning: agent {}: cannot restore its forwarded checkpoint: {e}",
                    i + 1
                ),
            }
        }
        if plan.warm {
            let path = restart::checkpoint_path(&run_dir, i);
            match restart::read_checkpoint(&path, i, self.scenario_hash) {
                Ok(c) if c.step < plan.down_from && c.step >= self.history.oldest() => {
                    checkpoint = Some(c.step)
                }
                Ok(c) => eprintln!(
                    "warning: agent {}: checkpoint of step {} is outside the recorded window; restarting cold",
                    i + 1,
                    c.step
                ),
                Err(e) if path.exists() => {
                    // Refused (not this agent's, not this run's, damaged): cold at once, counted.
                    self.checkpoints_refused[i] += 1;
                    eprintln!("warning: agent {}: {e}; restarting cold", i + 1);
                }
                Err(e) => eprintln!("warning: agent {}: no checkpoint ({e}); restarting cold", i + 1),
            }
        }
        let window = formation_agent::restart::Rejoin {
            checkpoint,
            down_from: plan.down_from,
            rejoin_at: plan.rejoin_at,
            recorded_from: self.history.oldest(),
        };
        // The down window's states too: the re-seed observes the fallback over all of it.
        let first = window
            .first_needed(self.capacity as u64)
            .min(plan.down_from)
            .max(self.history.oldest());
        let file = RejoinFile {
            agent: i,
            checkpoint,
            down_from: plan.down_from,
            rejoin_at: plan.rejoin_at,
            first,
            n: self.n,
            states: (first..plan.rejoin_at)
                .flat_map(|k| (0..self.n).map(move |j| (k, j)))
                .map(|(k, j)| self.history.state(k, j))
                .collect(),
            commands: (first..plan.down_from.max(first))
                .map(|k| self.history.command(k, i))
                .collect(),
            events: self.published.clone(),
            flown: (plan.down_from..plan.rejoin_at)
                .map(|k| self.history.command(k, i))
                .collect(),
        };
        let path = restart::rejoin_path(&run_dir, i);
        restart::write_rejoin(&path, self.scenario_hash, &file)
            .map_err(|e| format!("cannot write {}: {e}", path.display()))?;
        let args = ChildArgs {
            agent: Some(i),
            rejoin_at: Some(plan.rejoin_at),
            ..self.args.clone()
        };
        let label = format!("agent {} (--agent {i})", i + 1);
        let child = match &remote {
            Some(r) => r.spawn(i, label, &args)?,
            None => self.pins.spawn(super::governor::Place::Agent(i), |cpu| {
                spawn::spawn(&self.exe, Role::Agent, label, &args, cpu)
            })?,
        };
        eprintln!(
            "formation run: agent {} taken over at step {} (t = {:.3} s) by pid {} ({}, down from step {})",
            i + 1,
            plan.rejoin_at,
            plan.rejoin_at as f64 * self.args_dt(),
            child.pid(),
            if checkpoint.is_some() { "warm" } else { "cold" },
            plan.down_from
        );
        if let Some(inc) = self.incidents.iter_mut().rev().find(|x| x.agent == i) {
            inc.down_from = Some(plan.down_from);
            inc.rejoin_at = Some(plan.rejoin_at);
        }
        children[FIRST_AGENT + i] = child;
        Ok(())
    }

    fn args_dt(&self) -> f64 {
        self.supervisor.timeline().dt()
    }
}

/// The runtime events a summary is built from: the timeline events (crashes, hangs, links,
/// losses), the plant's take-downs (`EVENT_DOWN`) and the rejoins that end them
/// (`EVENT_UP_AGAIN`; without them a restarted agent would count as down to the end of the run),
/// and a realtime run's `windows` of the same two kinds.
pub fn for_summary(
    published: &[RuntimeEvent],
    windows: &[RuntimeEvent],
    dt: f64,
) -> Vec<RuntimeEvent> {
    published
        .iter()
        .chain(windows)
        .filter(|e| e.to_event(dt).is_some() || e.kind == EVENT_DOWN || e.kind == EVENT_UP_AGAIN)
        .copied()
        .collect()
}

/// The runtime policy's stall timeout (None: disabled).
pub fn stall_timeout(rt: &Runtime) -> Option<Duration> {
    (rt.stall_timeout_ms > 0).then(|| Duration::from_millis(rt.stall_timeout_ms))
}

/// How much longer than the Zenoh lease a multi-host run waits before it calls a stall a stall:
/// a host whose link went silent stalls a lockstep run until the lease declares it lost, and
/// must be named (and handled under the policy) as lost, not stop the run as a stall.
pub const STALL_BEYOND_LEASE: Duration = Duration::from_millis(1000);

/// The stall timeout of a run whose silent hosts are declared lost after `lease` (`None`: one
/// machine): at least the lease plus [`STALL_BEYOND_LEASE`].
pub fn stall_timeout_with(rt: &Runtime, lease: Option<Duration>) -> Option<Duration> {
    let t = stall_timeout(rt)?;
    Some(lease.map_or(t, |l| t.max(l + STALL_BEYOND_LEASE)))
}

/// Start-ups of the run (from the launch of its processes to every hello, as measured) a takeover
/// may take before a run that is still is called stalled: a successor is one process where the
/// launch started all of them, but it also rebuilds from the recorded steps; on a machine that
/// starts processes slowly (load, a slow disk) both are slow alike.
pub const TAKEOVER_STARTUPS: u32 = 4;

/// The stall limit: `base` ([`stall_timeout_with`]), or while a takeover is under way at least
/// [`TAKEOVER_STARTUPS`] times the run's measured start-up (`None`: not measured yet).
pub fn stall_limit(base: Duration, taking_over: bool, startup: Option<Duration>) -> Duration {
    match (taking_over, startup) {
        (true, Some(s)) => base.max(s * TAKEOVER_STARTUPS),
        _ => base,
    }
}

/// `4, 5` for agents 3 and 4 (0-based).
fn ids(agents: &[usize]) -> String {
    agents
        .iter()
        .map(|a| (a + 1).to_string())
        .collect::<Vec<_>>()
        .join(", ")
}

impl Takeover {
    /// The stall timeout of this run ([`stall_timeout_with`] its hosts' lease).
    pub fn stall_timeout(&self, rt: &Runtime) -> Option<Duration> {
        stall_timeout_with(rt, self.remote.as_ref().map(|r| r.lease()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use formation_config::scenario::events::Timeline;

    fn ev(kind: u32, agent: u32, step: u64) -> RuntimeEvent {
        RuntimeEvent {
            step,
            kind,
            agent,
            other: EVENT_ANY,
            ..RuntimeEvent::default()
        }
    }

    #[test]
    fn a_multi_host_run_calls_a_stall_only_after_a_silent_host_would_be_declared_lost() {
        let rt = Runtime {
            stall_timeout_ms: 2000,
            ..Runtime::default()
        };
        let ms = Duration::from_millis;
        assert_eq!(stall_timeout_with(&rt, None), Some(ms(2000)));
        assert_eq!(stall_timeout_with(&rt, Some(ms(3000))), Some(ms(4000)));
        assert_eq!(stall_timeout_with(&rt, Some(ms(500))), Some(ms(2000)));
        let off = Runtime {
            stall_timeout_ms: 0,
            ..Runtime::default()
        };
        assert_eq!(
            stall_timeout_with(&off, Some(ms(3000))),
            None,
            "disabled stays off"
        );
    }

    #[test]
    fn a_takeover_may_take_a_multiple_of_the_measured_start_up_before_a_stall_is_called() {
        let ms = Duration::from_millis;
        assert_eq!(stall_limit(ms(4000), false, Some(ms(3000))), ms(4000));
        assert_eq!(stall_limit(ms(4000), true, None), ms(4000), "floor");
        assert_eq!(
            stall_limit(ms(4000), true, Some(ms(200))),
            ms(4000),
            "floor"
        );
        assert_eq!(
            stall_limit(ms(4000), true, Some(ms(3000))),
            ms(3000) * TAKEOVER_STARTUPS,
            "a slow machine"
        );
        assert_eq!(ids(&[3, 4]), "4, 5");
    }

    #[test]
    fn a_restarted_agent_is_down_only_until_its_new_process_takes_over_in_the_summary() {
        let dt = 0.001;
        // Lockstep: the plant's take-down, then the announced rejoin; a JOINED is not a window.
        let lockstep = [
            ev(EVENT_DOWN, 2, 1000),
            ev(EVENT_UP_AGAIN, 2, 1500),
            ev(EVENT_JOINED, 2, 1500),
        ];
        // Realtime: nothing is published; the death and the join are the window.
        let realtime = [ev(EVENT_DOWN, 1, 3000), ev(EVENT_UP_AGAIN, 1, 3200)];
        let mut t = Timeline::new(&[], dt);
        for e in for_summary(&lockstep, &realtime, dt) {
            e.apply(&mut t);
        }
        assert!(t.up(2, 999) && !t.up(2, 1000) && !t.up(2, 1499) && t.up(2, 1500));
        assert!(t.up(2, 100_000), "up again to the end of the run");
        assert!(t.up(1, 2999) && !t.up(1, 3000) && t.up(1, 3200));
    }
}
