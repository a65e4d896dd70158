//! `formation run --hosts`: agents on other machines, through their `formation host` daemons and
//! one bridge per host (crate `formation-net`, docs/multi-host.md).
//!
//! Before anything starts: the handshake (every named host answers within its timeout, with the
//! same protocol, build and wire layout; exit 2 naming the host and what differs otherwise), then
//! every host prepares the run (services, bridge; a refusal ends the prepared ones, exit 2). Only
//! then are processes started: plant, leader and this machine's agents here, the others by their
//! daemons. Plant, leader and orchestrator always stay on the launching machine.

pub use super::remote_error::RemoteError;
use super::spawn::{RemoteProcess, RoleProcess};
use super::HostPacing;
use crate::link::LinkArgs;
use formation_config::node::args::ChildArgs;
use formation_config::node::restart;
use formation_config::protocol::services::Sizing;
use formation_config::Scenario;
use formation_net::bridge::{Bridge, BridgeConfig};
use formation_net::clock::Offset;
use formation_net::cluster::{Cluster, HandshakeError, LAUNCHER};
use formation_net::colocate::{self, DataPlane, Facts};
use formation_net::plan::Placement;
use formation_net::proto::{self, Reply, Request, RunRequest};
use formation_net::session::{self, Mode, Options};
use std::cell::RefCell;
use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Where the agents of a lost host are taken over (`Placement::takeover_host`): this machine.
pub const TAKEOVER_HOST: &str = LAUNCHER;

/// Placement options of `formation run`.
#[derive(clap::Args, Debug, Clone)]
pub struct PlaceArgs {
    /// Hosts (daemons started with `formation host --name NAME`) that take agents: the agents are
    /// spread round-robin over this machine and these hosts, unless placed with --place.
    #[arg(long, value_delimiter = ',', value_name = "NAME,NAME...")]
    pub hosts: Vec<String>,
    /// Place agents on a host: `4,5@b` (1-based ids; repeatable). With --place, agents not placed
    /// stay on this machine.
    #[arg(long, value_name = "IDS@HOST")]
    pub place: Vec<String>,
    /// Endpoint of a host's daemon (repeatable): tls/ADDR:PORT or quic/ADDR:PORT (with --tls),
    /// tcp/ADDR:PORT (with --auth) or unixsock-stream/PATH. Default: each --hosts daemon of yours on this machine
    /// (its socket in your private runtime folder).
    #[arg(long, value_name = "ENDPOINT")]
    pub connect: Vec<String>,
    /// Zenoh link options.
    #[command(flatten)]
    pub link: LinkArgs,
}

impl PlaceArgs {
    /// The `--auth` file, if given (also the readers admitted by `--zenoh-listen`).
    pub fn auth(&self) -> Option<&Path> {
        self.link.auth.as_deref()
    }
}

/// The host of every agent (0-based index), [`LAUNCHER`] for this machine.
pub fn placement(n: usize, hosts: &[String], place: &[String]) -> Result<Vec<String>, RemoteError> {
    for h in hosts {
        if !proto::valid_name(h) || h == LAUNCHER {
            return Err(RemoteError::HostName {
                host: h.clone(),
                launcher: LAUNCHER,
            });
        }
    }
    if place.is_empty() {
        let all: Vec<&str> = std::iter::once(LAUNCHER)
            .chain(hosts.iter().map(String::as_str))
            .collect();
        return Ok((0..n).map(|i| all[i % all.len()].to_string()).collect());
    }
    let mut v = vec![LAUNCHER.to_string(); n];
    let mut placed = vec![false; n];
    for p in place {
        let (ids, host) = p
            .split_once('@')
            .ok_or_else(|| RemoteError::PlaceForm(p.clone()))?;
        if host != LAUNCHER && !hosts.iter().any(|h| h == host) {
            return Err(RemoteError::PlaceHost {
                place: p.clone(),
                host: host.to_string(),
            });
        }
        for id in ids.split(',') {
            let k: usize = id.trim().parse().map_err(|_| RemoteError::PlaceId {
                place: p.clone(),
                id: id.to_string(),
            })?;
            if k == 0 || k > n {
                return Err(RemoteError::PlaceRange {
                    place: p.clone(),
                    agent: k,
                    n,
                });
            }
            if placed[k - 1] {
                return Err(RemoteError::PlaceTwice {
                    place: p.clone(),
                    agent: k,
                });
            }
            placed[k - 1] = true;
            v[k - 1] = host.to_string();
        }
    }
    Ok(v)
}

