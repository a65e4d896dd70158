//! `formation host`: a machine's daemon that lends its CPUs to runs.
//!
//! It announces itself with a liveliness token (`formation/host/<name>`) and answers
//! `formation/host/<name>/info` ([`HostInfo`]) and `formation/host/<name>/req` ([`Request`]).
//! For a run it creates a private run folder (mode 0700) with the validated scenario, every
//! iceoryx2 service of the run and the bridge ([`formation_net::bridge`]), then starts the agent processes
//! the orchestrator asks for — only `formation node agent ...` from its own executable — and
//! reports each one's exit. A daemon that shares the orchestrator's `/dev/shm` as its user
//! (co-located, [`formation_net::colocate`]) creates no service and runs no bridge: it checks that the
//! run's services are in its `/dev/shm` and its user's, and its agents open them and join the
//! orchestrator's membership of the run. A run ends when its orchestrator says so, or when the orchestrator's
//! liveliness token disappears (it died, or its link was lost): the processes are stopped, the
//! run's iceoryx2 files and its folder removed. The daemon is a single-threaded state machine:
//! one loop serves requests, reaps children and watches the orchestrators.

use crate::refusal::{FolderError, Refusal, ServeError};
use formation_config::node::args::ChildArgs;
use formation_config::node::ipc;
use formation_config::node::members::Membership;
use formation_config::node::ports::RunNode;
use formation_config::node::restart;
use formation_config::protocol::messages::Role;
use formation_config::protocol::services::{self, Sizing};
use formation_config::{Scenario, Variant};
use formation_net::auth::{Purpose, Replay, RunKey};
use formation_net::bridge::{Bridge, BridgeConfig};
use formation_net::colocate::{self, Facts};
use formation_net::daemon_link::{DaemonLink, Orchestrator, Outbox};
use formation_net::identity::{self, Identity};
use formation_net::logs::LogLimit;
use formation_net::plan::Placement;
use formation_net::proto::{self, ExitReport, HostInfo, Reply, Request, RunRequest};
use formation_net::session;
use std::collections::HashMap;
use std::os::unix::process::{CommandExt, ExitStatusExt};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// How long a prepared run waits for its orchestrator's liveliness token before it is dropped.
pub const ORCHESTRATOR_WAIT: Duration = Duration::from_secs(10);

/// How long the processes of an ending run get to exit by themselves before SIGKILL.
pub const STOP_GRACE: Duration = Duration::from_millis(1000);

/// How a daemon is started.
#[derive(Debug, Clone)]
pub struct DaemonOptions {
    /// Its name (key-safe, see [`proto::valid_name`]).
    pub name: String,
    /// Zenoh session (mode [`session::Mode::Daemon`]).
    pub session: session::Options,
    /// The executable the role processes are started from (the running `formation`).
    pub exe: PathBuf,
    /// Folder of the run folders (private: mode 0700).
    pub root: PathBuf,
    /// The highest `SCHED_FIFO` priority this daemon grants a run's agents
    /// (`--max-rt-priority`; default 0: none, the agents run under the normal policy whatever a
    /// run asks). A run asking for more is granted this, and the daemon says so.
    pub max_rt_priority: u32,
}

/// The largest request a daemon reads (a `Spawn` carries a rejoin file: the recorded window of
/// every quadrotor); anything longer is refused unread.
pub const MAX_REQUEST: usize = 32 << 20;

/// A run's share of this host.
struct HostRun {
    req: RunRequest,
    dir: PathBuf,
    variant: String,
    children: HashMap<usize, Child>,
    prepared: Instant,
    /// Hash of the run's scenario, which its checkpoints carry.
    scenario_hash: u64,
    /// The checkpoint file of each agent last forwarded (see [`Daemon::forward_checkpoints`]).
    forwarded: HashMap<usize, FileStamp>,
    /// The run's keys ([`formation_net::auth`]).
    key: RunKey,
    /// Sequence numbers of the requests about the run accepted so far.
    replay: Replay,
    /// Sequence number of the last report (exit, checkpoint) this daemon sent about the run.
    reports: u64,
    // Dropped in this order: bridge, node, membership (see `end`).
    bridge: Option<Bridge>,
    node: Option<RunNode>,
    membership: Option<Membership>,
}

/// What tells one version of a file from the next: inode (a checkpoint is written to a temporary
/// name and renamed, so each version is a new inode), size and modification time.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FileStamp {
    ino: u64,
    len: u64,
    mtime_ns: i128,
}

impl FileStamp {
    /// The stamp of `path`, if it exists.
    pub fn of(path: &Path) -> Option<FileStamp> {
        use std::os::unix::fs::MetadataExt;
        let m = std::fs::metadata(path).ok()?;
        Some(FileStamp {
            ino: m.ino(),
            len: m.len(),
            mtime_ns: i128::from(m.mtime()) * 1_000_000_000 + i128::from(m.mtime_nsec()),
        })
    }
}

