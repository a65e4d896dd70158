//! Agent i on the wall clock (`formation run --realtime`): it reacts to every fresh state at once
//! and never waits for its delayed inputs. At step k it uses, through the step-keyed histories, the
//! newest information stamped at or before t_k - tau_i(t_k) that has actually arrived
//! ([`crate::delay::StepHistory::at_or_before`]), so the injected delay adds to the real
//! IPC latency. Step 0 is the warm-up: the agent waits for everything step 0 needs, as in lockstep.
//!
//! If several states are queued (the agent fell behind), all enter the history and only the newest
//! is answered. Measures, per process: state hop (plant send stamp -> received), share hop
//! (neighbour send stamp -> received), the compute time of `Agent::step`, and the injected and
//! effective delay of every step (`Agent::applied_delay_steps`); written at the stop
//! to `<run dir>/timing/agent-<i>.json`. Live telemetry for `formation inspect` goes out on the
//! same service and with the same sim-time period as in lockstep ([`super::telemetry`]).
//! It checkpoints as in lockstep (`super::rejoin::Checkpoints`), so that under `--restart
//! on-failure` a process replacing a dead one restores the newest checkpoint, replays the recorded
//! steps up to the one the orchestrator had recorded at the death, and then answers the newest
//! states it gets (it cannot replay the steps it missed on the wall clock). The leader's frames
//! of the steps before its first wake-up went out before it subscribed: it computes those from
//! the mission itself (`local_mission`, what the leader computes) until the leader's stream
//! reaches its step, so a successor started during the warm-up of step 0 is ready for step 0.

use super::ports::Ports;
use super::rejoin::Checkpoints;
use super::telemetry::Sampler;
use crate::Agent;
use formation_config::node::boot::Boot;
use formation_config::node::clock::now_ns;
use formation_config::node::error::NodeError;
use formation_config::node::ports::{poke, send};
use formation_config::node::timing::{NsHistogram, TimingReport};
use formation_config::protocol::messages::CONTROL_STOP;
use formation_config::protocol::pacing::CHILD_WAIT;
use formation_config::protocol::wire::{DelayInjection, ReferenceFrame, VehicleState};
use std::collections::VecDeque;

/// What the agent measures.
#[derive(Default)]
struct Meters {
    state_hop: NsHistogram,
    share_hop: NsHistogram,
    compute: NsHistogram,
    /// tau_i(t_k) on the step grid, ns.
    injected: NsHistogram,
    /// Age of the oldest information the control used (`Agent::applied_delay_steps`), ns.
    effective: NsHistogram,
    /// Steps whose effective delay exceeded tau_M.
    over_tau_m: u64,
    skipped: u64,
}

/// Runs agent i in realtime mode until the orchestrator says stop (or goes away).
pub fn run(
    b: &Boot,
    i: usize,
    agent: Agent,
    ports: &Ports,
    checkpoints: &mut Checkpoints,
    local_mission: Option<formation_leader::Mission>,
) -> Result<(), NodeError> {
    if let Some(w) = formation_config::node::sched::realtime_setup(b.args.rt_priority) {
        eprintln!("warning: {w}");
    }
    // Checkpoints off the control thread, below its priority (written synchronously if the
    // thread cannot start).
    if let Err(e) = checkpoints.write_in_background() {
        eprintln!(
            "warning: agent {}: checkpoints written on the control thread: {e}",
            i + 1
        );
    }
    let dt_ns = (b.scenario.simulation.dt_s * 1e9).round() as u64;
    let tau_m_ns = (b.scenario.simulation.max_delay_s * 1e9).round() as u64;
    let mut node = Realtime {
        b,
        i,
        agent,
        ports,
        checkpoints,
        local_mission,
        m: Meters::default(),
        refs: VecDeque::with_capacity(128),
        pending_delays: Vec::new(),
        latest: None,
        referenced: None,
        local_reference: ReferenceFrame::default(),
        answered: None,
        sampler: Sampler::new(&b.scenario, i),
        dt_ns,
        tau_m_ns,
        re_entry: LiveReEntry::new(tau_m_ns.div_ceil(dt_ns.max(1)) + 1),
    };
    loop {
        if node.receive_inputs()? {
            return report(b, i, &node.m);
        }
        node.receive_states()?;
        if let Some(s) = node.latest {
            node.on_state(&s)?;
        }
        if let Some(why) = b.lifeline.must_stop() {
            return Err(NodeError::Stopped(format!(
                "agent {} stopping: {why}",
                i + 1
            )));
        }
        ports.wake.wait(CHILD_WAIT)?;
    }
}