/// A handshake error, with what is wrong with each endpoint when hosts did not answer (an
/// authentication failure, a socket or an address that cannot be reached).
fn why_missing(opts: &Options, e: HandshakeError) -> RemoteError {
    let mut diagnoses = Vec::new();
    if let HandshakeError::Missing(_) = e {
        diagnoses = opts
            .connect
            .iter()
            .filter_map(|ep| session::diagnose(opts, ep))
            .map(|f| f.to_string())
            .collect();
    }
    RemoteError::Handshake {
        source: e,
        diagnoses,
    }
}

/// Hosts reached and checked, before the run is prepared.
pub struct Remote {
    cluster: Cluster,
    lease: Duration,
    agent_hosts: Vec<String>,
    hosts: Vec<String>,
    neighbours: Vec<Vec<usize>>,
    offsets: BTreeMap<String, Offset>,
    /// Hosts whose daemons share this orchestrator's `/dev/shm`, user and iceoryx2 root.
    colocated: Vec<String>,
}

/// Opens the session and runs the handshake; `None` without `--hosts`.
pub fn connect(a: &PlaceArgs, scenario: &Scenario) -> Result<Option<Remote>, RemoteError> {
    if a.hosts.is_empty() {
        if !a.place.is_empty() || !a.connect.is_empty() {
            return Err(RemoteError::NeedsHosts);
        }
        return Ok(None);
    }
    let n = scenario.n_agents();
    let agent_hosts = placement(n, &a.hosts, &a.place)?;
    let mut hosts: Vec<String> = Vec::new();
    for h in &agent_hosts {
        if h != LAUNCHER && !hosts.contains(h) {
            hosts.push(h.clone());
        }
    }
    // Without --connect: each host's daemon of this user on this machine (its private socket).
    let connect = if a.connect.is_empty() {
        hosts
            .iter()
            .map(|h| session::local_endpoint(h))
            .collect::<Result<Vec<_>, _>>()?
    } else {
        a.connect.clone()
    };
    let opts = a.link.options(Mode::Orchestrator, vec![], connect);
    for w in opts.warnings() {
        eprintln!("formation run: {w}");
    }
    crate::link::ignore_sigpipe();
    let cluster = Cluster::open(&opts).map_err(|source| RemoteError::Handshake {
        source,
        diagnoses: Vec::new(),
    })?;
    let me = formation_net::identity::local();
    let infos = cluster
        .handshake(&hosts, &me, session::REPLY_TIMEOUT)
        .map_err(|e| why_missing(&opts, e))?;
    // A daemon sharing this /dev/shm as this user runs its agents on this orchestrator's
    // services (co-located); as another user it cannot take part.
    let here = Facts::here();
    let mut colocated = Vec::new();
    for (h, i) in &infos {
        match colocate::data_plane(h, &here, &i.facts())? {
            DataPlane::Colocated => {
                tracing::info!(host = h.as_str(), pid = i.pid, "co-located host");
                colocated.push(h.clone());
            }
            DataPlane::Remote => {}
        }
    }
    let mut offsets = BTreeMap::new();
    for h in &hosts {
        let o = cluster
            .clock_offset(h, std::time::Duration::from_secs(1))
            .ok_or_else(|| RemoteError::ClockProbe(h.clone()))?;
        tracing::info!(
            host = h.as_str(),
            offset_ns = o.offset_ns,
            rtt_ns = o.rtt_ns,
            "clock offset"
        );
        offsets.insert(h.clone(), o);
    }
    Ok(Some(Remote {
        cluster,
        lease: Duration::from_millis(a.link.lease_ms),
        agent_hosts,
        hosts,
        offsets,
        neighbours: Placement::neighbours_of(n, scenario.graph.edges.iter().map(|e| (e.a, e.b))),
        colocated,
    }))
}

