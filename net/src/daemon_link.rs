//! The Zenoh side of a host daemon (`formation host`, crate `formation-host`): its session, its
//! liveliness token, the queryable of its requests, the clock probe it answers at once, the
//! orchestrators it watches, the reports it puts and the bridges it starts. The daemon itself is
//! a state machine over these calls and names no Zenoh type; this is the only place where a
//! daemon touches Zenoh.

use crate::bridge::{Bridge, BridgeConfig, BridgeError};
use crate::proto;
use crate::session::{self, OptionError};
use std::time::Duration;
use zenoh::handlers::FifoChannelHandler;
use zenoh::sample::{Sample, SampleKind};
use zenoh::Wait;

/// Requests queued before the daemon's loop takes them (a full queue drops the newest).
const REQUEST_QUEUE: usize = 64;

/// Liveliness changes of orchestrators queued between two turns of the daemon's loop.
const ORCHESTRATOR_QUEUE: usize = 256;

/// A daemon's open link: what it listens to.
pub struct DaemonLink {
    out: Outbox,
    _token: zenoh::liveliness::LivelinessToken,
    queries: zenoh::query::Queryable<FifoChannelHandler<zenoh::query::Query>>,
    _clock: zenoh::query::Queryable<()>,
    orchestrators: zenoh::pubsub::Subscriber<FifoChannelHandler<Sample>>,
}

/// What a daemon sends on its own: reports put on run keys, and the bridges of its runs. Cheap
/// to clone (one session).
#[derive(Clone)]
pub struct Outbox {
    session: zenoh::Session,
}

/// One request to the daemon, answered once with [`Query::reply`].
pub struct Query {
    query: zenoh::query::Query,
}

/// A change of an orchestrator's liveliness token (`formation/run/<id>/orchestrator`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Orchestrator {
    /// The orchestrator of run `.0` is alive (its token appeared, or was there at start).
    Alive(String),
    /// The orchestrator of run `.0` is gone (it died, or its link was lost).
    Gone(String),
}

/// Why a daemon's link could not be opened.
#[derive(Debug)]
pub enum LinkError {
    /// The session could not be opened.
    Session(OptionError),
    /// The session is open but a declaration failed: what, and Zenoh's reason.
    Declare(&'static str, String),
}

impl std::fmt::Display for LinkError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            LinkError::Session(e) => write!(f, "{e}"),
            LinkError::Declare(what, e) => write!(f, "cannot {what}: {e}"),
        }
    }
}

impl std::error::Error for LinkError {}

impl DaemonLink {
    /// Opens the session of daemon `name` (`opts` in [`session::Mode::Daemon`]), declares its
    /// liveliness token (`formation/host/<name>`), the queryable of `formation/host/<name>/*`,
    /// the clock probe (answered at once in Zenoh's thread with [`formation_config::node::clock::now_ns`]:
    /// an answer queued behind the request loop would bias the offset estimate, crate::clock) and
    /// the watch of every orchestrator's token (with history: tokens already there are seen).
    pub fn open(opts: &session::Options, name: &str) -> Result<DaemonLink, LinkError> {
        let s = opts.open().map_err(LinkError::Session)?;
        let declare = |what| move |e: zenoh::Error| LinkError::Declare(what, e.to_string());
        let _token = s
            .liveliness()
            .declare_token(proto::host_token(name))
            .wait()
            .map_err(declare("declare the liveliness token"))?;
        let queries = s
            .declare_queryable(format!("formation/host/{name}/*"))
            .with(zenoh::handlers::FifoChannel::new(REQUEST_QUEUE))
            .wait()
            .map_err(declare("declare the queryable"))?;
        let _clock = s
            .declare_queryable(proto::clock_key(name))
            .callback(|q| {
                let now = formation_config::node::clock::now_ns();
                let _ = q
                    .reply(q.key_expr().clone(), now.to_le_bytes().to_vec())
                    .wait();
            })
            .wait()
            .map_err(declare("declare the clock queryable"))?;
        let orchestrators = s
            .liveliness()
            .declare_subscriber("formation/run/*/orchestrator")
            .history(true)
            .with(zenoh::handlers::FifoChannel::new(ORCHESTRATOR_QUEUE))
            .wait()
            .map_err(declare("watch the orchestrators"))?;
        Ok(DaemonLink {
            out: Outbox { session: s },
            _token,
            queries,
            _clock,
            orchestrators,
        })
    }

    /// The next request, waiting at most `timeout`.
    pub fn next_query(&self, timeout: Duration) -> Option<Query> {
        match self.queries.recv_timeout(timeout) {
            Ok(Some(query)) => Some(Query { query }),
            _ => None,
        }
    }

    /// The next change of an orchestrator's liveliness, if one is queued.
    pub fn orchestrator(&self) -> Option<Orchestrator> {
        let sample = self.orchestrators.try_recv().ok()??;
        let run = sample
            .key_expr()
            .as_str()
            .strip_prefix("formation/run/")
            .and_then(|r| r.strip_suffix("/orchestrator"))
            .unwrap_or("")
            .to_string();
        Some(match sample.kind() {
            SampleKind::Put => Orchestrator::Alive(run),
            SampleKind::Delete => Orchestrator::Gone(run),
        })
    }

    /// What the daemon sends on its own.
    pub fn outbox(&self) -> Outbox {
        self.out.clone()
    }
}

impl Outbox {
    /// Puts `msg` on `key`, blocking rather than dropping when the link is congested (an exit
    /// report or a checkpoint must arrive).
    pub fn put(&self, key: String, msg: Vec<u8>) {
        let _ = self
            .session
            .put(key, msg)
            .congestion_control(zenoh::qos::CongestionControl::Block)
            .wait();
    }

    /// Starts a run's bridge on this link ([`Bridge::start`]).
    pub fn bridge(&self, cfg: BridgeConfig) -> Result<Bridge, BridgeError> {
        Bridge::start(self.session.clone(), cfg)
    }
}

impl Query {
    /// Its payload (empty if it has none).
    pub fn payload(&self) -> Vec<u8> {
        self.query
            .payload()
            .map(|p| p.to_bytes().into_owned())
            .unwrap_or_default()
    }

    /// Whether it asks `formation/host/<name>/info` (the others are requests).
    pub fn asks_info(&self) -> bool {
        self.query.key_expr().as_str().ends_with("/info")
    }

    /// Answers it.
    pub fn reply(self, answer: Vec<u8>) {
        let _ = self
            .query
            .reply(self.query.key_expr().clone(), answer)
            .wait();
    }
}
