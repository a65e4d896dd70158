//! The orchestrator's side: reach the daemons, compare identities, prepare a run on each host,
//! start and stop its remote processes, and hear of their exits.

use crate::auth::{Purpose, Replay, RunKey, RunSecret};
use crate::clock;
use crate::error::ZenohError;
use crate::identity::{self, Identity};
use crate::proto::{self, ExitReport, HostInfo, Reply, Request};
use crate::session;
use formation_config::node::clock::now_ns;
use std::collections::BTreeMap;
use std::collections::HashMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use zenoh::sample::SampleKind;
use zenoh::Wait;

/// The name of the launching host in placements and keys (reserved: no daemon may take it).
pub const LAUNCHER: &str = "local";

/// What went wrong before anything started; the run exits 2 with this.
#[derive(Debug, Clone, PartialEq)]
pub enum HandshakeError {
    /// Hosts that did not answer within the timeout.
    Missing(Vec<String>),
    /// A host whose identity differs from this one: (host, what differs).
    Mismatch(String, Vec<String>),
    /// A host refused the run (why).
    Refused(String, String),
    /// Zenoh could not be opened.
    Session(String),
}

impl std::fmt::Display for HandshakeError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            HandshakeError::Missing(h) => write!(
                f,
                "host(s) {} did not answer within {:?} (is `formation host --name NAME` running there, reachable through --connect, and given the same --auth credentials?)",
                h.join(", "),
                session::REPLY_TIMEOUT
            ),
            HandshakeError::Mismatch(h, d) => write!(
                f,
                "this host ({LAUNCHER}) and host {h} cannot run together: {}",
                d.join("; ")
            ),
            HandshakeError::Refused(h, why) => write!(f, "host {h} refused the run: {why}"),
            HandshakeError::Session(e) => f.write_str(e),
        }
    }
}

impl std::error::Error for HandshakeError {}

/// A host's link state as the orchestrator sees it (liveliness).
#[derive(Debug, Default)]
struct Seen {
    exits: Vec<(String, ExitReport)>,
    lost: Vec<(String, Instant)>,
    checkpoints: Checkpoints,
    /// Reports (exits, checkpoints) refused because their host was lost before they came: a
    /// lost host is fenced for the rest of the run.
    fenced: u64,
}

impl Seen {
    /// Whether a report of `host` is taken: not once the host was lost (counted in `fenced`).
    fn admits(&mut self, host: &str) -> bool {
        if self.lost.iter().any(|(h, _)| h == host) {
            self.fenced += 1;
            return false;
        }
        true
    }
}

/// The checkpoints the daemons forwarded, kept with the orchestrator: per agent the
/// [`Checkpoints::KEPT`] newest by step. A takeover needs one taken before the step the agent went
/// down and still inside the orchestrator's ring of recorded steps; the newest may be of the very
/// step the host died in, so the one before it is kept too. No Zenoh: a pure store.
#[derive(Debug, Default, Clone)]
pub struct Checkpoints {
    by_agent: BTreeMap<usize, Vec<(u64, Vec<u8>)>>,
}

impl Checkpoints {
    /// Checkpoints kept per agent.
    pub const KEPT: usize = 2;

    /// A checkpoint of agent `agent` (0-based) taken before step `step`; a newer file of the same
    /// step replaces the older.
    pub fn offer(&mut self, agent: usize, step: u64, bytes: Vec<u8>) {
        let v = self.by_agent.entry(agent).or_default();
        v.retain(|(s, _)| *s != step);
        v.push((step, bytes));
        v.sort_by_key(|(s, _)| *s);
        let extra = v.len().saturating_sub(Self::KEPT);
        v.drain(..extra);
    }

    /// The newest checkpoint of `agent` a takeover can restore: taken before `down_from` (the
    /// first step it did not compute) and not before `oldest` (the oldest step the orchestrator
    /// still holds the records of, which the replay needs). `(step, file)`.
    pub fn pick(&self, agent: usize, down_from: u64, oldest: u64) -> Option<(u64, &[u8])> {
        self.by_agent
            .get(&agent)?
            .iter()
            .rev()
            .find_map(|(s, b)| (*s < down_from && *s >= oldest).then_some((*s, b.as_slice())))
    }
}

/// The run's secret as this orchestrator holds it (made at [`Cluster::announce`]).
struct RunAuth {
    secret: RunSecret,
    key: RunKey,
    /// Sequence number of the last request sent about the run.
    seq: AtomicU64,
}