impl Remote {
    /// Prepares the run on every host that is not co-located (services and bridge there; no
    /// process yet). A refusal ends the hosts already prepared. The co-located hosts are prepared
    /// once this orchestrator has created the run's services ([`RemoteRun::attach`]).
    pub fn prepare(
        mut self,
        run_id: &str,
        prefix: &str,
        scenario: &Scenario,
        variant: &str,
        pacing: HostPacing,
    ) -> Result<RemoteRun, RemoteError> {
        self.cluster.announce(run_id)?;
        let req = RunRequest {
            run_id: run_id.to_string(),
            secret: self.cluster.run_secret().ok_or(RemoteError::NoSecret)?,
            prefix: prefix.to_string(),
            scenario_toml: scenario.to_toml_string(),
            variant: variant.to_string(),
            agent_hosts: self.agent_hosts.clone(),
            launcher: LAUNCHER.to_string(),
            realtime: pacing.realtime,
            rt_priority: pacing.rt_priority,
            observers: pacing.observers,
            identity: formation_net::identity::local(),
            clock_offsets_ns: clock_offsets_ns(&self.offsets),
            colocated: None,
        };
        let placement = Placement {
            agent_hosts: self.agent_hosts,
            launcher: LAUNCHER.to_string(),
            neighbours: self.neighbours,
        };
        let run = RemoteRun {
            cluster: Arc::new(self.cluster),
            run_id: run_id.to_string(),
            placement: RefCell::new(placement.clone()),
            colocated: self.colocated,
            request: req,
            hosts: RefCell::new(Vec::new()),
            bridge: RefCell::new(None),
            lease: self.lease,
            moved: RefCell::new(BTreeMap::new()),
            lost: RefCell::new(BTreeMap::new()),
            offsets: self.offsets,
        };
        for h in self.hosts.iter().filter(|h| !run.colocated.contains(h)) {
            let req = RunRequest {
                agent_hosts: run.placement_for(h, &placement).agent_hosts,
                ..run.request.clone()
            };
            run.prepare_host(h, req)?;
        }
        Ok(run)
    }
}

/// A run spread over hosts: ends the run on every host when dropped.
pub struct RemoteRun {
    cluster: Arc<Cluster>,
    run_id: String,
    /// Where every agent lives now (a lost host's agents move, `Placement::after_loss`).
    placement: RefCell<Placement>,
    /// Hosts where the run is prepared and that are not lost.
    hosts: RefCell<Vec<String>>,
    bridge: RefCell<Option<Bridge>>,
    /// The Zenoh lease: a silent host is declared lost after it.
    lease: Duration,
    /// Agents moved off a lost host whose takeover has not restored a checkpoint yet: the host
    /// they were lost with.
    moved: RefCell<BTreeMap<usize, String>>,
    /// Every host taken over, with the agents it held then.
    lost: RefCell<BTreeMap<String, Vec<usize>>>,
    offsets: BTreeMap<String, Offset>,
    /// Hosts sharing this orchestrator's `/dev/shm` (`formation_net::colocate`): prepared after
    /// the services exist, never bridged.
    colocated: Vec<String>,
    /// The run request every host is prepared with (its placement per host).
    request: RunRequest,
}

/// Every host's clock minus this machine's, ns, this machine included (0).
fn clock_offsets_ns(offsets: &BTreeMap<String, Offset>) -> BTreeMap<String, i64> {
    let mut m: BTreeMap<String, i64> = offsets
        .iter()
        .map(|(h, o)| (h.clone(), o.offset_ns))
        .collect();
    m.insert(LAUNCHER.to_string(), 0);
    m
}

