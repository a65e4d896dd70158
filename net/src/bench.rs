//! Bare Zenoh for `formation bench --transports zenoh`: the cross-host part of a lockstep step
//! without the processes around it, so that a split run's step can be set against it.
//!
//! * [`Link`]: one end of a bare link between two processes, opened with the sessions of a run
//!   across hosts ([`crate::session`]: the launcher a router that connects, the other host a peer
//!   that listens, runtimes capped) and the bridges' frame publisher and subscriber
//!   ([`crate::bridge::frame_publisher`]: `CongestionControl::Block`, `express`,
//!   `Priority::RealTime`).
//! * [`StepPattern`]: what crosses between the launcher and one host in one lockstep step of a
//!   placement, as bridge records (service name, wire type name, size): the leader's reference
//!   and the plant's states of that host's agents with their wake-ups out, their commands and the
//!   plant's wake-up back, and the neighbour shares that cross in either direction. [`Records::frame`] builds the one frame
//!   a direction of a step takes at best, in the bridges' format ([`crate::bridge::parse_frame`]
//!   reads it).

use crate::bridge::{self, parse_frame, Record};
use crate::error::ZenohError;

/// A frame that is not the one a [`StepPattern`] expects: what differs.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum FrameMismatch {
    /// The body does not parse as a bridge frame.
    #[error(transparent)]
    Parse(#[from] bridge::RecordError),
    /// The first record is not the sending host.
    #[error("a frame without its sending host")]
    NoSender,
    /// Another record where a sample or event of a service was expected.
    #[error("expected {what} of {name}, got {got}")]
    Expected {
        /// `a sample` or `an event`.
        what: &'static str,
        /// The service expected.
        name: String,
        /// The record found (or `None`).
        got: String,
    },
    /// A record after the expected ones.
    #[error("an unexpected record {0}")]
    Unexpected(String),
}

/// Why the step pattern of a host cannot be made.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum StepError {
    /// The host holds no agent of the placement.
    #[error("no agent of the placement is on host {0}")]
    NoAgentOn(String),
    /// A service cannot be routed.
    #[error(transparent)]
    Route(#[from] crate::plan::PlanError),
}

/// Why a bare Zenoh link cannot be opened: the session, or a key's publisher or subscriber.
#[derive(Debug, thiserror::Error)]
pub enum LinkError {
    /// The session does not open.
    #[error(transparent)]
    Session(#[from] crate::session::OptionError),
    /// A publisher or subscriber cannot be declared.
    #[error(transparent)]
    Declare(#[from] ZenohError),
}
use crate::cluster::LAUNCHER;
use crate::plan::{agent_index, Placement};
use crate::session::{self, Mode, Options};
use formation_config::protocol::services::{
    wire_type_name, Message, Named, Topic, CONTROL_COMMAND, NEIGHBOUR_STATE, REFERENCE,
    VEHICLE_STATE, WAKE_AGENT, WAKE_PLANT,
};
use formation_config::Scenario;
use std::time::Duration;
use zenoh::handlers::FifoChannelHandler;
use zenoh::pubsub::{Publisher, Subscriber};
use zenoh::sample::Sample;
use zenoh::Wait;

/// Name of the second host of [`paper_split`].
pub const SPLIT_HOST: &str = "b";

/// The agents (1-based) [`paper_split`] places on [`SPLIT_HOST`]: the split of the multi-host
/// e2e test and of docs/multi-host.md (agents 1-3 on the launcher, 4-5 on the other host).
pub const SPLIT_AGENTS: [usize; 2] = [4, 5];

/// The paper scenario's five agents with [`SPLIT_AGENTS`] on [`SPLIT_HOST`], the rest on the
/// launcher; neighbours from the paper's graph.
pub fn paper_split() -> Placement {
    let scenario = Scenario::paper();
    let n = scenario.n_agents();
    Placement {
        agent_hosts: (1..=n)
            .map(|id| {
                if SPLIT_AGENTS.contains(&id) {
                    SPLIT_HOST.to_string()
                } else {
                    LAUNCHER.to_string()
                }
            })
            .collect(),
        launcher: LAUNCHER.to_string(),
        neighbours: Placement::neighbours_of(n, scenario.graph.edges.iter().map(|e| (e.a, e.b))),
    }
}

/// The bridge records of one direction of a step.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Records {
    /// Samples: (service name, wire type name, size in bytes).
    pub samples: Vec<(String, &'static str, usize)>,
    /// Events: service names.
    pub events: Vec<String>,
}

impl Records {
    /// The frame of these records as a bridge sends it from `from`, after `header` (the bench's
    /// step number): the sending host, every sample (zero bytes of its size), every event.
    pub fn frame(&self, from: &str, header: &[u8]) -> Vec<u8> {
        let mut f = Vec::with_capacity(header.len() + self.frame_bytes(from));
        f.extend_from_slice(header);
        bridge::put_from(&mut f, from);
        let largest = self.samples.iter().map(|s| s.2).max().unwrap_or(0);
        let zeros = vec![0u8; largest];
        for (name, type_name, size) in &self.samples {
            bridge::put_sample(&mut f, name, type_name, &zeros[..*size]);
        }
        for name in &self.events {
            bridge::put_event(&mut f, name);
        }
        f
    }

    /// Bytes of [`Records::frame`] from `from` without the header.
    pub fn frame_bytes(&self, from: &str) -> usize {
        let name = |n: &str| 3 + n.len();
        name(from)
            + self
                .samples
                .iter()
                .map(|(n, t, s)| name(n) + 1 + t.len() + 4 + s)
                .sum::<usize>()
            + self.events.iter().map(|n| name(n)).sum::<usize>()
    }

    /// Reads a frame body as a bridge's receiving side does ([`parse_frame`]) and checks that it
    /// holds exactly these records, in order.
    pub fn check(&self, body: &[u8]) -> Result<(), FrameMismatch> {
        let records = parse_frame(body).map_err(FrameMismatch::Parse)?;
        let mut it = records.iter();
        if !matches!(it.next(), Some(Record::From(_))) {
            return Err(FrameMismatch::NoSender);
        }
        for (name, type_name, size) in &self.samples {
            match it.next() {
                Some(Record::Sample {
                    name: n,
                    type_name: t,
                    bytes,
                }) if n == name && t == type_name && bytes.len() == *size => {}
                other => {
                    return Err(FrameMismatch::Expected {
                        what: "a sample",
                        name: name.clone(),
                        got: format!("{other:?}"),
                    })
                }
            }
        }
        for name in &self.events {
            match it.next() {
                Some(Record::Event(n)) if n == name => {}
                other => {
                    return Err(FrameMismatch::Expected {
                        what: "an event",
                        name: name.clone(),
                        got: format!("{other:?}"),
                    })
                }
            }
        }
        match it.next() {
            None => Ok(()),
            Some(r) => Err(FrameMismatch::Unexpected(format!("{r:?}"))),
        }
    }
}

/// What crosses between the launcher and one host in one lockstep step.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct StepPattern {
    /// The host (not the launcher).
    pub host: String,
    /// Launcher -> host.
    pub out: Records,
    /// Host -> launcher.
    pub back: Records,
}

/// Collects the per-step topics (states, shares, commands) each direction forwards.
struct PerStep<'a> {
    placement: &'a Placement,
    host: &'a str,
    pattern: StepPattern,
}