/// An orchestrator's Zenoh session and what it hears.
pub struct Cluster {
    session: zenoh::Session,
    auth: Option<Arc<RunAuth>>,
    seen: Arc<Mutex<Seen>>,
    _token: Option<zenoh::liveliness::LivelinessToken>,
    _subs: Vec<zenoh::pubsub::Subscriber<()>>,
}

impl Cluster {
    /// Opens the session.
    pub fn open(o: &session::Options) -> Result<Cluster, HandshakeError> {
        let session = o
            .open()
            .map_err(|e| HandshakeError::Session(e.to_string()))?;
        Ok(Cluster {
            session,
            auth: None,
            seen: Arc::new(Mutex::new(Seen::default())),
            _token: None,
            _subs: Vec::new(),
        })
    }

    /// The session (for the bridge).
    pub fn session(&self) -> zenoh::Session {
        self.session.clone()
    }

    /// Names of the daemons whose liveliness token is visible.
    pub fn names(&self, timeout: Duration) -> Vec<String> {
        let mut v = Vec::new();
        if let Ok(replies) = self
            .session
            .liveliness()
            .get(proto::HOSTS)
            .timeout(timeout)
            .wait()
        {
            while let Ok(r) = replies.recv() {
                if let Ok(s) = r.result() {
                    if let Some(n) = s.key_expr().as_str().strip_prefix("formation/host/") {
                        v.push(n.to_string());
                    }
                }
            }
        }
        v.sort();
        v.dedup();
        v
    }

    /// A daemon's info, and the round trip it took (for the clock offset estimate).
    pub fn info(&self, name: &str, timeout: Duration) -> Option<(HostInfo, Duration)> {
        let t0 = Instant::now();
        let replies = self
            .session
            .get(proto::host_info(name))
            .timeout(timeout)
            .wait()
            .ok()?;
        while let Ok(r) = replies.recv() {
            if let Ok(s) = r.result() {
                if let Ok(i) = serde_json::from_slice::<HostInfo>(&s.payload().to_bytes()) {
                    return Some((i, t0.elapsed()));
                }
            }
        }
        None
    }

    /// The offset of `name`'s `CLOCK_MONOTONIC` from this machine's, from [`clock::PROBES`]
    /// request/response probes (the one of the shortest round trip, [`clock::estimate`]).
    pub fn clock_offset(&self, name: &str, timeout: Duration) -> Option<clock::Offset> {
        let mut probes = Vec::with_capacity(clock::PROBES);
        for _ in 0..clock::PROBES {
            let t0 = now_ns();
            let Ok(replies) = self
                .session
                .get(proto::clock_key(name))
                .timeout(timeout)
                .wait()
            else {
                continue;
            };
            while let Ok(r) = replies.recv() {
                if let Ok(s) = r.result() {
                    let t3 = now_ns();
                    if let Ok(b) = <[u8; 8]>::try_from(&s.payload().to_bytes()[..]) {
                        probes.push(clock::Probe {
                            t0,
                            remote: u64::from_le_bytes(b),
                            t3,
                        });
                    }
                }
            }
        }
        clock::estimate(&probes)
    }

    /// Waits until every host in `names` answers (up to `timeout`) and has this identity.
    pub fn handshake(
        &self,
        names: &[String],
        me: &Identity,
        timeout: Duration,
    ) -> Result<BTreeMap<String, HostInfo>, HandshakeError> {
        let deadline = Instant::now() + timeout;
        let mut found = BTreeMap::new();
        loop {
            for n in names {
                if !found.contains_key(n) {
                    if let Some((i, _)) = self.info(n, Duration::from_millis(500)) {
                        found.insert(n.clone(), i);
                    }
                }
            }
            if found.len() == names.len() || Instant::now() >= deadline {
                break;
            }
            std::thread::sleep(Duration::from_millis(100));
        }
        let missing: Vec<String> = names
            .iter()
            .filter(|n| !found.contains_key(*n))
            .cloned()
            .collect();
        if !missing.is_empty() {
            return Err(HandshakeError::Missing(missing));
        }
        for (n, i) in &found {
            let d = identity::differences(me, &i.identity);
            if !d.is_empty() {
                return Err(HandshakeError::Mismatch(n.clone(), d));
            }
        }
        Ok(found)
    }