/// True for a timing file name a host may send: `[A-Za-z0-9_-]+.json` (nothing that leaves the
/// timing folder).
fn timing_file_name(name: &str) -> bool {
    name.strip_suffix(".json").is_some_and(|stem| {
        !stem.is_empty()
            && stem
                .bytes()
                .all(|b| b.is_ascii_alphanumeric() || b == b'_' || b == b'-')
    })
}

impl Drop for RemoteRun {
    fn drop(&mut self) {
        for h in self.hosts.borrow().iter() {
            let _ = self.cluster.request(
                h,
                &Request::End {
                    run_id: self.run_id.clone(),
                },
                &[],
                session::REPLY_TIMEOUT,
            );
        }
        let reports = self.cluster.fenced_reports();
        if reports > 0 {
            eprintln!(
                "formation run: {reports} report(s) (exits, checkpoints) from lost hosts refused after they were fenced"
            );
        }
        if let Some(b) = self.bridge.borrow_mut().take() {
            let s = &b.stats;
            use std::sync::atomic::Ordering::Relaxed;
            tracing::info!(
                frames_out = s.frames_out.load(Relaxed),
                samples_out = s.samples_out.load(Relaxed),
                events_out = s.events_out.load(Relaxed),
                frames_in = s.frames_in.load(Relaxed),
                refused = s.refused.load(Relaxed),
                fenced = s.fenced.load(Relaxed),
                "bridge stopped"
            );
            let fenced = s.fenced.load(Relaxed);
            if fenced > 0 {
                eprintln!(
                    "formation run: {fenced} frame(s) from lost hosts refused after they were fenced"
                );
            }
        }
    }
}

impl RemoteRun {
    /// The placement `host` works with: the daemons that bridge (and this machine's bridge, for
    /// [`LAUNCHER`]) see the co-located hosts' agents on the launcher
    /// (`Placement::data_plane`); a co-located daemon sees where every agent is started.
    fn placement_for(&self, host: &str, placement: &Placement) -> Placement {
        if self.colocated.iter().any(|c| c == host) {
            placement.clone()
        } else {
            placement.data_plane(&self.colocated)
        }
    }

    /// Prepares the run on `host`; it is ended with the run from then on.
    fn prepare_host(&self, host: &str, req: RunRequest) -> Result<(), RemoteError> {
        match self
            .cluster
            .request(host, &Request::Prepare(req), &[], session::REPLY_TIMEOUT)?
        {
            (Reply::Ok { .. }, _) => {
                self.hosts.borrow_mut().push(host.to_string());
                Ok(())
            }
            (Reply::Refused(why), _) => Err(RemoteError::Refused {
                host: host.to_string(),
                why,
            }),
        }
    }

    /// Once the orchestrator has created the run's services (no process started yet): prepares
    /// the co-located hosts, which check that those services are in their `/dev/shm` and their
    /// user's, and starts this machine's bridge if any host is not co-located.
    pub fn attach(&self, prefix: &str, sizing: Sizing, run_dir: &Path) -> Result<(), RemoteError> {
        let placement = self.placement.borrow().clone();
        for h in &self.colocated {
            let req = RunRequest {
                agent_hosts: placement.agent_hosts.clone(),
                colocated: Some(Box::new(proto::Colocated {
                    iox2_root: formation_config::node::ipc::root_dir()
                        .to_string_lossy()
                        .into_owned(),
                    members: formation_config::node::members::lock_path(run_dir),
                })),
                ..self.request.clone()
            };
            self.prepare_host(h, req)?;
        }
        let data = self.placement_for(LAUNCHER, &placement);
        if data.hosts().len() < 2 {
            tracing::info!("every host is co-located: no bridge");
            return Ok(());
        }
        self.start_bridge(prefix, sizing, data)
    }