/// Agent i on the wall clock: the controller and what its loop holds between wake-ups.
struct Realtime<'a> {
    b: &'a Boot,
    /// Agent index i (0-based).
    i: usize,
    agent: Agent,
    ports: &'a Ports,
    checkpoints: &'a mut Checkpoints,
    /// A successor computes the references the leader sent before it subscribed from the mission.
    local_mission: Option<formation_leader::Mission>,
    m: Meters,
    /// References received and not yet observed.
    refs: VecDeque<ReferenceFrame>,
    /// Delay injections not yet at their step.
    pending_delays: Vec<DelayInjection>,
    /// The newest state not answered yet.
    latest: Option<VehicleState>,
    /// A successor: the newest step whose reference it observed (from the mission or the leader).
    referenced: Option<u64>,
    /// The reference frame computed from `local_mission`.
    local_reference: ReferenceFrame,
    /// The newest step whose command went out.
    answered: Option<u64>,
    sampler: Sampler,
    /// The step dt, ns.
    dt_ns: u64,
    /// tau_M, ns.
    tau_m_ns: u64,
    /// A successor's live re-entry: the first step it got live, and the steps it listens before it
    /// answers (tau_M and one step: every delayed input it then reads was received live).
    re_entry: LiveReEntry,
}

impl Realtime<'_> {
    /// Reads stop, delay injections, references and the neighbours' shares; true on stop.
    fn receive_inputs(&mut self) -> Result<bool, NodeError> {
        let ports = self.ports;
        while let Some(c) = ports.control.receive()? {
            if c.kind == CONTROL_STOP {
                return Ok(true);
            }
        }
        while let Some(d) = ports.delays.receive()? {
            self.pending_delays.push(*d);
        }
        while let Some(r) = ports.reference.receive()? {
            self.refs.push_back(*r);
        }
        for sub in &ports.shares_in {
            while let Some(s) = sub.receive()? {
                if s.sent_ns != 0 {
                    self.m.share_hop.record(now_ns().saturating_sub(s.sent_ns));
                }
                self.agent.observe_neighbour(&s);
            }
        }
        Ok(false)
    }

    /// Reads every queued state: each enters the history and has its share sent, the newest is
    /// kept in `latest` to be answered.
    fn receive_states(&mut self) -> Result<(), NodeError> {
        let ports = self.ports;
        while let Some(s) = ports.state.receive()? {
            if self.answered.is_some_and(|a| s.step <= a) {
                // The warm-up's states of step 0 again (`WARMUP_RESEND` in the plant): answered
                // already; its share goes out again for a neighbour that started after it went.
                if s.step == 0 {
                    let mut share = crate::agent::share_of(&s);
                    share.sent_ns = now_ns();
                    send(&ports.share_out, share)?;
                    ports.neighbours_wake.iter().for_each(poke);
                }
                continue;
            }
            if s.sent_ns != 0 {
                self.m.state_hop.record(now_ns().saturating_sub(s.sent_ns));
            }
            if self.latest.replace(*s).is_some_and(|l| l.step != s.step) {
                // A newer state replaces one not answered yet: only the newest is answered.
                self.m.skipped += 1;
            }
            if !self.agent.has_own(s.step) || s.step == 0 {
                let mut share = if self.agent.has_own(s.step) {
                    crate::agent::share_of(&s)
                } else {
                    self.agent.observe_own(&s)
                };
                share.sent_ns = now_ns();
                send(&ports.share_out, share)?;
                if s.step == 0 {
                    // Warm-up: the neighbours wait for the shares of step 0.
                    ports.neighbours_wake.iter().for_each(poke);
                }
            }
        }
        Ok(())
    }

    /// Brings the references and delay injections up to the step of the newest state `s`, then
    /// answers it, or listens (a successor's live re-entry).
    fn on_state(&mut self, s: &VehicleState) -> Result<(), NodeError> {
        let k = s.step;
        self.take_references(k);
        let agent = &mut self.agent;
        self.pending_delays.retain(|d| {
            if d.step <= k {
                agent.set_delay(d);
                false
            } else {
                true
            }
        });
        let listening = self.local_mission.is_some()
            && k > 0
            && match self.re_entry.at(k) {
                ReEntry::Listen => true,
                ReEntry::Meet => {
                    self.agent.set_up_again(self.i, k);
                    self.agent.resync(s);
                    false
                }
                ReEntry::Answer => false,
            };
        if listening {
            self.latest = None;
        } else if k > 0 || self.agent.ready(0) {
            self.answer(s)?;
            self.latest = None;
        }
        Ok(())
    }

    /// Observes the references up to step k: the leader's received, and a successor's from the
    /// mission for a step whose frame the leader sent before this process subscribed.
    fn take_references(&mut self, k: u64) {
        while self.refs.front().is_some_and(|r| r.step <= k) {
            match self.refs.pop_front() {
                // Computed from the mission already (a successor).
                Some(r) if self.referenced.is_some_and(|s| r.step <= s) => {}
                Some(r) => {
                    self.referenced = Some(r.step);
                    self.agent.observe_reference(&r);
                    self.sampler.observe_reference(&r);
                }
                None => {}
            }
        }
        let referenced = self.referenced;
        if let Some(m) = self
            .local_mission
            .as_ref()
            .filter(|_| referenced.is_none_or(|r| r < k))
        {
            // The leader's frame of k went out before this process subscribed.
            m.reference(
                k,
                k as f64 * self.b.scenario.simulation.dt_s,
                &mut self.local_reference,
            );
            self.referenced = Some(k);
            self.agent.observe_reference(&self.local_reference);
            self.sampler.observe_reference(&self.local_reference);
        }
    }

    /// Computes, measures and sends the command of the state `s`, and a telemetry sample when one
    /// is due.
    fn answer(&mut self, s: &VehicleState) -> Result<(), NodeError> {
        let k = s.step;
        let (dt_ns, m) = (self.dt_ns, &mut self.m);
        // Outside the timed control: a warm restart restores the newest checkpoint. Taken here,
        // written once the command is out.
        self.checkpoints.take(&self.agent, k);
        let t0 = now_ns();
        let mut cmd = self.agent.step(s);
        let t1 = now_ns();
        m.compute.record(t1 - t0);
        let (injected, effective) = self.agent.applied_delay_steps(k);
        m.injected.record(injected * dt_ns);
        m.effective.record(effective * dt_ns);
        m.over_tau_m += u64::from(effective * dt_ns > self.tau_m_ns);
        cmd.sent_ns = t1;
        send(&self.ports.command, cmd)?;
        self.answered = Some(k);
        poke(&self.ports.plant_wake);
        self.sampler.observe_command(&cmd);
        if self.sampler.due_once(k) {
            let latency = std::time::Duration::from_nanos(t1 - t0);
            // Best effort: a failed telemetry send never disturbs control.
            let _ = send(&self.ports.telemetry, self.sampler.sample(s, &cmd, latency));
        }
        self.checkpoints.write_taken();
        Ok(())
    }
}

