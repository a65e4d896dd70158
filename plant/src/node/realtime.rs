//! The plant on the wall clock (`formation run --realtime`).
//!
//! Step 0 is a warm-up: its state goes out at once and the plant waits (without a deadline) for
//! every step-0 command, so that every agent's histories are seeded. From then on step k is
//! scheduled at S_k = S_1 + (k - 1) dt on CLOCK_MONOTONIC:
//! 1. sleep until S_k (absolute), record the jitter (wake-up minus S_k), publish the N states of
//!    step k stamped with the send time, wake the agents;
//! 2. collect the commands of step k until all N are in or the deadline S_{k+1} passes;
//! 3. apply them, integrate [t_k, t_{k+1}] and publish the step record. An agent whose command did
//!    not arrive in time is flown on its fallback (`super::deadline`): its last command held for
//!    `runtime.hold_s` (zero-order hold), then the failsafe of `crate::fallback`, until its
//!    commands come in again; such a step counts as one deadline miss. A command for a step already
//!    integrated is counted as late; the newest late one of an agent is applied at the next step
//!    that has no command of its own from it (`late_applied`), in place of the held command.
//!
//! The plant never waits for the recorder here: the step records buffer is sized for a second of
//! steps instead.

use super::deadline::{Arrival, Decision, Silence};
use super::ports::Ports;
use crate::Plant;
use formation_config::node::boot::Boot;
use formation_config::node::clock::{now_ns, sleep_until_ns};
use formation_config::node::error::NodeError;
use formation_config::node::ports::{poke, send};
use formation_config::node::timing::{NsHistogram, TimingReport};
use formation_config::protocol::messages::{StepEntry, CONTROL_STOP};
use formation_config::protocol::pacing::{ACK_EVERY, CHILD_WAIT};
use formation_config::protocol::wire::{ControlCommand, FaultInjection};
use std::time::Duration;

/// How often the states of step 0 go out again while the warm-up waits for a command (a lost
/// agent's successor needs them): a tenth of a second, far above a warm-up's usual length (every
/// process answers within milliseconds once started), far below the stall timeout.
const WARMUP_RESEND: Duration = Duration::from_millis(100);

/// What the plant measures.
struct Meters {
    /// State of step k published -> command of step k received, per agent.
    latency: Vec<NsHistogram>,
    /// Command send stamp -> received by the plant.
    command_hop: NsHistogram,
    /// Actual start of step k minus S_k.
    jitter: NsHistogram,
    misses: u64,
    late: u64,
    late_applied: u64,
    timed_steps: u64,
}

/// The plant's state between steps.
struct Loop<'a> {
    b: &'a Boot,
    ports: &'a Ports,
    plant: Plant,
    n: usize,
    commands: Vec<Option<ControlCommand>>,
    /// Per agent, the newest command that came after its step's deadline and is not applied yet.
    late: Vec<Option<ControlCommand>>,
    silence: Silence,
    entries: Vec<StepEntry>,
    faults: Vec<FaultInjection>,
    k: u64,
    published_ns: u64,
    m: Meters,
}

/// Why the loop ended early.
enum Stop {
    Asked,
    Error(NodeError),
}

impl<E: Into<NodeError>> From<E> for Stop {
    fn from(e: E) -> Stop {
        Stop::Error(e.into())
    }
}