    /// Starts this machine's bridge for the data-plane placement `placement`.
    fn start_bridge(
        &self,
        prefix: &str,
        sizing: Sizing,
        placement: Placement,
    ) -> Result<(), RemoteError> {
        let b = Bridge::start(
            self.cluster.session(),
            BridgeConfig {
                run_id: self.run_id.clone(),
                prefix: prefix.to_string(),
                me: LAUNCHER.to_string(),
                placement,
                sizing,
                create: false,
                key: self.cluster.run_key().ok_or(RemoteError::NoSecret)?,
                clock_offsets_ns: clock_offsets_ns(&self.offsets),
                rt_priority: if self.request.realtime {
                    self.request.rt_priority
                } else {
                    0
                },
            },
        )?;
        if self.request.realtime {
            eprintln!("formation run: {}", b.scheduling.describe());
        }
        tracing::info!(
            out = b.forwarded.0,
            inbound = b.forwarded.1,
            "bridge started"
        );
        *self.bridge.borrow_mut() = Some(b);
        Ok(())
    }

    /// Brings the run's timing files of every host into `<run_dir>/timing/` (the remote agents'
    /// `agent-<id>.json`, each bridge's link delays as `bridge-<host>.json`, this machine's
    /// included), once the processes have stopped.
    pub fn collect_timing(&self, run_dir: &Path) -> Result<(), RemoteError> {
        if let Some(b) = self.bridge.borrow().as_ref() {
            b.link_report()
                .write(run_dir, &format!("bridge-{LAUNCHER}"))
                .map_err(RemoteError::TimingReport)?;
        }
        let dir = formation_config::node::timing::dir(run_dir);
        for h in self.hosts.borrow().iter() {
            let req = Request::Report {
                run_id: self.run_id.clone(),
            };
            let (reply, bytes) = self.cluster.request(h, &req, &[], session::REPLY_TIMEOUT)?;
            if let Reply::Refused(why) = reply {
                return Err(RemoteError::Host {
                    host: h.clone(),
                    why,
                });
            }
            let report: proto::HostReport =
                serde_json::from_slice(&bytes).map_err(|source| RemoteError::Report {
                    host: h.clone(),
                    source,
                })?;
            for (name, text) in report.timing {
                if !timing_file_name(&name) {
                    return Err(RemoteError::TimingName {
                        host: h.clone(),
                        name,
                    });
                }
                let p = dir.join(&name);
                formation_config::node::files::write_atomic(&p, text.as_bytes())
                    .map_err(RemoteError::file(&p))?;
            }
        }
        Ok(())
    }

    /// The clock of every host as the handshake estimated it (`summary.json` `timing.clocks`).
    pub fn clocks_json(&self) -> serde_json::Value {
        serde_json::Value::Array(
            self.offsets
                .iter()
                .map(|(h, o)| {
                    serde_json::json!({
                        "host": h,
                        "offset_us": o.offset_ns as f64 / 1e3,
                        "rtt_us": o.rtt_ns as f64 / 1e3,
                        "uncertainty_us": o.uncertainty_ns as f64 / 1e3,
                    })
                })
                .collect(),
        )
    }

    /// Whether agent i (0-based) runs on another host.
    pub fn is_remote(&self, i: usize) -> bool {
        self.placement
            .borrow()
            .agent_hosts
            .get(i)
            .is_some_and(|h| h != LAUNCHER)
    }

    /// `agents 1,2,3 here, 4,5 on b`.
    pub fn describe(&self) -> String {
        let mut parts = Vec::new();
        let placement = self.placement.borrow();
        for h in placement.hosts() {
            let ids: Vec<String> = placement
                .agents_on(&h)
                .iter()
                .map(|i| (i + 1).to_string())
                .collect();
            if !ids.is_empty() {
                parts.push(format!("{} on {h}", ids.join(",")));
            }
        }
        format!("agents {}", parts.join("; "))
    }