/// Describes how a process ended, as the orchestrator prints it.
pub fn describe(status: ExitStatus) -> String {
    match (status.code(), status.signal()) {
        (Some(c), _) => format!("exited with code {c}"),
        (None, Some(9)) => "was killed (SIGKILL)".to_string(),
        (None, Some(s)) => format!("was killed by signal {s}"),
        _ => "exited".to_string(),
    }
}

/// The default folder of a daemon's runs: `$XDG_RUNTIME_DIR/formation/host-<name>`, else
/// `/tmp/formation-host-<uid>-<name>`.
pub fn default_root(name: &str) -> PathBuf {
    match std::env::var_os("XDG_RUNTIME_DIR") {
        Some(d) if !d.is_empty() => PathBuf::from(d)
            .join("formation")
            .join(format!("host-{name}")),
        // SAFETY: getuid has no preconditions.
        _ => std::env::temp_dir().join(format!("formation-host-{}-{name}", unsafe {
            libc::getuid()
        })),
    }
}

/// Creates `dir` owner-only (mode 0700), refusing a symbolic link or another user's folder.
fn private_dir(dir: &Path) -> Result<(), FolderError> {
    use std::os::unix::fs::{DirBuilderExt, MetadataExt, PermissionsExt};
    let _ = std::fs::DirBuilder::new()
        .recursive(true)
        .mode(0o700)
        .create(dir);
    let io = |source| FolderError::Io {
        dir: dir.to_path_buf(),
        source,
    };
    let m = std::fs::symlink_metadata(dir).map_err(io)?;
    // SAFETY: getuid has no preconditions.
    if !m.is_dir() || m.uid() != unsafe { libc::getuid() } {
        return Err(FolderError::NotOwn(dir.to_path_buf()));
    }
    std::fs::set_permissions(dir, std::fs::Permissions::from_mode(0o700)).map_err(io)
}

/// Whether `name` can name a daemon: a key-safe host name ([`proto::valid_name`]) other than the
/// launcher's own.
pub fn check_name(name: &str) -> Result<(), ServeError> {
    if !proto::valid_name(name) || name == formation_net::cluster::LAUNCHER {
        return Err(ServeError::Name {
            name: name.to_string(),
            launcher: formation_net::cluster::LAUNCHER,
        });
    }
    Ok(())
}

/// Runs the daemon until `stop` is set (SIGINT/SIGTERM). `Err`: it could not start.
pub fn serve(o: DaemonOptions, stop: &AtomicBool) -> Result<(), ServeError> {
    check_name(&o.name)?;
    private_dir(&o.root)?;
    sweep_stale(&o.root);
    // The token, the requests, the clock probe (answered at once, in Zenoh's thread) and the
    // orchestrators' tokens (formation_net::daemon_link).
    let link = DaemonLink::open(&o.session, &o.name)?;
    let me = identity::local();
    eprintln!(
        "formation host: {} listening on {} (pid {}, build {}, protocol {}, {} CPUs); runs in {}",
        o.name,
        o.session.listen.join(" "),
        std::process::id(),
        me.build,
        me.protocol,
        cpus(),
        o.root.display()
    );
    for w in o.session.warnings() {
        eprintln!("formation host: {w}");
    }
    let mut d = Daemon {
        o,
        out: link.outbox(),
        me,
        runs: HashMap::new(),
        log: LogLimit::default(),
        facts: Facts::here(),
    };
    // Runs whose orchestrator's token is alive (its Put may come before its run is prepared).
    let mut alive: std::collections::HashSet<String> = std::collections::HashSet::new();
    while !stop.load(Ordering::SeqCst) {
        if let Some(q) = link.next_query(Duration::from_millis(20)) {
            // The request's bytes (up to what the link accepts, tens of MiB from a stranger) are
            // freed before the reply, which ends the query: the querier sees the daemon's memory
            // as it is between requests.
            let answer = if q.asks_info() {
                serde_json::to_vec(&d.info()).unwrap()
            } else {
                d.request(&q.payload())
            };
            q.reply(answer);
        }
        while let Some(change) = link.orchestrator() {
            match change {
                Orchestrator::Alive(run) => {
                    alive.insert(run);
                }
                Orchestrator::Gone(run) => {
                    alive.remove(&run);
                    if d.runs.contains_key(&run) {
                        eprintln!("formation host: run {run}: its orchestrator is gone; ending it");
                        d.end(&run);
                    }
                }
            }
        }
        d.reap();
        d.forward_checkpoints();
        let stale: Vec<String> = d
            .runs
            .iter()
            .filter(|(id, r)| !alive.contains(*id) && r.prepared.elapsed() > ORCHESTRATOR_WAIT)
            .map(|(k, _)| k.clone())
            .collect();
        for run in stale {
            eprintln!("formation host: run {run}: no orchestrator within {ORCHESTRATOR_WAIT:?}; ending it");
            d.end(&run);
        }
    }
    let ids: Vec<String> = d.runs.keys().cloned().collect();
    for run in ids {
        d.end(&run);
    }
    Ok(())
}