    /// Sends a request to a daemon and waits for its reply (with the bytes after it, if any).
    /// A request about the run carries proof of the run's secret ([`crate::auth`]); a reply is
    /// taken only with proof of it too, except a refusal (which changes nothing).
    pub fn request(
        &self,
        host: &str,
        req: &Request,
        bytes: &[u8],
        timeout: Duration,
    ) -> Result<(Reply, Vec<u8>), RequestError> {
        let mut payload = proto::frame(req, bytes);
        let mut seq = 0;
        if req.run_id().is_some() {
            let a = self.auth.as_ref().ok_or(RequestError::NotAnnounced)?;
            seq = a.seq.fetch_add(1, Ordering::SeqCst) + 1;
            a.key.seal(Purpose::Request, host, seq, &mut payload);
        }
        let replies = self
            .session
            .get(proto::host_req(host))
            .payload(payload)
            .timeout(timeout)
            .wait()
            .map_err(|e| RequestError::Query {
                host: host.to_string(),
                why: e.to_string(),
            })?;
        match replies.recv() {
            Ok(r) => match r.result() {
                Ok(s) => self.reply(host, seq, &s.payload().to_bytes()),
                Err(e) => Err(RequestError::Query {
                    host: host.to_string(),
                    why: String::from_utf8_lossy(&e.payload().to_bytes()).into_owned(),
                }),
            },
            Err(_) => Err(RequestError::NoAnswer {
                host: host.to_string(),
                timeout,
            }),
        }
    }

    /// A daemon's reply to request `seq`: a plain JSON [`Reply`] or one framed with bytes, with
    /// the proof of the run's secret once the run is announced.
    fn reply(&self, host: &str, seq: u64, data: &[u8]) -> Result<(Reply, Vec<u8>), RequestError> {
        let parse = |data: &[u8]| -> Result<(Reply, Vec<u8>), RequestError> {
            if let Ok(reply) = serde_json::from_slice::<Reply>(data) {
                return Ok((reply, Vec::new()));
            }
            let (reply, rest): (Reply, &[u8]) = proto::decode_frame(data)?;
            Ok((reply, rest.to_vec()))
        };
        let Some(a) = &self.auth else {
            return parse(data);
        };
        match a.key.open(Purpose::Reply, host, data) {
            Ok((body, s)) if s == seq => parse(body),
            Ok((_, s)) => Err(RequestError::OtherReply {
                host: host.to_string(),
                seq,
                answered: s,
            }),
            // A refusal without proof changes nothing (the daemon may not hold the run).
            Err(e) => match serde_json::from_slice::<Reply>(data) {
                Ok(Reply::Refused(why)) => Ok((Reply::Refused(why), Vec::new())),
                _ => Err(RequestError::NoProof {
                    host: host.to_string(),
                    why: e,
                }),
            },
        }
    }

    /// The run's secret, for its `Prepare` requests (`None` before [`Cluster::announce`]).
    pub fn run_secret(&self) -> Option<RunSecret> {
        self.auth.as_ref().map(|a| a.secret.clone())
    }

    /// The run's keys, for this machine's bridge (`None` before [`Cluster::announce`]).
    pub fn run_key(&self) -> Option<RunKey> {
        self.auth.as_ref().map(|a| a.key.clone())
    }