    /// Starts agent `agent` on its host (with its rejoin file, for a process taking over).
    pub fn spawn(
        &self,
        agent: usize,
        label: String,
        args: &ChildArgs,
    ) -> Result<RoleProcess, RemoteError> {
        let host = self.placement.borrow().agent_hosts[agent].clone();
        let rejoin = match args.rejoin_at {
            Some(_) => {
                let p = restart::rejoin_path(&args.run_dir, agent);
                std::fs::read(&p).map_err(RemoteError::file(&p))?
            }
            None => Vec::new(),
        };
        let req = Request::Spawn {
            run_id: self.run_id.clone(),
            agent,
            rejoin_at: args.rejoin_at,
        };
        match self
            .cluster
            .request(&host, &req, &rejoin, session::REPLY_TIMEOUT)?
        {
            (Reply::Ok { pid: Some(pid) }, _) => Ok(RoleProcess::remote(
                format!("{label} on {host}"),
                Box::new(RemoteAgent {
                    cluster: self.cluster.clone(),
                    colocated: self
                        .colocated
                        .iter()
                        .any(|c| *c == host)
                        .then(|| self.request.prefix.clone()),
                    host,
                    run_id: self.run_id.clone(),
                    agent,
                    pid,
                }),
            )),
            (Reply::Ok { pid: None }, _) => Err(RemoteError::NoPid { host, label }),
            (Reply::Refused(why), _) => Err(RemoteError::Spawn { host, label, why }),
        }
    }

    /// Copies agent `agent`'s latest checkpoint from its host into `run_dir` (a warm takeover
    /// reads it here).
    pub fn fetch_checkpoint(&self, agent: usize, run_dir: &Path) -> Result<(), RemoteError> {
        let host = &self.placement.borrow().agent_hosts[agent].clone();
        let req = Request::Checkpoint {
            run_id: self.run_id.clone(),
            agent,
        };
        match self
            .cluster
            .request(host, &req, &[], session::REPLY_TIMEOUT)?
        {
            (Reply::Ok { .. }, bytes) => write_checkpoint(run_dir, agent, &bytes),
            (Reply::Refused(why), _) => Err(RemoteError::Host {
                host: host.clone(),
                why,
            }),
        }
    }
}

impl RemoteRun {
    /// The host of every agent now (`local` for this machine).
    pub fn agent_hosts(&self) -> Vec<String> {
        self.placement.borrow().agent_hosts.clone()
    }

    /// The Zenoh lease: a host whose link is silent this long is declared lost.
    pub fn lease(&self) -> Duration {
        self.lease
    }

    /// The agents (0-based) `host` held when it was lost: those it held when it was taken over,
    /// or (not taken over) those it holds.
    pub fn agents_lost_with(&self, host: &str) -> Vec<usize> {
        match self.lost.borrow().get(host) {
            Some(v) => v.clone(),
            None => self.placement.borrow().agents_on(host),
        }
    }

    /// When `host`'s daemon was seen to go, if it was.
    pub fn lost_at(&self, host: &str) -> Option<Instant> {
        self.cluster.lost(host)
    }

    /// `host` is lost and the run goes on: its agents move to the launcher
    /// (`Placement::after_loss`), this machine's bridge is re-planned first, then every other
    /// remaining host's (`Request::Replan`), and the lost host leaves the run. Returns the agents
    /// moved (0-based), or `None` if `host` was handled already. `Err`: a remaining host could
    /// not re-plan, and the run must stop.
    pub fn take_over_host(&self, host: &str) -> Result<Option<Vec<usize>>, RemoteError> {
        if !self.hosts.borrow().iter().any(|h| h == host) {
            return Ok(None);
        }
        let (next, moved) = self.placement.borrow().after_loss(host)?;
        if let Some(b) = self.bridge.borrow_mut().as_mut() {
            let (out, inbound) = b.replan(&self.placement_for(LAUNCHER, &next))?;
            tracing::info!(out, inbound, lost = host, "bridge re-planned");
        }
        self.hosts.borrow_mut().retain(|h| h != host);
        for h in self.hosts.borrow().iter() {
            let req = Request::Replan {
                run_id: self.run_id.clone(),
                agent_hosts: self.placement_for(h, &next).agent_hosts,
            };
            // A host lost as well (before or while it is asked) is taken over in its turn.
            let lost = || self.cluster.lost(h).is_some();
            let answer =
                (!lost()).then(|| self.cluster.request(h, &req, &[], session::REPLY_TIMEOUT));
            let Some(answer) = answer.filter(|_| !lost()) else {
                tracing::warn!(host = h.as_str(), lost = host, "not re-planned: lost too");
                continue;
            };
            match answer? {
                (Reply::Ok { .. }, _) => {}
                (Reply::Refused(why), _) => {
                    return Err(RemoteError::Replan {
                        host: h.clone(),
                        lost: host.to_string(),
                        why,
                    })
                }
            }
        }
        let mut m = self.moved.borrow_mut();
        for &i in &moved {
            m.insert(i, host.to_string());
        }
        self.lost
            .borrow_mut()
            .insert(host.to_string(), moved.clone());
        *self.placement.borrow_mut() = next;
        Ok(Some(moved))
    }