impl PerStep<'_> {
    fn add<T: Message>(&mut self, s: Named<Topic<T>>) -> Result<(), crate::plan::PlanError> {
        let i = agent_index(s.spec.pattern, &s.name);
        let route = |me: &str| {
            self.placement.route(
                me,
                &s.name,
                s.spec.publishers,
                s.spec.subscribers,
                s.spec.scope,
                i,
            )
        };
        let record = (s.name.clone(), wire_type_name::<T>(), size_of::<T>());
        if route(&self.placement.launcher)?
            .out_to
            .iter()
            .any(|h| h == self.host)
        {
            self.pattern.out.samples.push(record.clone());
        }
        if route(self.host)?.out_to.contains(&self.placement.launcher) {
            self.pattern.back.samples.push(record);
        }
        Ok(())
    }
}

impl StepPattern {
    /// The records of one lockstep step between the launcher and `host` for `placement`: the
    /// leader's reference (one a step, published ahead of the plant), the states, shares and
    /// commands its bridges forward ([`Placement::route`]), each agent's
    /// wake-up with its state (the plant wakes the agent it sent a state to) and the plant's
    /// wake-up with the commands (an agent wakes the plant after its command). A neighbour's
    /// wake-up after a share crosses only at step 0 or when that neighbour's delay is under one
    /// step (docs/runtime.md, "Pacing"), so it is not part of a step.
    pub fn of(placement: &Placement, host: &str) -> Result<StepPattern, StepError> {
        if host == placement.launcher || !placement.agent_hosts.iter().any(|h| h == host) {
            return Err(StepError::NoAgentOn(host.to_string()));
        }
        let mut p = PerStep {
            placement,
            host,
            pattern: StepPattern {
                host: host.to_string(),
                out: Records::default(),
                back: Records::default(),
            },
        };
        let n = placement.agent_hosts.len();
        p.add(REFERENCE.named())?;
        for i in 0..n {
            p.add(VEHICLE_STATE.at(i))?;
        }
        for i in 0..n {
            p.add(NEIGHBOUR_STATE.at(i))?;
        }
        for i in 0..n {
            p.add(CONTROL_COMMAND.at(i))?;
        }
        let mut pattern = p.pattern;
        for i in placement.agents_on(host) {
            pattern.out.events.push(WAKE_AGENT.at(i).name);
        }
        if !pattern.back.samples.is_empty() {
            pattern.back.events.push(WAKE_PLANT.named().name);
        }
        Ok(pattern)
    }
}