    /// Declares this run's orchestrator (its liveliness token: the daemons end the run when it
    /// disappears) and starts hearing exit reports and lost hosts.
    /// Makes the run's secret first ([`crate::auth`]): exit reports and checkpoints are taken
    /// only with proof of it.
    pub fn announce(&mut self, run_id: &str) -> Result<(), AnnounceError> {
        let secret = RunSecret::generate()?;
        let key = secret.keys(run_id);
        self.auth = Some(Arc::new(RunAuth {
            secret,
            key: key.clone(),
            seq: AtomicU64::new(0),
        }));
        self._token = Some(
            self.session
                .liveliness()
                .declare_token(proto::run_token(run_id))
                .wait()
                .map_err(|e| ZenohError::new("cannot declare the run's token", e))?,
        );
        let seen = self.seen.clone();
        let exits_key = proto::run_exit(run_id);
        let exits_check = Reports::new(key.clone(), exits_key.clone());
        let exits = self
            .session
            .declare_subscriber(exits_key)
            .callback(move |s| {
                let data = s.payload().to_bytes();
                let r = exits_check.open(&data, |body| {
                    let r = serde_json::from_slice::<ExitReport>(body)?;
                    Ok((r.host.clone(), r))
                });
                if let Some(r) = r {
                    let mut seen = seen.lock().unwrap();
                    if seen.admits(&r.host) {
                        seen.exits.push((r.host.clone(), r));
                    }
                }
            })
            .wait()
            .map_err(|e| ZenohError::new("cannot subscribe to exits", e))?;
        let seen = self.seen.clone();
        let checkpoints_key = proto::run_checkpoint(run_id);
        let checkpoints_check = Reports::new(key, checkpoints_key.clone());
        let checkpoints = self
            .session
            .declare_subscriber(checkpoints_key)
            .callback(move |s| {
                let data = s.payload().to_bytes();
                let note = checkpoints_check.open(&data, |body| {
                    let (n, bytes) = proto::decode_frame::<proto::CheckpointNote>(body)?;
                    Ok((n.host.clone(), (n, bytes.to_vec())))
                });
                if let Some((n, bytes)) = note {
                    let mut seen = seen.lock().unwrap();
                    if seen.admits(&n.host) {
                        seen.checkpoints.offer(n.agent, n.step, bytes);
                    }
                }
            })
            .wait()
            .map_err(|e| ZenohError::new("cannot subscribe to checkpoints", e))?;
        self._subs.push(checkpoints);
        let seen = self.seen.clone();
        let hosts = self
            .session
            .liveliness()
            .declare_subscriber(proto::HOSTS)
            .callback(move |s| {
                if s.kind() == SampleKind::Delete {
                    if let Some(n) = s.key_expr().as_str().strip_prefix("formation/host/") {
                        seen.lock()
                            .unwrap()
                            .lost
                            .push((n.to_string(), Instant::now()));
                    }
                }
            })
            .wait()
            .map_err(|e| ZenohError::new("cannot watch the hosts", e))?;
        self._subs.push(exits);
        self._subs.push(hosts);
        Ok(())
    }

    /// The exit report of `pid` of agent `agent` on `host`, if one came.
    pub fn exit_of(&self, host: &str, agent: usize, pid: u32) -> Option<String> {
        let seen = self.seen.lock().unwrap();
        seen.exits
            .iter()
            .find(|(h, r)| h == host && r.agent == agent && r.pid == pid)
            .map(|(_, r)| r.how.clone())
    }

    /// The newest forwarded checkpoint of `agent` a takeover can restore (see
    /// [`Checkpoints::pick`]): `(step, file)`.
    pub fn checkpoint(&self, agent: usize, down_from: u64, oldest: u64) -> Option<(u64, Vec<u8>)> {
        self.seen
            .lock()
            .unwrap()
            .checkpoints
            .pick(agent, down_from, oldest)
            .map(|(s, b)| (s, b.to_vec()))
    }

    /// Reports (exit reports, checkpoints) refused because their host had been lost.
    pub fn fenced_reports(&self) -> u64 {
        self.seen.lock().unwrap().fenced
    }

    /// When `host`'s daemon was seen to go (its liveliness token vanished), if it did.
    pub fn lost(&self, host: &str) -> Option<Instant> {
        self.seen
            .lock()
            .unwrap()
            .lost
            .iter()
            .find(|(h, _)| h == host)
            .map(|(_, t)| *t)
    }
}

/// The check of the reports (exit reports, checkpoints) put on one key expression of the run:
/// proof of the run's secret for that key, a sequence number not seen before from that host.
/// Refusals are logged at most once a second per reason.
struct Reports {
    key: RunKey,
    on: String,
    state: Mutex<(HashMap<String, Replay>, crate::logs::LogLimit)>,
}

impl Reports {
    fn new(key: RunKey, on: String) -> Reports {
        Reports {
            key,
            on,
            state: Mutex::new((HashMap::new(), crate::logs::LogLimit::default())),
        }
    }

