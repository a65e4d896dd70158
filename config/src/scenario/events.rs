//! The fault timeline of a scenario (`[[events]]`) and the runtime policy (`[runtime]`), and the
//! [`Timeline`] every process derives from them: who is up at step k, which messages are delivered.
//!
//! An event happens at a *step* (`round(at_s / dt)`), never at a wall-clock moment, so `formation
//! sim` and a lockstep `formation run` apply it at the same point of the same step: a crash is a
//! step, not a moment. Every question a process asks of the timeline is a pure function of the
//! events and the step; none allocates.
//!
//! Semantics (the failure model, `docs/failures.md`):
//! * `crash` of agent i at step c for `down_s`: agent i computes nothing in [c, c + d) (d =
//!   round(down_s / dt)), its process is killed, and a new one takes over at step c + d, restored
//!   from its last checkpoint (`restart_state = "warm"`) or from scratch (`"cold"`).
//! * `hang` of agent i: the same window, but the process keeps its state (it is stopped, not killed)
//!   and resumes with the information it missed.
//! * While agent i is down the plant flies quadrotor i on its fallback, and agent i's shares are not
//!   delivered.
//! * `link_down` / `link_up` of `agents = [i, j]`: no share crosses the edge in either direction
//!   from the `link_down` step until the next `link_up` of the same pair.
//! * `message_loss`: each share `from` -> `to` of a step in [at, at + duration) is lost with
//!   `probability`, decided by a hash of (seed, from, to, step): the same messages are lost in every
//!   run of the same timeline.
//! * `fault` and `delay`: an actuator fault (constant Gamma, delta) or a delay profile from that
//!   step on, as `formation inject` does on a live run.

use serde::{Deserialize, Serialize};

/// What happens ([`Event::kind`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum EventKind {
    /// Actuator fault of `agent`: constant `gamma`, `delta` from this step on.
    Fault,
    /// Delay profile of `agent` from this step on (`base_s`, `amplitude_s`, `angular_rate_rad_s`).
    Delay,
    /// The process of `agent` dies; a new one takes over after `down_s`.
    Crash,
    /// The process of `agent` stops for `down_s`, then resumes.
    Hang,
    /// The edge `agents = [i, j]` carries nothing from here on.
    LinkDown,
    /// The edge `agents = [i, j]` carries shares again.
    LinkUp,
    /// Shares `from` -> `to` (every edge if both are omitted) are lost with `probability`.
    MessageLoss,
}

impl EventKind {
    /// Its name in TOML, JSON and on the command line.
    pub const fn name(self) -> &'static str {
        match self {
            EventKind::Fault => "fault",
            EventKind::Delay => "delay",
            EventKind::Crash => "crash",
            EventKind::Hang => "hang",
            EventKind::LinkDown => "link_down",
            EventKind::LinkUp => "link_up",
            EventKind::MessageLoss => "message_loss",
        }
    }

    /// Whether the event takes an agent down for a while (crash or hang).
    pub const fn takes_agent_down(self) -> bool {
        matches!(self, EventKind::Crash | EventKind::Hang)
    }
}

/// One event of the fault timeline: `[[events]]` in a scenario, a line of `events.jsonl`. Agent ids
/// are 1-based, as everywhere a user writes them. Which fields a kind needs is checked by
/// validation (`events[k].<field>` is named when one is missing or out of range).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Event {
    /// Sim time of the event, s; it applies at step round(at_s / dt).
    pub at_s: f64,
    /// What happens.
    pub kind: EventKind,
    /// The agent (1-based): fault, delay, crash, hang.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub agent: Option<usize>,
    /// The edge (1-based ids): link_down, link_up.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub agents: Option<[usize; 2]>,
    /// How long the agent is down, s: crash, hang.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub down_s: Option<f64>,
    /// Fault: Gamma_i (diagonal), in (0, 1].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gamma: Option<[f64; 3]>,
    /// Fault: delta_i, N m.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub delta: Option<[f64; 3]>,
    /// Delay: tau_i(t) = base + amplitude sin(rate t), s.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub base_s: Option<f64>,
    /// Delay amplitude, s (default 0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub amplitude_s: Option<f64>,
    /// Delay angular rate, rad/s (default 0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub angular_rate_rad_s: Option<f64>,
    /// Message loss: sender (1-based); omitted with `to`: every edge.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub from: Option<usize>,
    /// Message loss: receiver (1-based).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub to: Option<usize>,
    /// Message loss: probability that one share is lost, in [0, 1].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub probability: Option<f64>,
    /// Message loss: seed of the loss pattern (default 0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub seed: Option<u64>,
    /// Message loss: how long it lasts, s (default: to the end of the run).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub duration_s: Option<f64>,
}