/// Removes run folders a killed daemon left (their members lock is free: nobody is in the run).
fn sweep_stale(root: &Path) {
    let Ok(rd) = std::fs::read_dir(root) else {
        return;
    };
    for e in rd.flatten() {
        let dir = e.path();
        let lock = formation_config::node::members::lock_path(&dir);
        let prefix = services::run_prefix(&e.file_name().to_string_lossy());
        match Membership::join(&dir, &prefix) {
            Ok(m) => {
                if let Some(r) = m.leave_last() {
                    let _ = r;
                    let _ = std::fs::remove_dir_all(&dir);
                }
            }
            Err(_) if !lock.exists() => {
                let _ = std::fs::remove_dir_all(&dir);
            }
            Err(_) => {}
        }
    }
}

fn cpus() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

struct Daemon {
    o: DaemonOptions,
    /// Reports and bridges go out here (formation_net::daemon_link).
    out: Outbox,
    me: Identity,
    runs: HashMap<String, HostRun>,
    /// Refusals are logged at most once a second per reason.
    log: LogLimit,
    /// Its shared memory place, user and iceoryx2 root ([`formation_net::colocate`]).
    facts: Facts,
}

/// A request that is no frame of a request: refused as `malformed`, saying why.
fn malformed(e: proto::FrameError) -> (&'static str, String) {
    ("malformed", e.to_string())
}

fn refused(why: String) -> Vec<u8> {
    serde_json::to_vec(&Reply::Refused(why)).unwrap()
}

fn ok(pid: Option<u32>) -> Vec<u8> {
    serde_json::to_vec(&Reply::Ok { pid }).unwrap()
}

impl Daemon {
    fn info(&self) -> HostInfo {
        HostInfo {
            name: self.o.name.clone(),
            cpus: cpus(),
            listen: self.o.session.listen.clone(),
            runs: self.runs.len(),
            pid: std::process::id(),
            identity: self.me.clone(),
            clock_us: proto::now_us(),
            shm: self.facts.shm.clone(),
            uid: self.facts.uid,
            iox2_root: self.facts.iox2_root.clone(),
        }
    }

    /// Serves one request; a refusal changes nothing. A request about a run (all but `Prepare`)
    /// must carry proof of the run's secret for this host with a sequence number not seen before
    /// ([`formation_net::auth`]): without it nothing is done. Replies about a run carry proof too.
    fn request(&mut self, bytes: &[u8]) -> Vec<u8> {
        match self.authenticated(bytes) {
            Ok((req, rest, seq)) => {
                // Replies are sealed with the key of the run asked about, or of the run a
                // `Prepare` has just created (not of one it was refused for).
                let (run_id, prepares) = match &req {
                    Request::Prepare(p) => (p.run_id.clone(), true),
                    r => (r.run_id().unwrap_or_default().to_string(), false),
                };
                // Taken before: `End` removes the run.
                let before = self.runs.get(&run_id).map(|r| r.key.clone());
                let result = self.dispatch(req, &rest);
                let key = match prepares {
                    true if result.is_ok() => self.runs.get(&run_id).map(|r| r.key.clone()),
                    true => None,
                    false => before,
                };
                let mut reply = result.unwrap_or_else(|e| {
                    self.log.eprint("requests", "refused", || {
                        format!("formation host: refused: {e}")
                    });
                    refused(e.to_string())
                });
                if let Some(k) = key {
                    k.seal(Purpose::Reply, &self.o.name, seq, &mut reply);
                }
                reply
            }
            Err((reason, why)) => {
                self.log.eprint("requests", reason, || {
                    format!("formation host: refused: {why}")
                });
                refused(why)
            }
        }
    }