/// Runs the realtime plant until every step is done, then waits for the stop message.
pub fn run(b: &Boot, ports: &Ports, plant: Plant) -> Result<(), NodeError> {
    if let Some(w) = formation_config::node::sched::realtime_setup(b.args.rt_priority) {
        eprintln!("warning: {w}");
    }
    let n = b.scenario.n_agents();
    let mut l = Loop {
        b,
        ports,
        plant,
        n,
        commands: vec![None; n],
        late: vec![None; n],
        silence: Silence::new(n),
        entries: vec![StepEntry::default(); n],
        // The scenario's fault events go the way of the live injections, as in lockstep.
        faults: super::scenario_faults(&b.scenario),
        k: 0,
        published_ns: 0,
        m: Meters {
            latency: (0..n).map(|_| NsHistogram::new()).collect(),
            command_hop: NsHistogram::new(),
            jitter: NsHistogram::new(),
            misses: 0,
            late: 0,
            late_applied: 0,
            timed_steps: 0,
        },
    };
    let spin = Duration::from_micros(u64::from(b.args.spin_us));
    match l.run(spin) {
        Ok(()) => {}
        Err(Stop::Asked) => return l.report(),
        Err(Stop::Error(e)) => return Err(e),
    }
    l.report()?;
    loop {
        match l.drain() {
            Err(Stop::Asked) => return Ok(()),
            Err(Stop::Error(e)) => return Err(e),
            Ok(()) => {}
        }
        if let Some(why) = b.lifeline.must_stop() {
            return Err(NodeError::Stopped(format!(
                "stopping after the last step: {why}"
            )));
        }
        ports.wake.wait(CHILD_WAIT)?;
    }
}