impl Event {
    /// An event of `kind` at `at_s` with every optional field empty.
    pub fn new(at_s: f64, kind: EventKind) -> Event {
        Event {
            at_s,
            kind,
            agent: None,
            agents: None,
            down_s: None,
            gamma: None,
            delta: None,
            base_s: None,
            amplitude_s: None,
            angular_rate_rad_s: None,
            from: None,
            to: None,
            probability: None,
            seed: None,
            duration_s: None,
        }
    }

    /// The step it applies at for a step `dt`.
    pub fn step(&self, dt: f64) -> u64 {
        (self.at_s / dt).round().max(0.0) as u64
    }
}

/// What the orchestrator does when an agent process dies or hangs outside the timeline.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum RestartPolicy {
    /// Stop the run (exit 1), naming the process.
    #[default]
    Never,
    /// Start a new agent process (at most `max_restarts` per agent); plant and leader are never
    /// restarted.
    OnFailure,
}

/// What a restarted agent starts from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum RestartState {
    /// Its last checkpoint, replayed up to the step it went down (learned weights, estimates,
    /// filters and histories as the dead process had them).
    #[default]
    Warm,
    /// A fresh controller (initial weights and estimates); only its delay histories are refilled.
    Cold,
}

/// What the plant's onboard failsafe flies a quadrotor on once its controller has been down for
/// `hold_s` (`plant/src/fallback.rs`, docs/failures.md "While an agent is down").
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum Fallback {
    /// Fly its formation slot: the leader's reference of the step (broadcast to every quadrotor)
    /// plus its formation offset, with the failsafe's own position and attitude loops.
    #[default]
    Slot,
    /// Brake and hold the point where it stops, altitude included.
    Hold,
    /// Level hover: roll and pitch to zero, yaw rate damped, thrust against gravity (drifts with
    /// the velocity it had).
    Hover,
}

/// Whose view of a returning member `runtime.rejoin_reference` re-arms the reference generator in
/// (docs/failures.md, bumpless re-entry).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum RejoinMembers {
    /// Only its neighbours' controllers: they see the returning member's reference start where the
    /// failsafe left it (zero consensus error with it), while its own controller tracks its slot
    /// at once (the failsafe kept it near it).
    #[default]
    Neighbours,
    /// Only the returning controller's own reference.
    Itself,
    /// Both: its own reference and its neighbours' view of it.
    All,
}

impl RejoinMembers {
    /// Whether the returning controller re-arms its own reference.
    pub fn itself(self) -> bool {
        matches!(self, RejoinMembers::Itself | RejoinMembers::All)
    }

    /// Whether a neighbour re-arms the reference of a member that came back.
    pub fn neighbours(self) -> bool {
        matches!(self, RejoinMembers::Neighbours | RejoinMembers::All)
    }
}