    /// The request in `bytes`, the bytes after it and its sequence number (0 for `Prepare`), if
    /// it may be served: `Err((reason, why))` otherwise.
    fn authenticated(
        &mut self,
        bytes: &[u8],
    ) -> Result<(Request, Vec<u8>, u64), (&'static str, String)> {
        if bytes.len() > MAX_REQUEST {
            return Err((
                "oversized",
                format!("a request of {} bytes (at most {MAX_REQUEST})", bytes.len()),
            ));
        }
        let (req, _): (Request, &[u8]) = proto::decode_frame(bytes).map_err(malformed)?;
        let Some(run_id) = req.run_id().map(str::to_string) else {
            let (req, rest) = proto::decode_frame::<Request>(bytes).map_err(malformed)?;
            return Ok((req, rest.to_vec(), 0));
        };
        let me = self.o.name.clone();
        let r = self
            .runs
            .get_mut(&run_id)
            .ok_or_else(|| ("unknown run", format!("no run {run_id} on host {me}")))?;
        let (body, seq) = r.key.open(Purpose::Request, &me, bytes).map_err(|e| {
            (
                "no proof",
                format!("a request about run {run_id} refused: {e}"),
            )
        })?;
        r.replay.accept(seq).map_err(|e| {
            (
                "replayed",
                format!("a request about run {run_id} refused: {e}"),
            )
        })?;
        let (req, rest) = proto::decode_frame::<Request>(body).map_err(malformed)?;
        if req.run_id() != Some(run_id.as_str()) {
            return Err(("malformed", "a request changed its run".into()));
        }
        Ok((req, rest.to_vec(), seq))
    }

    /// Does what an accepted request asks.
    fn dispatch(&mut self, req: Request, rest: &[u8]) -> Result<Vec<u8>, Refusal> {
        match req {
            Request::Prepare(r) => self.prepare(r).map(|_| ok(None)),
            Request::Spawn {
                run_id,
                agent,
                rejoin_at,
            } => self
                .spawn(&run_id, agent, rejoin_at, rest)
                .map(|pid| ok(Some(pid))),
            Request::Kill { run_id, agent } => self.kill(&run_id, agent).map(|_| ok(None)),
            Request::Signal {
                run_id,
                agent,
                signal,
            } => self.signal(&run_id, agent, signal).map(|_| ok(None)),
            Request::Stopped { run_id, agent } => self.stopped(&run_id, agent),
            Request::Checkpoint { run_id, agent } => self.checkpoint(&run_id, agent),
            Request::Replan {
                run_id,
                agent_hosts,
            } => self.replan(&run_id, agent_hosts).map(|_| ok(None)),
            Request::Report { run_id } => self.report(&run_id),
            Request::End { run_id } => {
                if self.runs.contains_key(&run_id) {
                    self.end(&run_id);
                }
                Ok(ok(None))
            }
        }
    }

    /// Run `run_id`, whose agent `agent` (0-based) is placed on this host.
    fn placed_here(&mut self, run_id: &str, agent: usize) -> Result<&mut HostRun, Refusal> {
        let me = self.o.name.clone();
        let r = self.run(run_id)?;
        if r.req.agent_hosts.get(agent) != Some(&me) {
            return Err(Refusal::NotPlacedHere {
                agent: agent.saturating_add(1),
                run: run_id.to_string(),
                host: me,
            });
        }
        Ok(r)
    }

    fn run(&mut self, run_id: &str) -> Result<&mut HostRun, Refusal> {
        self.runs.get_mut(run_id).ok_or_else(|| Refusal::NoRun {
            run: run_id.to_string(),
            host: self.o.name.clone(),
        })
    }

    /// Checks a run request against this daemon before anything of the run is made: its build,
    /// ids, scenario, placement and limits, and (co-located) this host's `/dev/shm`. Returns the
    /// request with the real-time priority this daemon grants, its scenario and its variant.
    fn admit(&self, r: RunRequest) -> Result<(RunRequest, Scenario, Variant), Refusal> {
        let diff = identity::differences(&r.identity, &self.me);
        if !diff.is_empty() {
            return Err(Refusal::Differ {
                host: self.o.name.clone(),
                differences: diff,
            });
        }
        if r.run_id.is_empty()
            || r.run_id.len() > 16
            || !r.run_id.bytes().all(|b| b.is_ascii_hexdigit())
        {
            return Err(Refusal::RunId(r.run_id.clone()));
        }
        if r.prefix != services::run_prefix(&r.run_id) {
            return Err(Refusal::Prefix {
                prefix: r.prefix.clone(),
                expected: services::run_prefix(&r.run_id),
            });
        }
        if self.runs.contains_key(&r.run_id) {
            return Err(Refusal::AlreadyPrepared(r.run_id.clone()));
        }
        let scenario = Scenario::from_toml_str(&r.scenario_toml)?;
        formation_config::scenario::validate::validate(&scenario)?;
        let n = scenario.n_agents();
        if n > formation_config::MAX_AGENTS {
            return Err(Refusal::TooManyAgents {
                n,
                max: formation_config::MAX_AGENTS,
            });
        }
        let variant =
            Variant::parse(&r.variant).ok_or_else(|| Refusal::Variant(r.variant.clone()))?;
        if r.agent_hosts.len() != n {
            return Err(Refusal::AgentHosts {
                hosts: r.agent_hosts.len(),
                n,
            });
        }
        if !r.agent_hosts.iter().all(|h| proto::valid_name(h)) || !proto::valid_name(&r.launcher) {
            return Err(Refusal::NotKeySafe);
        }
        if !r.agent_hosts.contains(&self.o.name) {
            return Err(Refusal::NothingHere(self.o.name.clone()));
        }
        if r.rt_priority > 99 {
            return Err(Refusal::RtPriority(r.rt_priority));
        }
        let mut r = r;
        if r.rt_priority > self.o.max_rt_priority {
            eprintln!(
                "formation host: run {}: asks for real-time priority {}; granted {} (--max-rt-priority)",
                r.run_id, r.rt_priority, self.o.max_rt_priority
            );
            r.rt_priority = self.o.max_rt_priority;
        }
        if r.observers > services::MAX_OBSERVERS + 1 {
            return Err(Refusal::Observers {
                given: r.observers,
                max: services::MAX_OBSERVERS + 1,
            });
        }
        if let Some(c) = &r.colocated {
            self.check_colocated(&r, c)?;
        }
        Ok((r, scenario, variant))
    }