impl Loop<'_> {
    fn run(&mut self, spin: Duration) -> Result<(), Stop> {
        let steps = self.b.scenario.n_steps();
        let dt_ns = (self.b.scenario.simulation.dt_s * 1e9).round().max(1.0) as u64;
        // Start signal: the first progress message.
        let mut started = false;
        while !started {
            started = self.drain_start()?;
            if !started {
                self.check()?;
                self.ports.wake.wait(CHILD_WAIT)?;
            }
        }
        if steps == 0 {
            return Ok(());
        }
        // Warm-up step 0: no deadline. While it lasts, the states of step 0 go out again every
        // WARMUP_RESEND: an agent process started after they went out (the successor of one lost
        // with its host at step 0) gets its own, and its neighbours answer with their shares of
        // step 0 again (an agent answers each step once).
        self.publish_states()?;
        let mut sent = std::time::Instant::now();
        while !self.all_in() {
            self.drain()?;
            if !self.all_in() {
                self.check()?;
                if sent.elapsed() >= WARMUP_RESEND {
                    self.publish_states()?;
                    sent = std::time::Instant::now();
                }
                self.ports.wake.wait(CHILD_WAIT)?;
            }
        }
        self.integrate()?;
        let s1 = now_ns() + dt_ns;
        while self.k < steps {
            let scheduled = s1 + (self.k - 1) * dt_ns;
            sleep_until_ns(scheduled);
            let woke = now_ns();
            self.m.jitter.record(woke.saturating_sub(scheduled));
            self.m.timed_steps += 1;
            self.publish_states()?;
            let deadline = scheduled + dt_ns;
            loop {
                self.drain()?;
                if self.all_in() {
                    break;
                }
                let now = now_ns();
                if now >= deadline {
                    self.m.misses += 1;
                    break;
                }
                self.ports
                    .wake
                    .spin_then_wait(spin, Duration::from_nanos(deadline - now))?;
            }
            self.integrate()?;
            if self.k.is_multiple_of(256) {
                self.check()?;
            }
        }
        Ok(())
    }

    fn check(&self) -> Result<(), Stop> {
        match self.b.lifeline.must_stop() {
            Some(why) => Err(Stop::Error(NodeError::Stopped(format!(
                "stopping at step {}: {why}",
                self.k
            )))),
            None => Ok(()),
        }
    }

    fn all_in(&self) -> bool {
        self.commands.iter().all(Option::is_some)
    }

    /// Drains control and progress; true once the start signal has come.
    fn drain_start(&mut self) -> Result<bool, Stop> {
        let p = self.ports;
        while let Some(c) = p.control.receive()? {
            if c.kind == CONTROL_STOP {
                return Err(Stop::Asked);
            }
        }
        let mut started = false;
        while p.progress.receive()?.is_some() {
            started = true;
        }
        Ok(started)
    }

    /// Drains every subscriber: stop, progress (ignored), faults, commands.
    fn drain(&mut self) -> Result<(), Stop> {
        self.drain_start()?;
        let p = self.ports;
        while let Some(f) = p.faults.receive()? {
            self.faults.push(*f);
        }
        for (i, sub) in p.commands.iter().enumerate() {
            while let Some(c) = sub.receive()? {
                let now = now_ns();
                if c.agent as usize != i || c.step > self.k {
                    return Err(Stop::Error(NodeError::Protocol(format!(
                        "protocol error: command of agent {} for step {} while at step {}",
                        c.agent, c.step, self.k
                    ))));
                }
                if c.step < self.k || self.commands[i].is_some() {
                    self.m.late += 1;
                    if c.step < self.k && self.late[i].is_none_or(|l| l.step < c.step) {
                        self.late[i] = Some(*c);
                    }
                    continue;
                }
                if c.sent_ns != 0 {
                    self.m.command_hop.record(now.saturating_sub(c.sent_ns));
                }
                if self.k > 0 {
                    self.m.latency[i].record(now.saturating_sub(self.published_ns));
                }
                self.commands[i] = Some(*c);
            }
        }
        Ok(())
    }

    fn publish_states(&mut self) -> Result<(), Stop> {
        let now = now_ns();
        for i in 0..self.n {
            let mut s = self.plant.vehicle_state(i);
            s.sent_ns = now;
            send(&self.ports.states[i], s)?;
        }
        self.published_ns = now;
        self.ports.agents_wake.iter().for_each(poke);
        Ok(())
    }

    /// Applies the commands of step k (the fallback where none came), integrates, and publishes the
    /// step record.
    fn integrate(&mut self) -> Result<(), Stop> {
        let k = self.k;
        let plant = &mut self.plant;
        self.faults.retain(|f| {
            if f.step <= k {
                plant.inject_fault(f);
                false
            } else {
                true
            }
        });
        for i in 0..self.n {
            let on_time = self.commands[i].take();
            let late = self.late[i].take();
            let arrival = match (&on_time, &late) {
                (Some(_), _) => Arrival::OnTime,
                (None, Some(_)) => Arrival::Late,
                (None, None) => Arrival::Nothing,
            };
            let cmd = match (self.silence.decide(i, arrival), on_time.or(late)) {
                (Decision::Command | Decision::Late, Some(mut c)) => {
                    if arrival == Arrival::Late {
                        self.m.late_applied += 1;
                    }
                    c.step = k;
                    self.plant.apply(i, &c);
                    c
                }
                (Decision::Fallback { since_steps }, _) => {
                    self.plant
                        .apply_fallback(i, since_steps, &self.b.scenario.runtime)
                }
                (Decision::Command | Decision::Late, None) => {
                    unreachable!("a command decision has its command")
                }
            };
            self.entries[i] = StepEntry {
                truth: self.plant.truth(i),
                command: cmd,
            };
        }
        self.ports.publish_step(&self.entries)?;
        self.plant.advance();
        self.k += 1;
        if self.k.is_multiple_of(ACK_EVERY) || self.k == self.b.scenario.n_steps() {
            poke(&self.ports.orchestrator_wake);
        }
        Ok(())
    }

    /// Writes `<run dir>/timing/plant.json`.
    fn report(&self) -> Result<(), NodeError> {
        let mut r = TimingReport::default();
        for (i, h) in self.m.latency.iter().enumerate() {
            r.histograms
                .insert(format!("state_to_command/{i}"), h.clone());
        }
        r.histograms
            .insert("command_hop".into(), self.m.command_hop.clone());
        r.histograms.insert("jitter".into(), self.m.jitter.clone());
        r.counters.insert("deadline_misses".into(), self.m.misses);
        r.counters.insert("late_commands".into(), self.m.late);
        r.counters
            .insert("late_commands_applied".into(), self.m.late_applied);
        r.counters.insert("timed_steps".into(), self.m.timed_steps);
        r.write(&self.b.args.run_dir, "plant")
    }
}