/// `[runtime]`: supervision, checkpoints and the fallbacks of a run. Every field has a default, so
/// scenarios without the section behave as before (no restarts).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Runtime {
    /// Policy for an agent process that dies or hangs outside the timeline. Default `never`.
    pub restart: RestartPolicy,
    /// Most restarts of one agent under `on-failure` (timeline crashes do not count). Default 3.
    pub max_restarts: u32,
    /// A role process that makes no progress for this long (wall time) while others wait on it is
    /// declared hung, named, killed and handled by `restart`, ms. Default 2000; 0 disables it.
    pub stall_timeout_ms: u64,
    /// Sim time between two checkpoints of an agent's controller state, s. Default 1.
    pub checkpoint_every_s: f64,
    /// What a restarted agent starts from. Default `warm`.
    pub restart_state: RestartState,
    /// While an agent is down, the plant holds its last command for this long, then flies the
    /// level-hover fallback, s. Default 0.2.
    pub hold_s: f64,
    /// What the failsafe flies after `hold_s`: `slot`, `hold` or `hover`. Default `slot`.
    pub fallback: Fallback,
    /// A new or resumed controller re-synchronises its command filters and auxiliary systems to
    /// the vehicle's current attitude and rate before its first command (adaptive estimates and
    /// RBFNN weights are kept). Default true.
    pub rejoin_resync: bool,
    /// A controller that comes back re-seeds its RBFNN before its first command so that its output
    /// F-hat_iP at the quadrotor's state equals the external acceleration the failsafe observed
    /// while it was down (read from the recorded states and the commands it was flown with, the
    /// failsafe's disturbance observer run again at its rate; docs/failures.md, "Re-entry that has
    /// learned"; D21): the smallest change of the weights that does it, then the projection of D15.
    /// Default true; without events nothing of it runs.
    pub rejoin_reseed: bool,
    /// A controller that comes back has the reference generator of D19 re-armed for its quadrotor
    /// in the controllers `rejoin_reference_for` names: the reference starts at the quadrotor's
    /// state where the failsafe left it and reaches its slot within `rejoin_reference_accel_m_s2`,
    /// so those controllers start from zero consensus errors with it instead of the failsafe's
    /// tracking error (docs/failures.md, bumpless re-entry; docs/deviations.md D21).
    /// Default true (measured in docs/failures.md); without events nothing of it runs.
    pub rejoin_reference: bool,
    /// In whose controllers the generator is re-armed: `neighbours`, `itself` or `all`. Default
    /// `all`: in its own controller the re-armed generator also holds back D23's leader-relative
    /// drive of the RBFNN until the reference is at the slot again, in the neighbours' it starts
    /// their consensus errors at zero (crash sweeps measured in docs/failures.md).
    pub rejoin_reference_for: RejoinMembers,
    /// a_R: largest acceleration of the re-armed reference, m/s² (the generator's a_S; its limit
    /// is up at once: the quadrotor is flying). Default 1.0 (D19's a_S).
    pub rejoin_reference_accel_m_s2: f64,
    /// lambda_R: rate of its final approach to the slot (double pole at -2 lambda_R), 1/s.
    /// Default 0.5 (D19's lambda_S).
    pub rejoin_reference_rate_1_s: f64,
    /// Gate of D23's leader-relative RBFNN drive in a controller that has come back, m: as
    /// `controller.position.nn_leader_gate_m` at start-up, the drive acts once the re-armed
    /// generator's remaining offset |e| is at or below it; 0: held until that generator is over.
    /// Default absent: the start-up gate `nn_leader_gate_m`. A returning quadrotor is back within
    /// centimetres of its slot, so the start-up gate (5 cm) releases the drive at once; the limit
    /// `controller.position.nn_leader_drive_limit_m` bounds what the network then integrates of
    /// the return's error (without it, agent 5 down at 45 s for 2 s: 0.54 m, 5.3 s), and holding
    /// the drive for the generator's ~10 s tail left a warm restart worse than a cold one
    /// (docs/failures.md, "Bumpless re-entry").
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rejoin_drive_gate_m: Option<f64>,
    /// Level-hover fallback: attitude gain (torque = -J (k_att A + k_rate omega)), 1/s². Default 16.
    pub fallback_attitude_gain: f64,
    /// Level-hover fallback: rate gain, 1/s. Default 8.
    pub fallback_rate_gain: f64,
    /// A neighbour whose newest delivered share is older than the delayed step by more than this
    /// is dropped from the consensus terms until fresh data returns, s. Default 0.1.
    pub stale_after_s: f64,
}

impl Default for Runtime {
    fn default() -> Runtime {
        Runtime {
            restart: RestartPolicy::Never,
            max_restarts: 3,
            stall_timeout_ms: 2000,
            checkpoint_every_s: 1.0,
            restart_state: RestartState::Warm,
            hold_s: 0.2,
            fallback: Fallback::Slot,
            rejoin_resync: true,
            rejoin_reseed: true,
            rejoin_reference: true,
            rejoin_reference_for: RejoinMembers::All,
            rejoin_reference_accel_m_s2: 1.0,
            rejoin_reference_rate_1_s: 0.5,
            rejoin_drive_gate_m: None,
            fallback_attitude_gain: 16.0,
            fallback_rate_gain: 8.0,
            stale_after_s: 0.1,
        }
    }
}