    /// Prepares a run ([`Daemon::admit`]ted): its private folder and scenario, and unless it is
    /// co-located its membership, node and bridge.
    fn prepare(&mut self, r: RunRequest) -> Result<(), Refusal> {
        let (r, scenario, variant) = self.admit(r)?;
        let n = scenario.n_agents();
        let dir = self.o.root.join(&r.run_id);
        // The daemon's own log names the folder; the refusal does not.
        private_dir(&dir).map_err(|e| {
            eprintln!("formation host: run {}: {e}", r.run_id);
            Refusal::RunFolder
        })?;
        let fail = |e: Refusal, dir: &Path| {
            let _ = std::fs::remove_dir_all(dir);
            e
        };
        std::fs::write(dir.join("scenario.toml"), &r.scenario_toml)
            .map_err(|e| fail(Refusal::WriteScenario(e), &dir))?;
        if r.colocated.is_some() {
            eprintln!(
                "formation host: run {} prepared (co-located: the orchestrator's services in this /dev/shm, no bridge): agents {:?} here",
                r.run_id,
                own_agents(&r.agent_hosts, &self.o.name)
            );
            self.insert(r, dir, variant, None, None, None);
            return Ok(());
        }
        let membership =
            Membership::create(&dir, &r.prefix).map_err(|e| fail(Refusal::Membership(e), &dir))?;
        let node = ipc::node(&r.prefix, "fm-host").map_err(|e| fail(e.into(), &dir))?;
        let placement = Placement {
            agent_hosts: r.agent_hosts.clone(),
            launcher: r.launcher.clone(),
            neighbours: Placement::neighbours_of(
                n,
                scenario.graph.edges.iter().map(|e| (e.a, e.b)),
            ),
        };
        let bridge = self.out.bridge(BridgeConfig {
            run_id: r.run_id.clone(),
            prefix: r.prefix.clone(),
            me: self.o.name.clone(),
            placement,
            sizing: Sizing::for_scenario(&scenario, r.realtime, r.observers),
            create: true,
            key: r.secret.keys(&r.run_id),
            clock_offsets_ns: r.clock_offsets_ns.clone(),
            rt_priority: if r.realtime { r.rt_priority } else { 0 },
        });
        let bridge = match bridge {
            Ok(b) => b,
            Err(e) => {
                drop(node);
                drop(membership);
                let _ = ipc::remove_residue(&r.prefix);
                return Err(fail(e.into(), &dir));
            }
        };
        eprintln!(
            "formation host: run {} prepared: agents {:?} here, {} services forwarded out, {} in",
            r.run_id,
            own_agents(&r.agent_hosts, &self.o.name),
            bridge.forwarded.0,
            bridge.forwarded.1
        );
        if r.realtime {
            eprintln!(
                "formation host: run {}: {}",
                r.run_id,
                bridge.scheduling.describe()
            );
        }
        self.insert(r, dir, variant, Some(bridge), Some(node), Some(membership));
        Ok(())
    }

    /// Checks a co-located run ([`colocate`]) against this host's own `/dev/shm`, user and
    /// iceoryx2 root before anything of it is made: the orchestrator's services must be here and
    /// this user's, its iceoryx2 root this daemon's, its membership lock a private file of this
    /// user. A flag alone makes nobody's services reachable.
    fn check_colocated(&self, r: &RunRequest, c: &proto::Colocated) -> Result<(), Refusal> {
        let euid = colocate::euid();
        let mine = self.facts.iox2_root.clone().unwrap_or_default();
        if c.iox2_root != mine {
            return Err(colocate::ServicesError::OtherRoot {
                theirs: c.iox2_root.clone(),
                mine,
            }
            .into());
        }
        let entries = colocate::shm_entries()?;
        let n = colocate::check_services(&entries, &r.prefix, euid)?;
        colocate::check_members(&c.members, euid).map_err(|e| {
            // The daemon's own log names the path; the refusal does not.
            eprintln!("formation host: run {}: {e}", r.run_id);
            Refusal::Members
        })?;
        eprintln!(
            "formation host: run {}: co-located: {n} shared memory files of {} here, uid {euid}",
            r.run_id, r.prefix
        );
        Ok(())
    }