    /// For an agent moved off a lost host: writes the newest checkpoint its daemon forwarded
    /// that a takeover at `down_from` can restore (taken before it, not before `oldest`, the
    /// oldest recorded step) into `run_dir`, where the takeover reads it. `Ok(None)`: not a moved
    /// agent, or no such checkpoint came (the takeover goes cold).
    pub fn restore_checkpoint(
        &self,
        agent: usize,
        run_dir: &Path,
        down_from: u64,
        oldest: u64,
    ) -> Result<Option<u64>, RemoteError> {
        // Once: a later restart of the moved agent reads the checkpoints it writes here.
        if self.moved.borrow_mut().remove(&agent).is_none() {
            return Ok(None);
        }
        let Some((step, bytes)) = self.cluster.checkpoint(agent, down_from, oldest) else {
            return Ok(None);
        };
        write_checkpoint(run_dir, agent, &bytes)?;
        Ok(Some(step))
    }
}

/// Puts a checkpoint that came from a host where agent `agent`'s successor reads it: whole, owner
/// only, never through a symbolic link (`files::write_atomic`).
fn write_checkpoint(run_dir: &Path, agent: usize, bytes: &[u8]) -> Result<(), RemoteError> {
    let p = restart::checkpoint_path(run_dir, agent);
    if let Some(d) = p.parent() {
        std::fs::create_dir_all(d).map_err(RemoteError::file(d))?;
    }
    formation_config::node::files::write_atomic(&p, bytes).map_err(RemoteError::file(&p))
}

/// Longest wait for a daemon to say whether an agent is stopped: asked only once a run has made no
/// progress for its stall timeout, when the run is about to be stopped or the agent replaced.
const STOPPED_TIMEOUT: Duration = Duration::from_secs(1);

/// An agent process on another host.
struct RemoteAgent {
    cluster: Arc<Cluster>,
    host: String,
    run_id: String,
    agent: usize,
    pid: u32,
    /// For a host that shares this machine's kernel (co-located): the run's iceoryx2 prefix, by
    /// which the orchestrator recognises and fences the process itself once the host is lost.
    colocated: Option<String>,
}

impl RemoteAgent {
    /// Its host was lost: on a co-located host, whose daemon may only be paused while its
    /// agents run on, the process is ended here before its successor starts (`fence`); what
    /// was done, for the line that names the loss.
    fn fence(&self) -> String {
        let Some(prefix) = &self.colocated else {
            return String::new();
        };
        use super::fence::{end_agent, Fenced, FENCE_TIMEOUT};
        match end_agent(self.pid, prefix, self.agent, FENCE_TIMEOUT) {
            Fenced::Ended => {
                "; fenced: its process ended here (SIGKILL) before its successor starts".into()
            }
            Fenced::Gone | Fenced::NotOurs => String::new(),
            Fenced::StillRunning => {
                format!("; fenced: SIGKILLed here, still running after {FENCE_TIMEOUT:?}")
            }
            Fenced::Failed(kind) => format!("; cannot fence its process: {kind}"),
        }
    }
}

impl RemoteProcess for RemoteAgent {
    fn pid(&self) -> u32 {
        self.pid
    }

    fn host(&self) -> &str {
        &self.host
    }