impl Runtime {
    /// Steps between checkpoints (at least 1).
    pub fn checkpoint_steps(&self, dt: f64) -> u64 {
        ((self.checkpoint_every_s / dt).round() as u64).max(1)
    }

    /// `stale_after_s` in whole steps.
    pub fn stale_steps(&self, dt: f64) -> u64 {
        (self.stale_after_s / dt).round().max(0.0) as u64
    }
}

/// A window [from, to) of steps in which an agent is down.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DownWindow {
    /// 0-based agent index.
    pub agent: usize,
    /// First step down.
    pub from: u64,
    /// First step up again (`u64::MAX`: never).
    pub to: u64,
    /// Crash (a new process from `to` on) or hang (the same process resumes).
    pub kind: EventKind,
}

/// A window in which the edge {a, b} carries nothing.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct LinkWindow {
    a: usize,
    b: usize,
    from: u64,
    to: u64,
}

/// Loss of shares from `from` to `to` (None: any) in [start, end).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Loss {
    from: Option<usize>,
    to: Option<usize>,
    start: u64,
    end: u64,
    probability: f64,
    seed: u64,
}

/// A fault or delay change at a step (0-based agent).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Change {
    /// Constant actuator fault from `step` on.
    Fault {
        /// First step.
        step: u64,
        /// Agent index.
        agent: usize,
        /// Gamma_i.
        gamma: [f64; 3],
        /// delta_i, N m.
        delta: [f64; 3],
    },
    /// Delay profile from `step` on.
    Delay {
        /// First step.
        step: u64,
        /// Agent index.
        agent: usize,
        /// tau = base + amplitude sin(rate t), s.
        base_s: f64,
        /// s.
        amplitude_s: f64,
        /// rad/s.
        angular_rate_rad_s: f64,
    },
}

/// The timeline resolved to steps and 0-based indices: every question is a pure function of it.
/// Events may be added while a run goes on ([`Timeline::add`]); an event is added before any
/// process reaches its step, so every process answers the same.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Timeline {
    dt: f64,
    down: Vec<DownWindow>,
    links: Vec<LinkWindow>,
    losses: Vec<Loss>,
    changes: Vec<Change>,
}