    /// Records a prepared run.
    fn insert(
        &mut self,
        r: RunRequest,
        dir: PathBuf,
        variant: Variant,
        bridge: Option<Bridge>,
        node: Option<RunNode>,
        membership: Option<Membership>,
    ) {
        self.runs.insert(
            r.run_id.clone(),
            HostRun {
                key: r.secret.keys(&r.run_id),
                replay: Replay::default(),
                reports: 0,
                scenario_hash: restart::scenario_hash(r.scenario_toml.as_bytes()),
                variant: variant.name().to_string(),
                req: r,
                dir,
                children: HashMap::new(),
                prepared: Instant::now(),
                forwarded: HashMap::new(),
                bridge,
                node,
                membership,
            },
        );
    }

    fn spawn(
        &mut self,
        run_id: &str,
        agent: usize,
        rejoin_at: Option<u64>,
        rejoin: &[u8],
    ) -> Result<u32, Refusal> {
        let exe = self.o.exe.clone();
        let r = self.placed_here(run_id, agent)?;
        if r.children.contains_key(&agent) {
            return Err(Refusal::Running {
                agent: agent + 1,
                run: run_id.to_string(),
            });
        }
        if let Some(at) = rejoin_at {
            // Verified like a checkpoint before it is written or any process reads it.
            let file =
                restart::decode_rejoin(rejoin, agent, r.scenario_hash, at).map_err(|why| {
                    Refusal::Rejoin {
                        agent: agent + 1,
                        why,
                    }
                })?;
            restart::write_rejoin(&restart::rejoin_path(&r.dir, agent), r.scenario_hash, &file)
                .map_err(|e| Refusal::WriteRejoin {
                    agent: agent + 1,
                    kind: e.kind(),
                })?;
        }
        let args = ChildArgs {
            run_id: r.req.run_id.clone(),
            prefix: r.req.prefix.clone(),
            run_dir: r.dir.clone(),
            variant: r.variant.clone(),
            agent: Some(agent),
            realtime: r.req.realtime,
            spin_us: 0,
            rt_priority: r.req.rt_priority,
            rejoin_at,
            members: r.req.colocated.as_ref().map(|c| c.members.clone()),
        };
        let mut cmd = Command::new(&exe);
        cmd.arg0(Role::Agent.process_name(Some(agent)))
            .args(["node", Role::Agent.name()])
            .args(args.to_args())
            .stdin(Stdio::null());
        // SAFETY: only async-signal-safe calls between fork and exec.
        unsafe {
            cmd.pre_exec(|| {
                formation_config::node::process::die_with_parent_ignore_sigint();
                Ok(())
            });
        }
        let child = cmd.spawn().map_err(|source| Refusal::Start {
            agent: agent + 1,
            source,
        })?;
        let pid = child.id();
        r.children.insert(agent, child);
        eprintln!(
            "formation host: run {run_id}: agent {} started, pid {pid}",
            agent + 1
        );
        Ok(pid)
    }

    fn kill(&mut self, run_id: &str, agent: usize) -> Result<(), Refusal> {
        // Idempotent: a run already ended has no process left to kill.
        let Some(r) = self.runs.get_mut(run_id) else {
            return Ok(());
        };
        if let Some(mut c) = r.children.remove(&agent) {
            let _ = c.kill();
            let _ = c.wait();
        }
        if let Some(n) = &r.node {
            n.try_cleanup_dead_nodes();
        }
        Ok(())
    }

    fn signal(&mut self, run_id: &str, agent: usize, signal: i32) -> Result<(), Refusal> {
        if signal != libc::SIGSTOP && signal != libc::SIGCONT {
            return Err(Refusal::Signal(signal));
        }
        let r = self.run(run_id)?;
        let c = r
            .children
            .get(&agent)
            .ok_or(Refusal::NotRunning(agent + 1))?;
        // SAFETY: kill(2) on our own unreaped child.
        unsafe { libc::kill(c.id() as libc::pid_t, signal) };
        Ok(())
    }