    fn kill_and_reap(&mut self) {
        if self.cluster.lost(&self.host).is_some() {
            // Its host is gone, and the process with it (it dies with its daemon), unless the
            // daemon is only paused: on a co-located host it is fenced here.
            let fenced = self.fence();
            if !fenced.is_empty() {
                tracing::info!(
                    agent = self.agent + 1,
                    host = self.host.as_str(),
                    "{fenced}"
                );
            }
            return;
        }
        let req = Request::Kill {
            run_id: self.run_id.clone(),
            agent: self.agent,
        };
        if let Err(e) = self
            .cluster
            .request(&self.host, &req, &[], session::REPLY_TIMEOUT)
        {
            tracing::warn!("cannot kill agent {} on {}: {e}", self.agent + 1, self.host);
        }
    }

    fn signal(&self, signal: i32) {
        if self.cluster.lost(&self.host).is_some() {
            return;
        }
        let req = Request::Signal {
            run_id: self.run_id.clone(),
            agent: self.agent,
            signal,
        };
        if let Err(e) = self
            .cluster
            .request(&self.host, &req, &[], session::REPLY_TIMEOUT)
        {
            tracing::warn!(
                "cannot signal agent {} on {}: {e}",
                self.agent + 1,
                self.host
            );
        }
    }

    fn is_stopped(&self) -> bool {
        if self.cluster.lost(&self.host).is_some() {
            return false;
        }
        let req = Request::Stopped {
            run_id: self.run_id.clone(),
            agent: self.agent,
        };
        match self.cluster.request(&self.host, &req, &[], STOPPED_TIMEOUT) {
            Ok((Reply::Ok { .. }, bytes)) => bytes.first() == Some(&1),
            Ok((Reply::Refused(_), _)) => false,
            Err(e) => {
                tracing::warn!(
                    "cannot ask host {} about agent {}: {e}",
                    self.host,
                    self.agent + 1
                );
                false
            }
        }
    }

    fn try_wait(&mut self) -> Option<String> {
        if let Some(how) = self.cluster.exit_of(&self.host, self.agent, self.pid) {
            return Some(how);
        }
        self.cluster.lost(&self.host).map(|_| {
            format!(
                "was lost with host {} (its daemon's liveliness token vanished){}",
                self.host,
                self.fence()
            )
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn agents_go_round_robin_over_this_machine_and_the_hosts_unless_placed() {
        let h = vec!["b".to_string()];
        assert_eq!(
            placement(5, &h, &[]).unwrap(),
            ["local", "b", "local", "b", "local"]
        );
        assert_eq!(
            placement(5, &h, &["4,5@b".into()]).unwrap(),
            ["local", "local", "local", "b", "b"]
        );
        let hc = vec!["b".to_string(), "c".to_string()];
        assert_eq!(
            placement(4, &hc, &["1@c".into(), "2@b".into()]).unwrap(),
            ["c", "b", "local", "local"]
        );
    }

    #[test]
    fn a_host_may_send_only_plain_timing_file_names() {
        assert!(timing_file_name("agent-4.json"));
        assert!(timing_file_name("bridge-b.json"));
        assert!(!timing_file_name("../x.json"));
        assert!(!timing_file_name("a/b.json"));
        assert!(!timing_file_name(".json"));
        assert!(!timing_file_name("plant.toml"));
    }

    #[test]
    fn a_bad_placement_is_named() {
        let h = vec!["b".to_string()];
        assert!(placement(5, &h, &["6@b".into()])
            .unwrap_err()
            .to_string()
            .contains("agent 6 does not exist"));
        assert!(placement(5, &h, &["4@c".into()])
            .unwrap_err()
            .to_string()
            .contains("not in --hosts"));
        assert!(placement(5, &h, &["4@b".into(), "4@b".into()])
            .unwrap_err()
            .to_string()
            .contains("placed twice"));
        assert!(placement(5, &h, &["x@b".into()])
            .unwrap_err()
            .to_string()
            .contains("not an agent id"));
        assert!(placement(5, &h, &["4b".into()])
            .unwrap_err()
            .to_string()
            .contains("IDS@HOST"));
        assert!(placement(5, &["local".into()], &[]).is_err());
        assert!(placement(5, &["a/b".into()], &[]).is_err());
    }
}