/// Which end of a bare link.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Side {
    /// The launcher: a Zenoh router that connects (the orchestrator's session).
    Launcher,
    /// The other host: a Zenoh peer that listens (a host daemon's session).
    Host,
}

impl Side {
    fn name(self) -> &'static str {
        match self {
            Side::Launcher => "launcher",
            Side::Host => "host",
        }
    }
}

/// One end of a bare Zenoh link: frames to the other end with the bridges' publisher, frames
/// from it through the bridges' subscriber (in order).
pub struct Link {
    publisher: Publisher<'static>,
    subscriber: Subscriber<FifoChannelHandler<Sample>>,
    // Dropped last: the ports above belong to it.
    _session: zenoh::Session,
}

impl Link {
    /// Opens this end of the link named `tag` (key-safe): the launcher connects to `endpoint`,
    /// the host listens on it (`tcp/127.0.0.1:PORT` with `auth`, or `tls/127.0.0.1:PORT` with
    /// `tls`, as a run's hosts).
    pub fn open(
        side: Side,
        endpoint: &str,
        tag: &str,
        auth: Option<std::path::PathBuf>,
        tls: Option<std::path::PathBuf>,
    ) -> Result<Link, LinkError> {
        let (mode, listen, connect) = match side {
            Side::Launcher => (Mode::Orchestrator, vec![], vec![endpoint.to_string()]),
            Side::Host => (Mode::Daemon, vec![endpoint.to_string()], vec![]),
        };
        let opts = Options {
            mode,
            listen,
            connect,
            auth,
            tls,
            lease_ms: session::DEFAULT_LEASE_MS,
        };
        let s = opts.open()?;
        let other = match side {
            Side::Launcher => Side::Host,
            Side::Host => Side::Launcher,
        };
        let key = |to: Side| format!("formation/bench/{tag}/to/{}", to.name());
        Ok(Link {
            publisher: bridge::frame_publisher(&s, key(other))?,
            subscriber: bridge::frame_subscriber(&s, key(side))?,
            _session: s,
        })
    }

    /// Sends one frame to the other end.
    pub fn send(&self, frame: Vec<u8>) -> Result<(), ZenohError> {
        self.publisher
            .put(frame)
            .wait()
            .map_err(|e| ZenohError::new("zenoh put", e))
    }

    /// A frame that is already there, without blocking.
    pub fn try_recv(&self) -> Result<Option<Vec<u8>>, ZenohError> {
        self.subscriber
            .try_recv()
            .map(|s| s.map(|s| s.payload().to_bytes().into_owned()))
            .map_err(|e| ZenohError::new("zenoh receive", e))
    }

    /// The next frame, waiting at most `timeout`.
    pub fn recv_timeout(&self, timeout: Duration) -> Result<Option<Vec<u8>>, ZenohError> {
        self.subscriber
            .recv_timeout(timeout)
            .map(|s| s.map(|s| s.payload().to_bytes().into_owned()))
            .map_err(|e| ZenohError::new("zenoh receive", e))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_split_step_carries_the_remote_agents_states_and_commands_and_the_shares_of_the_cut_edge() {
        let p = StepPattern::of(&paper_split(), SPLIT_HOST).unwrap();
        let names = |r: &Records| r.samples.iter().map(|s| s.0.clone()).collect::<Vec<_>>();
        // Agents 4 and 5 (indices 3, 4) on b; the paper's path graph cuts the edge 3-4.
        assert_eq!(
            names(&p.out),
            [
                "formation/reference",
                "formation/agent/3/state",
                "formation/agent/4/state",
                "formation/agent/2/share"
            ]
        );
        assert_eq!(
            p.out.events,
            ["formation/wake/agent/3", "formation/wake/agent/4"]
        );
        assert_eq!(
            names(&p.back),
            [
                "formation/agent/3/share",
                "formation/agent/3/command",
                "formation/agent/4/command"
            ]
        );
        assert_eq!(p.back.events, ["formation/wake/plant"]);
        let state = size_of::<formation_config::protocol::wire::VehicleState>();
        assert_eq!(p.out.samples[1].2, state);
        assert!(StepPattern::of(&paper_split(), LAUNCHER).is_err());
    }

    #[test]
    fn a_step_frame_is_read_back_as_the_bridges_read_it_and_a_foreign_one_is_refused() {
        let p = StepPattern::of(&paper_split(), SPLIT_HOST).unwrap();
        let f = p.out.frame(LAUNCHER, &[9; 16]);
        assert_eq!(f.len(), 16 + p.out.frame_bytes(LAUNCHER));
        p.out.check(&f[16..]).unwrap();
        assert!(p.back.check(&f[16..]).is_err());
        assert!(p.out.check(&f[16..f.len() - 1]).is_err());
    }
}