    fn stopped(&mut self, run_id: &str, agent: usize) -> Result<Vec<u8>, Refusal> {
        let r = self.run(run_id)?;
        let c = r
            .children
            .get(&agent)
            .ok_or(Refusal::NotRunning(agent + 1))?;
        let stopped = formation_config::node::process::is_stopped(c.id());
        Ok(proto::frame(
            &Reply::Ok { pid: Some(c.id()) },
            &[u8::from(stopped)],
        ))
    }

    fn checkpoint(&mut self, run_id: &str, agent: usize) -> Result<Vec<u8>, Refusal> {
        let r = self.placed_here(run_id, agent)?;
        let path = restart::checkpoint_path(&r.dir, agent);
        let bytes = std::fs::read(&path).map_err(|e| Refusal::Checkpoint {
            agent: agent + 1,
            kind: e.kind(),
        })?;
        Ok(proto::frame(&Reply::Ok { pid: None }, &bytes))
    }

    /// A host of the run was lost and its agents moved: re-plans this host's bridge for the new
    /// placement. Only the agents of the lost host may move, and not onto this host (a moved
    /// agent goes to the launcher, `Placement::after_loss`); its own agents stay.
    fn replan(&mut self, run_id: &str, agent_hosts: Vec<String>) -> Result<(), Refusal> {
        let me = self.o.name.clone();
        let r = self.run(run_id)?;
        if agent_hosts.len() != r.req.agent_hosts.len()
            || !agent_hosts.iter().all(|h| proto::valid_name(h))
        {
            return Err(Refusal::ReplanShape {
                run: run_id.to_string(),
                hosts: agent_hosts.len(),
                agents: r.req.agent_hosts.len(),
            });
        }
        for (i, (was, now)) in r.req.agent_hosts.iter().zip(&agent_hosts).enumerate() {
            if was != now && (*was == me || *now == me) {
                return Err(Refusal::ReplanMove {
                    run: run_id.to_string(),
                    agent: i + 1,
                    was: was.clone(),
                    now: now.clone(),
                });
            }
        }
        let scenario = Scenario::from_toml_str(&r.req.scenario_toml)?;
        let placement = Placement {
            agent_hosts: agent_hosts.clone(),
            launcher: r.req.launcher.clone(),
            neighbours: Placement::neighbours_of(
                scenario.n_agents(),
                scenario.graph.edges.iter().map(|e| (e.a, e.b)),
            ),
        };
        let forwarded = match r.bridge.as_mut() {
            Some(b) => b.replan(&placement)?,
            None => (0, 0),
        };
        r.req.agent_hosts = agent_hosts;
        eprintln!(
            "formation host: run {run_id} re-planned: agents {:?} placed elsewhere now; {} services forwarded out, {} in",
            r.req
                .agent_hosts
                .iter()
                .enumerate()
                .filter(|(_, h)| **h != me)
                .map(|(i, h)| format!("{}@{h}", i + 1))
                .collect::<Vec<_>>(),
            forwarded.0,
            forwarded.1
        );
        Ok(())
    }

    /// Sends the orchestrator every checkpoint file its agents wrote since the last call (each a
    /// whole file: the agents write to a temporary name and rename), so the orchestrator holds a
    /// copy of each agent's latest checkpoint and a warm takeover works when this host is gone.
    fn forward_checkpoints(&mut self) {
        let mut notes = Vec::new();
        for (id, r) in self.runs.iter_mut() {
            for &agent in r.children.keys() {
                let path = restart::checkpoint_path(&r.dir, agent);
                let Some(stamp) = FileStamp::of(&path) else {
                    continue;
                };
                if r.forwarded.get(&agent) == Some(&stamp) {
                    continue;
                }
                r.forwarded.insert(agent, stamp);
                let Ok(bytes) = std::fs::read(&path) else {
                    continue;
                };
                match restart::decode_checkpoint(&bytes, agent, r.scenario_hash) {
                    Ok(c) => notes.push((
                        id.clone(),
                        proto::CheckpointNote {
                            host: self.o.name.clone(),
                            agent,
                            step: c.step,
                        },
                        bytes,
                    )),
                    Err(e) => eprintln!(
                        "formation host: run {id}: agent {}'s checkpoint not forwarded: {e}",
                        agent + 1
                    ),
                }
            }
        }
        for (id, note, bytes) in notes {
            let key = proto::run_checkpoint(&id);
            let Some(msg) = self.sealed_report(&id, &key, proto::frame(&note, &bytes)) else {
                continue;
            };
            self.out.put(key, msg);
        }
    }