    /// What `parse` makes of a sealed report (with the sending host), if it is one.
    fn open<T>(
        &self,
        data: &[u8],
        parse: impl FnOnce(&[u8]) -> Result<(String, T), Box<dyn std::error::Error>>,
    ) -> Option<T> {
        let mut st = self.state.lock().unwrap_or_else(|p| p.into_inner());
        let (replays, log) = &mut *st;
        let on = &self.on;
        let (body, seq) = match self.key.open(Purpose::Report, on, data) {
            Ok(v) => v,
            Err(e) => {
                log.warn(on, "no proof", || format!("a report on {on} refused: {e}"));
                return None;
            }
        };
        let (host, v) = match parse(body) {
            Ok(v) => v,
            Err(e) => {
                log.warn(on, "malformed", || format!("a report on {on} refused: {e}"));
                return None;
            }
        };
        // Only holders of the run's secret get here: the table holds the run's hosts.
        if let Err(e) = replays.entry(host.clone()).or_default().accept(seq) {
            log.warn(on, "replayed", || {
                format!("a report of {host} on {on} refused: {e}")
            });
            return None;
        }
        Some(v)
    }
}

/// Why a request to a host daemon got no usable reply: the host and what failed.
#[derive(Debug, thiserror::Error)]
pub enum RequestError {
    /// A request about the run before [`Cluster::announce`].
    #[error("a request about a run before the run was announced")]
    NotAnnounced,
    /// The query failed, or the host answered with an error.
    #[error("host {host}: {why}")]
    Query {
        /// The host.
        host: String,
        /// Zenoh's error or the host's error reply.
        why: String,
    },
    /// No answer within the timeout.
    #[error("host {host} did not answer within {timeout:?}")]
    NoAnswer {
        /// The host.
        host: String,
        /// How long it was given.
        timeout: Duration,
    },
    /// The reply to another request.
    #[error("host {host} answered request {seq} with the reply to request {answered}")]
    OtherReply {
        /// The host.
        host: String,
        /// The request's sequence number.
        seq: u64,
        /// The sequence number the reply proves.
        answered: u64,
    },
    /// A reply without proof of the run's secret.
    #[error("host {host}'s reply was refused: {why}")]
    NoProof {
        /// The host.
        host: String,
        /// What the proof check said.
        why: crate::auth::ProofError,
    },
    /// A reply that is not a protocol message.
    #[error(transparent)]
    Frame(#[from] proto::FrameError),
}

/// Why a run cannot be announced: its secret, or a Zenoh declaration.
#[derive(Debug, thiserror::Error)]
pub enum AnnounceError {
    /// The run's secret cannot be made.
    #[error(transparent)]
    Secret(#[from] crate::auth::SecretError),
    /// The run's token or a subscriber cannot be declared.
    #[error(transparent)]
    Zenoh(#[from] ZenohError),
}

crate::error::into_string!(RequestError, AnnounceError);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_lost_host_is_fenced_its_later_reports_refused_and_counted() {
        let mut seen = Seen::default();
        assert!(seen.admits("b"));
        seen.lost.push(("b".to_string(), Instant::now()));
        assert!(!seen.admits("b"));
        assert!(!seen.admits("b"));
        assert!(seen.admits("c"), "another host's reports are taken");
        assert_eq!(seen.fenced, 2);
    }

    #[test]
    fn a_takeover_restores_the_newest_checkpoint_before_the_step_it_went_down_within_the_records() {
        let mut c = Checkpoints::default();
        assert_eq!(c.pick(3, 5000, 0), None, "none forwarded yet");
        c.offer(3, 0, vec![0]);
        c.offer(3, 1000, vec![1]);
        c.offer(3, 2000, vec![2]);
        c.offer(4, 2000, vec![42]);
        // Only the two newest are kept.
        assert_eq!(c.pick(3, 5000, 0), Some((2000, &[2u8][..])));
        assert_eq!(c.pick(3, 1500, 0), Some((1000, &[1u8][..])));
        assert_eq!(c.pick(3, 900, 0), None, "step 0's was dropped");
        // The host died right after the checkpoint of step 2000 was written: down from 2000.
        assert_eq!(c.pick(3, 2000, 0), Some((1000, &[1u8][..])));
        // Older than the recorded steps the replay needs: none.
        assert_eq!(c.pick(3, 2000, 1200), None);
        // Per agent; a newer copy of the same step replaces the older; out of order is sorted.
        assert_eq!(c.pick(4, 3000, 0), Some((2000, &[42u8][..])));
        c.offer(4, 2000, vec![43]);
        c.offer(4, 1000, vec![41]);
        assert_eq!(c.pick(4, 3000, 0), Some((2000, &[43u8][..])));
        assert_eq!(c.pick(4, 2000, 0), Some((1000, &[41u8][..])));
    }
}