/// What a successor does with a live step ([`LiveReEntry::at`]).
#[derive(Debug, PartialEq, Eq)]
enum ReEntry {
    /// Stay silent: the plant flies the failsafe, the histories fill with live inputs.
    Listen,
    /// The first answer: the filters meet the vehicle where the failsafe left it.
    Meet,
    /// Control as usual.
    Answer,
}

/// A successor rebuilt up to the step its predecessor was last recorded at answers the newest
/// states, up to seconds later on the wall clock: its histories hold nothing between. For the
/// first tau_M of live steps its delayed inputs would be the rebuilt, stale ones (measured: after
/// a realtime SIGSTOP of 1.2 s a first command of -2 m/s² for a true error of 1 cm), so it listens
/// `listen` steps (tau_M and one step) from its first live step before it answers. Its own down
/// window (opened at the rebuild) ends at its first answer, where its reference generator re-arms
/// from the vehicle's state (`runtime.rejoin_reference`) and its filters meet the vehicle.
struct LiveReEntry {
    listen: u64,
    first: Option<u64>,
    met: bool,
}

impl LiveReEntry {
    fn new(listen: u64) -> LiveReEntry {
        LiveReEntry {
            listen,
            first: None,
            met: false,
        }
    }

    /// What to do with live step k.
    fn at(&mut self, k: u64) -> ReEntry {
        let first = *self.first.get_or_insert(k);
        if k - first < self.listen {
            ReEntry::Listen
        } else if !std::mem::replace(&mut self.met, true) {
            ReEntry::Meet
        } else {
            ReEntry::Answer
        }
    }
}

/// Writes `<run dir>/timing/agent-<i>.json`.
fn report(b: &Boot, i: usize, m: &Meters) -> Result<(), NodeError> {
    let mut r = TimingReport::default();
    r.histograms.insert("state_hop".into(), m.state_hop.clone());
    r.histograms.insert("share_hop".into(), m.share_hop.clone());
    r.histograms
        .insert("controller_step".into(), m.compute.clone());
    r.histograms
        .insert("injected_delay".into(), m.injected.clone());
    r.histograms
        .insert("effective_delay".into(), m.effective.clone());
    r.counters
        .insert("effective_over_tau_m".into(), m.over_tau_m);
    r.counters.insert("skipped_states".into(), m.skipped);
    r.write(&b.args.run_dir, &format!("agent-{}", i + 1))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A successor listens `listen` steps from its first live step, meets the vehicle at the next
    /// one it gets (also when states were skipped), then answers.
    #[test]
    fn a_successor_listens_tau_m_then_meets_the_vehicle_once() {
        let mut r = LiveReEntry::new(51);
        assert_eq!(r.at(6340), ReEntry::Listen);
        assert_eq!(r.at(6390), ReEntry::Listen);
        assert_eq!(r.at(6395), ReEntry::Meet);
        assert_eq!(r.at(6396), ReEntry::Answer);
    }
}