/// splitmix64: a fast, well-mixed 64-bit hash.
fn mix(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

impl Timeline {
    /// The timeline of `events` (validated) for a step `dt`.
    pub fn new(events: &[Event], dt: f64) -> Timeline {
        let mut t = Timeline {
            dt,
            ..Timeline::default()
        };
        for e in events {
            t.add(e);
        }
        t
    }

    /// Adds one (validated) event.
    pub fn add(&mut self, e: &Event) {
        let step = e.step(self.dt);
        let steps = |s: Option<f64>| s.map_or(u64::MAX, |s| (s / self.dt).round().max(1.0) as u64);
        let idx = |a: Option<usize>| a.map(|a| a.saturating_sub(1));
        match e.kind {
            EventKind::Crash | EventKind::Hang => {
                if let Some(agent) = idx(e.agent) {
                    self.down.push(DownWindow {
                        agent,
                        from: step,
                        to: step.saturating_add(steps(e.down_s)),
                        kind: e.kind,
                    });
                }
            }
            EventKind::LinkDown => {
                if let Some([a, b]) = e.agents {
                    self.links.push(LinkWindow {
                        a: a.saturating_sub(1),
                        b: b.saturating_sub(1),
                        from: step,
                        to: u64::MAX,
                    });
                }
            }
            EventKind::LinkUp => {
                if let Some([a, b]) = e.agents {
                    let (a, b) = (a.saturating_sub(1), b.saturating_sub(1));
                    for w in self.links.iter_mut() {
                        let same = (w.a, w.b) == (a, b) || (w.a, w.b) == (b, a);
                        if same && w.from <= step && w.to > step {
                            w.to = step;
                        }
                    }
                }
            }
            EventKind::MessageLoss => self.losses.push(Loss {
                from: idx(e.from),
                to: idx(e.to),
                start: step,
                end: step.saturating_add(steps(e.duration_s)),
                probability: e.probability.unwrap_or(0.0),
                seed: e.seed.unwrap_or(0),
            }),
            EventKind::Fault => {
                if let Some(agent) = idx(e.agent) {
                    self.changes.push(Change::Fault {
                        step,
                        agent,
                        gamma: e.gamma.unwrap_or([1.0; 3]),
                        delta: e.delta.unwrap_or([0.0; 3]),
                    });
                }
            }
            EventKind::Delay => {
                if let Some(agent) = idx(e.agent) {
                    self.changes.push(Change::Delay {
                        step,
                        agent,
                        base_s: e.base_s.unwrap_or(0.0),
                        amplitude_s: e.amplitude_s.unwrap_or(0.0),
                        angular_rate_rad_s: e.angular_rate_rad_s.unwrap_or(0.0),
                    });
                }
            }
        }
    }

    /// Adds a fault or delay change (a live injection).
    pub fn push_change(&mut self, c: Change) {
        self.changes.push(c);
    }

    /// Agent i is down from step `from` until further notice (a process that died or hung outside
    /// the timeline; [`Timeline::set_up_again`] ends the window).
    pub fn set_down(&mut self, agent: usize, from: u64, kind: EventKind) {
        self.down.push(DownWindow {
            agent,
            from,
            to: u64::MAX,
            kind,
        });
    }

    /// Ends the open down window of agent i at step `at` (its new process takes over there).
    pub fn set_up_again(&mut self, agent: usize, at: u64) {
        for w in self.down.iter_mut() {
            if w.agent == agent && w.to == u64::MAX && w.from <= at {
                w.to = at;
            }
        }
    }

    /// The step length, s.
    pub fn dt(&self) -> f64 {
        self.dt
    }

    /// Whether agent i computes its command at step k.
    pub fn up(&self, agent: usize, k: u64) -> bool {
        !self
            .down
            .iter()
            .any(|w| w.agent == agent && w.from <= k && k < w.to)
    }

    /// The down window of agent i that contains step k, if any.
    pub fn down_window(&self, agent: usize, k: u64) -> Option<DownWindow> {
        self.down
            .iter()
            .copied()
            .find(|w| w.agent == agent && w.from <= k && k < w.to)
    }

    /// The latest step in (`after`, `upto`] at which agent i came back from a down window (the
    /// first step its new or resumed controller computes), if any.
    pub fn latest_return(&self, agent: usize, after: u64, upto: u64) -> Option<u64> {
        self.down
            .iter()
            .filter(|w| w.agent == agent && w.to > after && w.to <= upto && w.to > w.from)
            .map(|w| w.to)
            .max()
    }

    /// Every down window, in the order they were added.
    pub fn down_windows(&self) -> &[DownWindow] {
        &self.down
    }

    /// The fault and delay changes, in the order they were added.
    pub fn changes(&self) -> &[Change] {
        &self.changes
    }

    /// Whether the edge {a, b} carries shares at step k.
    pub fn link_up(&self, a: usize, b: usize, k: u64) -> bool {
        !self
            .links
            .iter()
            .any(|w| ((w.a, w.b) == (a, b) || (w.a, w.b) == (b, a)) && w.from <= k && k < w.to)
    }

    /// Whether the share of step k from `from` is lost on its way to `to`.
    pub fn lost(&self, from: usize, to: usize, k: u64) -> bool {
        self.losses.iter().any(|l| {
            l.from.is_none_or(|f| f == from)
                && l.to.is_none_or(|t| t == to)
                && l.start <= k
                && k < l.end
                && {
                    let h = mix(l.seed ^ mix((from as u64) << 40 ^ (to as u64) << 20 ^ mix(k)));
                    // 53 random bits as a uniform number in [0, 1).
                    ((h >> 11) as f64) * (1.0 / (1u64 << 53) as f64) < l.probability
                }
        })
    }

    /// Whether the share of step k from `from` reaches `to`: the sender was up, the edge up, and
    /// the message not lost.
    pub fn delivered(&self, from: usize, to: usize, k: u64) -> bool {
        self.up(from, k) && self.link_up(from, to, k) && !self.lost(from, to, k)
    }

    /// True when the timeline has no event at all (the fast path of every question).
    pub fn is_empty(&self) -> bool {
        self.down.is_empty() && self.links.is_empty() && self.losses.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ev(at_s: f64, kind: EventKind) -> Event {
        Event::new(at_s, kind)
    }

    #[test]
    fn a_crash_takes_the_agent_down_for_down_s_from_its_step() {
        let mut e = ev(20.0, EventKind::Crash);
        e.agent = Some(3);
        e.down_s = Some(0.5);
        let t = Timeline::new(&[e], 0.001);
        assert!(t.up(2, 19_999));
        assert!(!t.up(2, 20_000));
        assert!(!t.up(2, 20_499));
        assert!(t.up(2, 20_500));
        assert!(t.up(1, 20_100), "only agent 3");
        assert!(
            !t.delivered(2, 1, 20_100),
            "a down agent's shares are not delivered"
        );
    }

    #[test]
    fn a_link_is_down_in_both_directions_until_its_link_up() {
        let mut d = ev(1.0, EventKind::LinkDown);
        d.agents = Some([2, 3]);
        let mut u = ev(6.0, EventKind::LinkUp);
        u.agents = Some([3, 2]);
        let t = Timeline::new(&[d, u], 0.001);
        assert!(t.link_up(1, 2, 999));
        assert!(!t.link_up(1, 2, 1000) && !t.link_up(2, 1, 5999));
        assert!(t.link_up(1, 2, 6000));
        assert!(t.link_up(0, 1, 3000), "other edges untouched");
    }

    #[test]
    fn message_loss_drops_about_its_probability_and_the_same_messages_every_time() {
        let mut l = ev(0.0, EventKind::MessageLoss);
        l.probability = Some(0.2);
        l.seed = Some(7);
        let t = Timeline::new(std::slice::from_ref(&l), 0.001);
        let lost = (0..100_000).filter(|&k| t.lost(0, 1, k)).count();
        assert!((19_000..21_000).contains(&lost), "{lost} of 100000");
        let again = Timeline::new(&[l], 0.001);
        assert!((0..10_000).all(|k| t.lost(1, 0, k) == again.lost(1, 0, k)));
        let other: usize = (0..10_000)
            .filter(|&k| t.lost(0, 1, k) != t.lost(1, 0, k))
            .count();
        assert!(other > 1000, "directions are independent: {other}");
    }

    #[test]
    fn an_open_down_window_ends_where_the_new_process_takes_over() {
        let mut t = Timeline::new(&[], 0.001);
        t.set_down(1, 500, EventKind::Crash);
        assert!(!t.up(1, 10_000));
        t.set_up_again(1, 800);
        assert!(!t.up(1, 799) && t.up(1, 800) && t.up(1, 499));
    }

    #[test]
    fn the_latest_return_is_the_end_of_a_closed_down_window_inside_the_span() {
        let mut c = ev(20.0, EventKind::Crash);
        c.agent = Some(3);
        c.down_s = Some(2.0);
        let mut h = ev(40.0, EventKind::Hang);
        h.agent = Some(3);
        h.down_s = Some(0.5);
        let mut t = Timeline::new(&[c, h], 0.001);
        assert_eq!(t.latest_return(2, 0, 21_999), None, "still down");
        assert_eq!(t.latest_return(2, 0, 22_000), Some(22_000));
        assert_eq!(t.latest_return(2, 22_000, 40_499), None, "already seen");
        assert_eq!(t.latest_return(2, 0, 50_000), Some(40_500), "the latest");
        assert_eq!(t.latest_return(1, 0, 50_000), None, "only agent 3");
        t.set_down(1, 500, EventKind::Crash);
        assert_eq!(
            t.latest_return(1, 0, 50_000),
            None,
            "an open window never returns"
        );
        t.set_up_again(1, 800);
        assert_eq!(t.latest_return(1, 0, 50_000), Some(800));
    }
}