    /// The run's timing files on this host (its agents', once they have stopped, and its bridge's
    /// link delays as `bridge-<host>.json`).
    fn report(&mut self, run_id: &str) -> Result<Vec<u8>, Refusal> {
        let me = self.o.name.clone();
        let r = self.run(run_id)?;
        // The agents write their files when they stop: give them the grace of an ending run.
        wait_for_exit(&mut r.children, STOP_GRACE);
        if let Some(b) = &r.bridge {
            b.link_report()
                .write(&r.dir, &format!("bridge-{me}"))
                .map_err(Refusal::TimingReport)?;
        }
        let mut out = proto::HostReport::default();
        let dir = formation_config::node::timing::dir(&r.dir);
        for e in std::fs::read_dir(&dir)
            .map_err(|e| Refusal::TimingFolder(e.kind()))?
            .flatten()
        {
            let name = e.file_name().to_string_lossy().into_owned();
            if name.ends_with(".json") {
                let text = std::fs::read_to_string(e.path()).map_err(|x| Refusal::TimingFile {
                    name: name.clone(),
                    kind: x.kind(),
                })?;
                out.timing.insert(name, text);
            }
        }
        Ok(proto::frame(
            &Reply::Ok { pid: None },
            &serde_json::to_vec(&out).unwrap(),
        ))
    }

    /// Reaps exited children and reports them.
    fn reap(&mut self) {
        let mut reports = Vec::new();
        for (id, r) in self.runs.iter_mut() {
            let mut gone = Vec::new();
            for (&agent, c) in r.children.iter_mut() {
                if let Ok(Some(st)) = c.try_wait() {
                    gone.push(agent);
                    reports.push((
                        id.clone(),
                        ExitReport {
                            host: self.o.name.clone(),
                            agent,
                            pid: c.id(),
                            how: describe(st),
                        },
                    ));
                }
            }
            for a in &gone {
                r.children.remove(a);
            }
            if !gone.is_empty() {
                if let Some(n) = &r.node {
                    n.try_cleanup_dead_nodes();
                }
            }
        }
        for (id, rep) in reports {
            let key = proto::run_exit(&id);
            let Some(msg) = self.sealed_report(&id, &key, serde_json::to_vec(&rep).unwrap()) else {
                continue;
            };
            self.out.put(key, msg);
        }
    }

    /// `msg` with the proof of run `id`'s secret for key expression `key` (see [`formation_net::auth`]).
    fn sealed_report(&mut self, id: &str, key: &str, mut msg: Vec<u8>) -> Option<Vec<u8>> {
        let r = self.runs.get_mut(id)?;
        r.reports += 1;
        r.key.seal(Purpose::Report, key, r.reports, &mut msg);
        Some(msg)
    }

    /// Ends a run: its processes get [`STOP_GRACE`] to exit, then SIGKILL; bridge stopped; every
    /// iceoryx2 file of its prefix and its folder removed.
    fn end(&mut self, run_id: &str) {
        let Some(mut r) = self.runs.remove(run_id) else {
            return;
        };
        wait_for_exit(&mut r.children, STOP_GRACE);
        for c in r.children.values_mut() {
            let _ = c.kill();
            let _ = c.wait();
        }
        r.children.clear();
        drop(r.bridge.take());
        drop(r.node.take());
        drop(r.membership.take());
        let _ = std::fs::remove_dir_all(&r.dir);
        if let Some(c) = &r.req.colocated {
            // The files are the orchestrator's: it removes them, or the last process of the run
            // does. Its agents here were members of its run, ended here without leaving it as a
            // member does: the daemon leaves in their place, and removes the files if nobody of
            // the run is left (the orchestrator SIGKILLed, its other processes gone before).
            let last = Membership::join_file(Path::new(&c.members), &r.req.prefix)
                .ok()
                .and_then(Membership::leave_last);
            match last {
                Some(Ok(n)) if n > 0 => eprintln!("formation host: run {run_id} ended; its folder and {n} iceoryx2 files removed (co-located, and the last of its run: its orchestrator is gone)"),
                _ => eprintln!("formation host: run {run_id} ended; its folder removed (co-located: its iceoryx2 files are the orchestrator's)"),
            }
            return;
        }
        let removed = ipc::remove_residue(&r.req.prefix).unwrap_or(0);
        eprintln!(
            "formation host: run {run_id} ended; {removed} iceoryx2 files and its folder removed"
        );
    }
}

/// The 1-based ids of the agents placed on `me`.
fn own_agents(agent_hosts: &[String], me: &str) -> Vec<usize> {
    agent_hosts
        .iter()
        .enumerate()
        .filter(|(_, h)| *h == me)
        .map(|(i, _)| i + 1)
        .collect()
}

/// Gives `children` up to `grace` to exit by themselves (polled every 10 ms).
fn wait_for_exit(children: &mut HashMap<usize, Child>, grace: Duration) {
    let deadline = Instant::now() + grace;
    while Instant::now() < deadline
        && children
            .values_mut()
            .any(|c| matches!(c.try_wait(), Ok(None)))
    {
        std::thread::sleep(Duration::from_millis(10));
    }
}
