//! Zenoh sessions of this project: which mode, which endpoints, credentials, threads.
//!
//! * Endpoints: `unixsock-stream/PATH` (a Unix socket), `tcp/HOST:PORT` (plaintext, with Zenoh
//!   user/password authentication), `tls/HOST:PORT` (mutual TLS over TCP, [`crate::tls`]) and
//!   `quic/HOST:PORT` (QUIC over UDP: the same certificates and mutual TLS 1.3).
//! * A daemon's default endpoint is a Unix socket named after it in its user's private runtime
//!   folder ([`local_dir`]: `$XDG_RUNTIME_DIR/formation/`, else `/tmp/formation-<uid>/`, mode
//!   0700, owned by that user, never a link): the kernel lets only that user (and root) connect.
//!   An orchestrator or `formation hosts` of the same user finds it there by host name.
//! * Every `tcp/` endpoint (loopback included) needs `--auth FILE`; every `tls/` endpoint needs
//!   `--tls DIR`, and so does every `quic/` endpoint; a Unix socket in a folder others can enter needs `--auth`. The only exception:
//!   a run's telemetry export ([`Mode::Export`]) may listen on TCP loopback without `--auth`.
//! * Before a TLS or QUIC link is opened, a pre-flight handshake ([`crate::tls::preflight`],
//!   [`crate::tls::preflight_quic`]) checks the peer's certificate against this host's CA alone
//!   and names whoever refused whom; after a failure, [`diagnose`] tells an authentication
//!   failure from an unreachable endpoint.
//! * Multicast scouting is off: hosts are joined by explicit endpoints only.
//! * Zenoh's runtimes default to six worker threads per process; on small machines
//!   [`bound_threads`] caps each runtime at one worker unless `ZENOH_RUNTIME` is already set.

use crate::tls::{self, Material, TlsRefusal};
use formation_config::node::files;
use std::os::unix::fs::MetadataExt;
use std::path::{Path, PathBuf};
use std::time::Duration;
use zenoh::Wait;

/// Default port of `formation host --listen tcp/…`, `tls/…` and `quic/…` in the docs' examples.
pub const DEFAULT_PORT: u16 = 7447;

/// Extension of a daemon's socket in [`local_dir`].
pub const SOCKET_EXT: &str = "sock";

/// Longest path of a Unix socket (`sun_path` holds 108 bytes with the final NUL).
pub const MAX_SOCKET_PATH: usize = 107;

/// Default lease: a host whose link is silent this long is declared lost (Zenoh
/// `transport/link/tx/lease`). A killed process is seen at once (its link closes).
pub const DEFAULT_LEASE_MS: u64 = 3000;

/// How long [`diagnose`] gives a probe session to be admitted.
pub const PROBE_TIMEOUT: Duration = Duration::from_secs(2);

/// Role of a session in the topology.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mode {
    /// A host daemon (and its bridge): a router that listens. Not a peer: a Zenoh 1.10 router
    /// keeps the peers connected to it in one region that it takes to be a full mesh and never
    /// relays data from one of them to another, so two daemons that cannot reach each other
    /// directly would exchange nothing. Routers route over their links (link state), so traffic
    /// between two daemons goes through the orchestrator's router.
    Daemon,
    /// The launching orchestrator: a router that connects to every daemon and relays between them.
    Orchestrator,
    /// `formation hosts`: a client that connects, asks and leaves.
    Client,
    /// `formation run --zenoh-listen`: a run's telemetry for outside readers ([`crate::export`]),
    /// a peer that listens and, like a daemon, admits only the users of its `--auth` file.
    Export,
}

/// What a session is opened with.
#[derive(Debug, Clone)]
pub struct Options {
    /// Topology role.
    pub mode: Mode,
    /// Endpoints to listen on.
    pub listen: Vec<String>,
    /// Endpoints to connect to.
    pub connect: Vec<String>,
    /// `user:password` file (mode 0600): the daemon's accepted users, the orchestrator's credentials
    /// (its first line).
    pub auth: Option<PathBuf>,
    /// `--tls DIR`: CA certificate, this host's certificate and key ([`crate::tls::Material`]).
    pub tls: Option<PathBuf>,
    /// Link lease, ms.
    pub lease_ms: u64,
}

/// What a `tls/` link risks with Zenoh 1.10 (docs/multi-host.md, "Known problem of Zenoh 1.10.2's
/// TLS link"): its sending and receiving tasks share one rustls connection without a lock
/// (eclipse-zenoh/zenoh#2557). Under traffic the link drops (the run names the host as lost) or
/// the process aborts on corrupted memory (seen: a daemon's "memory allocation of 140257123150048
/// bytes failed" in rustls under `zenoh_link_tls` beside two CPU-bound loops). `quic/` takes the
/// same `--tls` folder and shares nothing unlocked between its tasks.
pub const TLS_LINK_RISK: &str = "Zenoh 1.10's TLS link is unsound (eclipse-zenoh/zenoh#2557: one \
rustls connection shared by two tasks without a lock): under traffic the link can drop or this \
process abort; quic/HOST:PORT takes the same --tls folder without that race (docs/multi-host.md)";

impl Options {
    /// Warnings about options that are accepted but risky: a `tls/` endpoint ([`TLS_LINK_RISK`]).
    /// One line each, without the program's prefix.
    pub fn warnings(&self) -> Vec<String> {
        let tls: Vec<&str> = self
            .listen
            .iter()
            .chain(&self.connect)
            .map(String::as_str)
            .filter(|e| e.starts_with("tls/"))
            .collect();
        if tls.is_empty() {
            return Vec::new();
        }
        vec![format!("warning: {}: {TLS_LINK_RISK}", tls.join(" "))]
    }
}

/// Zenoh access control of a daemon: no link may declare a queryable or a liveliness token on a
/// daemon's keys (`formation/host/**`, `formation/clock/**`). Only the daemon itself answers its
/// requests, so a holder of its credentials cannot stand in for it and receive the `Prepare`
/// (and the secret) of another tenant's run, nor pose as a daemon. Declarations only: no rule is
/// checked per message.
pub const DAEMON_ACCESS_CONTROL: &str = r#"{
  enabled: true,
  default_permission: "allow",
  rules: [{
    id: "daemon-keys",
    permission: "deny",
    flows: ["ingress"],
    messages: ["declare_queryable", "liveliness_token"],
    key_exprs: ["formation/host/**", "formation/clock/**"],
  }],
  subjects: [{ id: "every-link" }],
  policies: [{ rules: ["daemon-keys"], subjects: ["every-link"] }],
}"#;

/// A parsed endpoint.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Endpoint {
    /// `unixsock-stream/PATH`.
    Unix(PathBuf),
    /// `tcp/HOST:PORT`.
    Tcp {
        /// Host name or address (IPv6 in brackets).
        host: String,
        /// Port.
        port: u16,
    },
    /// `tls/HOST:PORT`.
    Tls {
        /// Host name or address (IPv6 in brackets).
        host: String,
        /// Port.
        port: u16,
    },
    /// `quic/HOST:PORT` (a UDP port).
    Quic {
        /// Host name or address (IPv6 in brackets).
        host: String,
        /// Port.
        port: u16,
    },
}

impl Endpoint {
    /// Whether the endpoint is a TCP, TLS or QUIC one on a loopback address.
    pub fn is_loopback(&self) -> bool {
        let host = match self {
            Endpoint::Unix(_) => return false,
            Endpoint::Tcp { host, .. }
            | Endpoint::Tls { host, .. }
            | Endpoint::Quic { host, .. } => host,
        };
        let host = host.trim_start_matches('[').trim_end_matches(']');
        host == "localhost"
            || host
                .parse::<std::net::IpAddr>()
                .is_ok_and(|a| a.is_loopback())
    }
}

/// Why a session's options are refused, or its link failed.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum OptionError {
    /// A malformed endpoint.
    Endpoint {
        /// The endpoint as given.
        endpoint: String,
        /// What is wrong.
        why: String,
    },
    /// A `tcp/` endpoint without `--auth` (or an export beyond loopback without it).
    NeedsAuth {
        /// The endpoint.
        endpoint: String,
        /// Whether it is listened on (else connected to).
        listening: bool,
    },
    /// A `tls/` or `quic/` endpoint without `--tls`.
    NeedsTls(String),
    /// A Unix socket to listen on in a folder others may enter, without `--auth`.
    SharedSocket {
        /// The endpoint.
        endpoint: String,
        /// Why the folder is not private.
        why: String,
    },
    /// The `--auth` file is unusable.
    Credentials {
        /// The file.
        path: PathBuf,
        /// Why.
        why: String,
    },
    /// The `--tls` folder is unusable.
    Certificates(tls::CertError),
    /// The private runtime folder of the default endpoints is unsafe or cannot be made.
    LocalDir {
        /// The folder.
        dir: PathBuf,
        /// Why.
        why: String,
    },
    /// No daemon of this user on this machine (no socket in [`local_dir`]).
    NoLocalDaemon(PathBuf),
    /// A Zenoh configuration key refused a value (a bug, named).
    Config {
        /// The key.
        key: String,
        /// Zenoh's reason.
        why: String,
    },
    /// A peer was refused, or refused this host, before the session was opened.
    Link(LinkFailure),
    /// Zenoh could not open the session.
    Open(String),
}

impl std::fmt::Display for OptionError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            OptionError::Endpoint { endpoint, why } => write!(
                f,
                "endpoint '{endpoint}': {why} (expected unixsock-stream/PATH, tcp/HOST:PORT, tls/HOST:PORT or quic/HOST:PORT)"
            ),
            OptionError::NeedsAuth { endpoint, listening } => write!(
                f,
                "{} {endpoint} requires authentication: pass --auth FILE (user:password lines, mode 0600), or use an encrypted tls/HOST:PORT or quic/HOST:PORT endpoint with --tls DIR (mutual TLS); see docs/multi-host.md",
                if *listening { "listening on" } else { "connecting to" }
            ),
            OptionError::NeedsTls(ep) => write!(
                f,
                "endpoint {ep} needs --tls DIR (the CA certificate, this host's certificate and key: `formation certs`, docs/multi-host.md)"
            ),
            OptionError::SharedSocket { endpoint, why } => write!(
                f,
                "listening on {endpoint} without --auth needs a folder only you can enter ({why})"
            ),
            OptionError::Credentials { path, why } => {
                write!(f, "--auth {}: {why}", path.display())
            }
            OptionError::Certificates(e) => write!(f, "--tls: {e}"),
            OptionError::LocalDir { dir, why } => write!(
                f,
                "the private folder of local daemons {}: {why} (it must be a folder of yours with mode 0700)",
                dir.display()
            ),
            OptionError::NoLocalDaemon(dir) => write!(
                f,
                "no daemon of yours runs on this machine (no socket in {}): start one with `formation host`, or name a remote one with --connect",
                dir.display()
            ),
            OptionError::Config { key, why } => write!(f, "zenoh config {key}: {why}"),
            OptionError::Link(l) => l.fmt(f),
            OptionError::Open(e) => write!(f, "cannot open the Zenoh session: {e}"),
        }
    }
}

impl std::error::Error for OptionError {}

/// Why the link to one endpoint failed, as [`diagnose`] or the TLS pre-flight found it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum LinkProblem {
    /// No socket at the path: no daemon listens there.
    NoSocket,
    /// The socket exists but cannot be connected to (permission denied: another user's; refused:
    /// its daemon is gone).
    Socket(String),
    /// The address cannot be reached (refused, no route, timed out).
    Unreachable(String),
    /// The peer accepted the connection and refused the Zenoh session: its `--auth` users do not
    /// include this host's user and password (or this host presented none).
    Credentials {
        /// Whether this host presented credentials at all.
        presented: bool,
    },
    /// A TLS certificate was refused, either way.
    Tls(TlsRefusal),
}

/// A failed link: the endpoint and why.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LinkFailure {
    /// The endpoint.
    pub endpoint: String,
    /// Why.
    pub problem: LinkProblem,
}

impl LinkFailure {
    /// Whether the failure is one of authentication (credentials or a certificate refused).
    pub fn is_authentication(&self) -> bool {
        matches!(
            self.problem,
            LinkProblem::Credentials { .. }
                | LinkProblem::Tls(TlsRefusal::PeerCertificate { .. })
                | LinkProblem::Tls(TlsRefusal::OwnCertificate(_))
        )
    }
}

impl LinkFailure {
    /// What failed, without the endpoint (for lines that name it already).
    pub fn problem_text(&self) -> String {
        match &self.problem {
            LinkProblem::NoSocket => "no daemon listens there (no such socket)".into(),
            LinkProblem::Socket(why) => format!("cannot connect to the socket: {why}"),
            LinkProblem::Unreachable(why) => format!("unreachable: {why}"),
            LinkProblem::Credentials { presented: true } => "authentication failed: the daemon refused the user and password of --auth (not one of its users, or a wrong password)".into(),
            LinkProblem::Credentials { presented: false } => {
                "authentication failed: the daemon requires a user and password (pass --auth FILE)".into()
            }
            LinkProblem::Tls(r @ TlsRefusal::PeerCertificate { .. })
            | LinkProblem::Tls(r @ TlsRefusal::OwnCertificate(_)) => {
                format!("authentication failed: {r}")
            }
            LinkProblem::Tls(r) => r.to_string(),
        }
    }
}

impl std::fmt::Display for LinkFailure {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}: {}", self.endpoint, self.problem_text())
    }
}

fn bad_endpoint(ep: &str, why: &str) -> OptionError {
    OptionError::Endpoint {
        endpoint: ep.to_string(),
        why: why.to_string(),
    }
}

/// Parses `unixsock-stream/PATH` (absolute, at most [`MAX_SOCKET_PATH`] bytes), `tcp/HOST:PORT`,
/// `tls/HOST:PORT` or `quic/HOST:PORT`.
pub fn parse_endpoint(ep: &str) -> Result<Endpoint, OptionError> {
    if let Some(path) = ep.strip_prefix("unixsock-stream/") {
        let p = PathBuf::from(path);
        if !p.is_absolute() {
            return Err(bad_endpoint(ep, "the socket path must be absolute"));
        }
        if path.len() > MAX_SOCKET_PATH {
            return Err(bad_endpoint(
                ep,
                &format!("a socket path is at most {MAX_SOCKET_PATH} bytes"),
            ));
        }
        return Ok(Endpoint::Unix(p));
    }
    let (transport, rest) = ep
        .split_once('/')
        .filter(|(t, _)| ["tcp", "tls", "quic"].contains(t))
        .ok_or_else(|| bad_endpoint(ep, "unknown transport"))?;
    let (host, port) = rest
        .rsplit_once(':')
        .ok_or_else(|| bad_endpoint(ep, "no port"))?;
    let port = port
        .parse::<u16>()
        .map_err(|_| bad_endpoint(ep, "port is not a number in 0..=65535"))?;
    if host.is_empty() {
        return Err(bad_endpoint(ep, "no host"));
    }
    let host = host.to_string();
    Ok(match transport {
        "tls" => Endpoint::Tls { host, port },
        "quic" => Endpoint::Quic { host, port },
        _ => Endpoint::Tcp { host, port },
    })
}

/// The private folder of this user's daemon sockets: `$XDG_RUNTIME_DIR/formation` when that
/// runtime folder exists, else `/tmp/formation-<uid>`; created with mode 0700 if missing, refused
/// when it is a link or another user's, made owner-only (0700) when it is this user's.
pub fn local_dir() -> Result<PathBuf, OptionError> {
    let dir = match std::env::var_os("XDG_RUNTIME_DIR").filter(|d| !d.is_empty()) {
        Some(d) if Path::new(&d).is_dir() => Path::new(&d).join("formation"),
        _ => PathBuf::from(format!("/tmp/formation-{}", files::current_uid())),
    };
    files::ensure_private_dir(&dir).map_err(|e| OptionError::LocalDir {
        dir: e.path,
        why: e.why,
    })?;
    let m = std::fs::symlink_metadata(&dir).map_err(|e| OptionError::LocalDir {
        dir: dir.clone(),
        why: e.to_string(),
    })?;
    if m.mode() & 0o077 != 0 {
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(&dir, std::fs::Permissions::from_mode(0o700)).map_err(|e| {
            OptionError::LocalDir {
                dir: dir.clone(),
                why: format!("cannot make it owner-only: {e}"),
            }
        })?;
    }
    Ok(dir)
}

/// The default endpoint of the daemon named `name` (its Unix socket in [`local_dir`]).
pub fn local_endpoint(name: &str) -> Result<String, OptionError> {
    let ep = format!(
        "unixsock-stream/{}",
        local_dir()?.join(format!("{name}.{SOCKET_EXT}")).display()
    );
    parse_endpoint(&ep)?;
    Ok(ep)
}

/// The endpoints of every daemon socket in [`local_dir`] (sorted); an error when there is none.
pub fn local_endpoints() -> Result<Vec<String>, OptionError> {
    let dir = local_dir()?;
    let mut v: Vec<String> = std::fs::read_dir(&dir)
        .map_err(|e| OptionError::LocalDir {
            dir: dir.clone(),
            why: e.to_string(),
        })?
        .flatten()
        .filter(|e| e.file_type().is_ok_and(|t| !t.is_dir() && !t.is_symlink()))
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|x| x == SOCKET_EXT))
        .map(|p| format!("unixsock-stream/{}", p.display()))
        .collect();
    if v.is_empty() {
        return Err(OptionError::NoLocalDaemon(dir));
    }
    v.sort();
    Ok(v)
}

/// Why a socket's folder is not private (owner-only, this user's, not a link), if it is not.
fn socket_folder_problem(path: &Path) -> Option<String> {
    let dir = path.parent()?;
    if let Err(why) = files::check_private_dir(dir) {
        return Some(format!("{}: {why}", dir.display()));
    }
    let mode = std::fs::symlink_metadata(dir).ok()?.mode() & 0o777;
    (mode & 0o077 != 0).then(|| format!("{} has mode {mode:04o}", dir.display()))
}

impl Options {
    /// The `--tls` material, read and checked (`None` without `--tls`).
    pub fn material(&self) -> Result<Option<Material>, OptionError> {
        self.tls
            .as_deref()
            .map(Material::load)
            .transpose()
            .map_err(OptionError::Certificates)
    }

    /// Validates the endpoints, the credentials and certificates, and the rules above.
    pub fn check(&self) -> Result<(), OptionError> {
        self.check_with(self.material()?.as_ref())
    }

    fn check_with(&self, tls: Option<&Material>) -> Result<(), OptionError> {
        if let Some(a) = &self.auth {
            read_credentials(a)?;
        }
        let all = self
            .listen
            .iter()
            .map(|e| (e, true))
            .chain(self.connect.iter().map(|e| (e, false)));
        for (ep, listening) in all {
            match parse_endpoint(ep)? {
                Endpoint::Tcp { .. } if self.auth.is_none() => {
                    let exported = self.mode == Mode::Export && parse_endpoint(ep)?.is_loopback();
                    if !exported {
                        return Err(OptionError::NeedsAuth {
                            endpoint: ep.clone(),
                            listening,
                        });
                    }
                }
                Endpoint::Tls { .. } | Endpoint::Quic { .. } if tls.is_none() => {
                    return Err(OptionError::NeedsTls(ep.clone()))
                }
                Endpoint::Unix(path) if listening && self.auth.is_none() => {
                    if let Some(why) = socket_folder_problem(&path) {
                        return Err(OptionError::SharedSocket {
                            endpoint: ep.clone(),
                            why,
                        });
                    }
                }
                _ => {}
            }
        }
        Ok(())
    }

    /// The Zenoh configuration.
    pub fn config(&self) -> Result<zenoh::Config, OptionError> {
        let tls = self.material()?;
        self.check_with(tls.as_ref())?;
        let mut c = zenoh::Config::default();
        let set = |c: &mut zenoh::Config, k: &str, v: String| {
            c.insert_json5(k, &v).map_err(|e| OptionError::Config {
                key: k.to_string(),
                why: e.to_string(),
            })
        };
        let json = |s: &str| serde_json::to_string(s).unwrap_or_default();
        let mode = match self.mode {
            Mode::Export => "peer",
            Mode::Daemon | Mode::Orchestrator => "router",
            Mode::Client => "client",
        };
        set(&mut c, "mode", format!("\"{mode}\""))?;
        set(&mut c, "scouting/multicast/enabled", "false".into())?;
        set(
            &mut c,
            "listen/endpoints",
            serde_json::to_string(&self.listen).unwrap_or_default(),
        )?;
        set(
            &mut c,
            "connect/endpoints",
            serde_json::to_string(&self.connect).unwrap_or_default(),
        )?;
        set(&mut c, "transport/link/tx/lease", self.lease_ms.to_string())?;
        // Four keep-alives per lease (Zenoh's default ratio).
        set(&mut c, "transport/link/tx/keep_alive", "4".into())?;
        // No timestamps, no adminspace: nothing this project reads.
        set(&mut c, "timestamping/enabled", "false".into())?;
        set(&mut c, "adminspace/enabled", "false".into())?;
        if self.mode == Mode::Daemon {
            set(&mut c, "access_control", DAEMON_ACCESS_CONTROL.into())?;
        }
        if self.mode == Mode::Orchestrator {
            // Fail at once if a daemon cannot be reached (the handshake names it).
            set(&mut c, "connect/timeout_ms", "2000".into())?;
            set(&mut c, "connect/exit_on_failure", "false".into())?;
        }
        if let Some(path) = &self.auth {
            let (user, password) = read_credentials(path)?;
            set(&mut c, "transport/auth/usrpwd/user", json(&user))?;
            set(&mut c, "transport/auth/usrpwd/password", json(&password))?;
            if matches!(self.mode, Mode::Daemon | Mode::Export) {
                set(
                    &mut c,
                    "transport/auth/usrpwd/dictionary_file",
                    json(&path.display().to_string()),
                )?;
            }
        }
        if let Some(m) = &tls {
            use base64::Engine;
            let b64 = |b: &[u8]| json(&base64::engine::general_purpose::STANDARD.encode(b));
            // Zenoh's TLS and QUIC links both read this section.
            let k = "transport/link/tls";
            // The contents, not the paths: the files were read once, checked, without
            // following links; Zenoh never opens them.
            set(
                &mut c,
                &format!("{k}/root_ca_certificate_base64"),
                b64(&m.ca_pem),
            )?;
            set(
                &mut c,
                &format!("{k}/listen_certificate_base64"),
                b64(&m.cert_pem),
            )?;
            set(
                &mut c,
                &format!("{k}/listen_private_key_base64"),
                b64(m.key_pem()),
            )?;
            set(
                &mut c,
                &format!("{k}/connect_certificate_base64"),
                b64(&m.cert_pem),
            )?;
            set(
                &mut c,
                &format!("{k}/connect_private_key_base64"),
                b64(m.key_pem()),
            )?;
            set(&mut c, &format!("{k}/enable_mtls"), "true".into())?;
            set(
                &mut c,
                &format!("{k}/verify_name_on_connect"),
                "true".into(),
            )?;
        }
        Ok(c)
    }

    /// Opens the session. An orchestrator or client first checks every `tls/` and `quic/`
    /// endpoint it connects to ([`tls::preflight`], [`tls::preflight_quic`]): a certificate
    /// refused either way is an error naming the endpoint (an endpoint that cannot be reached is
    /// left to the handshake, which names the host missing).
    pub fn open(&self) -> Result<zenoh::Session, OptionError> {
        bound_threads();
        let c = self.config()?;
        if matches!(self.mode, Mode::Orchestrator | Mode::Client) {
            if let Some(m) = self.material()? {
                for ep in &self.connect {
                    match preflight(&parse_endpoint(ep)?, &m) {
                        None | Some(TlsRefusal::Unreachable(_)) => {}
                        Some(r) => {
                            return Err(OptionError::Link(LinkFailure {
                                endpoint: ep.clone(),
                                problem: LinkProblem::Tls(r),
                            }))
                        }
                    }
                }
            }
        }
        zenoh::open(c)
            .wait()
            .map_err(|e| OptionError::Open(e.to_string()))
    }
}

/// The pre-flight handshake of a `tls/` or `quic/` endpoint: why it is refused, if it is
/// (`None` for other endpoints).
fn preflight(ep: &Endpoint, m: &Material) -> Option<TlsRefusal> {
    match ep {
        Endpoint::Tls { host, port } => tls::preflight(host, *port, m).err(),
        Endpoint::Quic { host, port } => tls::preflight_quic(host, *port, m).err(),
        Endpoint::Unix(_) | Endpoint::Tcp { .. } => None,
    }
}

/// Why the link to `endpoint` (one of `o`'s) fails, if it does: no socket, a socket of another
/// user, unreachable, its TLS certificates refused either way, or — when the connection is
/// accepted and a Zenoh client session with `o`'s credentials is not — an authentication
/// failure. `None` when a session opens. For error messages after a host did not answer; costs
/// one short client session per endpoint.
pub fn diagnose(o: &Options, endpoint: &str) -> Option<LinkFailure> {
    let fail = |problem| {
        Some(LinkFailure {
            endpoint: endpoint.to_string(),
            problem,
        })
    };
    match parse_endpoint(endpoint).ok()? {
        Endpoint::Unix(path) => {
            match std::fs::symlink_metadata(&path) {
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                    return fail(LinkProblem::NoSocket)
                }
                // Another user's private folder: the kernel refuses even a look.
                Err(e) => return fail(LinkProblem::Socket(e.to_string())),
                Ok(_) => {}
            }
            if let Err(e) = std::os::unix::net::UnixStream::connect(&path) {
                return fail(LinkProblem::Socket(e.to_string()));
            }
        }
        Endpoint::Tcp { host, port } => {
            use std::net::ToSocketAddrs;
            let bare = host
                .trim_start_matches('[')
                .trim_end_matches(']')
                .to_string();
            let addr = match (bare.as_str(), port)
                .to_socket_addrs()
                .map(|mut a| a.next())
            {
                Ok(Some(a)) => a,
                Ok(None) => return fail(LinkProblem::Unreachable("no address".into())),
                Err(e) => return fail(LinkProblem::Unreachable(e.to_string())),
            };
            if let Err(e) = std::net::TcpStream::connect_timeout(&addr, PROBE_TIMEOUT) {
                return fail(LinkProblem::Unreachable(e.to_string()));
            }
        }
        ep @ (Endpoint::Tls { .. } | Endpoint::Quic { .. }) => {
            let m = o.material().ok()??;
            if let Some(r) = preflight(&ep, &m) {
                return fail(match r {
                    TlsRefusal::Unreachable(why) => LinkProblem::Unreachable(why),
                    r => LinkProblem::Tls(r),
                });
            }
        }
    }
    // Reached: does a client session with these credentials get in?
    let probe = Options {
        mode: Mode::Client,
        listen: vec![],
        connect: vec![endpoint.to_string()],
        ..o.clone()
    };
    let mut c = probe.config().ok()?;
    c.insert_json5("connect/timeout_ms", &PROBE_TIMEOUT.as_millis().to_string())
        .ok()?;
    match zenoh::open(c).wait() {
        Ok(s) => {
            let _ = s.close().wait();
            None
        }
        Err(_) => fail(LinkProblem::Credentials {
            presented: o.auth.is_some(),
        }),
    }
}

/// The first `user:password` line of a credentials file, which must be a regular file readable
/// by its owner only (mode 0600 or stricter).
pub fn read_credentials(path: &Path) -> Result<(String, String), OptionError> {
    let bad = |why: String| OptionError::Credentials {
        path: path.to_path_buf(),
        why,
    };
    let meta = std::fs::symlink_metadata(path).map_err(|e| bad(format!("cannot read: {e}")))?;
    if !meta.file_type().is_file() {
        return Err(bad("not a regular file".into()));
    }
    if meta.mode() & 0o077 != 0 {
        return Err(bad(format!(
            "mode {:o}: a credentials file must not be readable by group or others (chmod 600)",
            meta.mode() & 0o777
        )));
    }
    let text = std::fs::read_to_string(path).map_err(|e| bad(format!("cannot read: {e}")))?;
    let line = text
        .lines()
        .map(str::trim)
        .find(|l| !l.is_empty())
        .ok_or_else(|| bad("empty: expected user:password lines".into()))?;
    let (u, p) = line
        .split_once(':')
        .filter(|(u, p)| !u.is_empty() && !p.is_empty())
        .ok_or_else(|| bad("expected user:password lines".into()))?;
    Ok((u.to_string(), p.to_string()))
}

/// Caps Zenoh's runtimes at one worker thread each (unless `ZENOH_RUNTIME` is set): a session
/// otherwise starts six workers, too many beside seven busy processes on two cores.
///
pub fn bound_threads() {
    if std::env::var_os("ZENOH_RUNTIME").is_none() {
        // SAFETY: called before any Zenoh runtime exists, from the thread that opens the session.
        unsafe {
            std::env::set_var(
                "ZENOH_RUNTIME",
                "(app: (worker_threads: 1), acc: (worker_threads: 1), tx: (worker_threads: 1, max_blocking_threads: 2), rx: (worker_threads: 1, max_blocking_threads: 2), net: (worker_threads: 1, max_blocking_threads: 2))",
            );
        }
    }
}

/// How long an orchestrator waits for replies of the daemons.
pub const REPLY_TIMEOUT: Duration = Duration::from_secs(5);

#[cfg(test)]
mod tests {
    use super::*;

    fn opts(mode: Mode, listen: &[&str], connect: &[&str]) -> Options {
        Options {
            mode,
            listen: listen.iter().map(|s| s.to_string()).collect(),
            connect: connect.iter().map(|s| s.to_string()).collect(),
            auth: None,
            tls: None,
            lease_ms: DEFAULT_LEASE_MS,
        }
    }

    #[test]
    fn a_tls_endpoint_is_warned_about_once_naming_it_and_the_sound_quic_link() {
        let w = opts(
            Mode::Orchestrator,
            &[],
            &[
                "tls/10.0.0.2:7447",
                "quic/10.0.0.3:7447",
                "tls/10.0.0.4:7447",
            ],
        )
        .warnings();
        assert_eq!(w.len(), 1, "{w:?}");
        assert!(w[0].starts_with("warning: tls/10.0.0.2:7447 tls/10.0.0.4:7447: "));
        assert!(
            w[0].contains("zenoh#2557") && w[0].contains("quic/HOST:PORT"),
            "{}",
            w[0]
        );
        assert!(opts(Mode::Daemon, &["quic/0.0.0.0:7447"], &[])
            .warnings()
            .is_empty());
        assert!(
            opts(Mode::Daemon, &["tls/0.0.0.0:7447"], &[])
                .warnings()
                .len()
                == 1
        );
    }

    #[test]
    fn a_daemons_configuration_carries_its_access_control_and_zenoh_takes_it() {
        use std::os::unix::fs::DirBuilderExt;
        let dir = std::env::temp_dir().join(format!("fm-acl-{}", std::process::id()));
        std::fs::DirBuilder::new().mode(0o700).create(&dir).unwrap();
        let sock = format!("unixsock-stream/{}", dir.join("d.sock").display());
        let c = opts(Mode::Daemon, &[&sock], &[]).config();
        let _ = std::fs::remove_dir_all(&dir);
        let c = c.expect("a daemon's configuration is accepted");
        let acl = c.get_json("access_control").expect("access control is set");
        assert!(
            acl.contains("declare_queryable") && acl.contains("formation/host/**"),
            "{acl}"
        );
        assert!(opts(Mode::Orchestrator, &[], &[])
            .config()
            .unwrap()
            .get_json("access_control/enabled")
            .is_ok_and(|v| v == "false"));
    }

    #[test]
    fn endpoints_of_the_four_transports_are_parsed_and_malformed_ones_named() {
        let tcp = |h: &str, p| Endpoint::Tcp {
            host: h.into(),
            port: p,
        };
        assert_eq!(
            parse_endpoint("tcp/127.0.0.1:7447"),
            Ok(tcp("127.0.0.1", 7447))
        );
        assert!(parse_endpoint("tcp/localhost:0").unwrap().is_loopback());
        assert!(parse_endpoint("tcp/[::1]:7447").unwrap().is_loopback());
        assert!(!parse_endpoint("tcp/10.0.0.2:7447").unwrap().is_loopback());
        assert!(!parse_endpoint("tcp/0.0.0.0:7447").unwrap().is_loopback());
        assert_eq!(
            parse_endpoint("tls/10.0.0.2:7447"),
            Ok(Endpoint::Tls {
                host: "10.0.0.2".into(),
                port: 7447
            })
        );
        assert_eq!(
            parse_endpoint("quic/[::1]:7447"),
            Ok(Endpoint::Quic {
                host: "[::1]".into(),
                port: 7447
            })
        );
        assert!(parse_endpoint("quic/localhost:7447").unwrap().is_loopback());
        assert!(parse_endpoint("quic/10.0.0.2").is_err());
        assert!(parse_endpoint("quic/:7447").is_err());
        assert!(parse_endpoint("quic_datagram/10.0.0.2:7447").is_err());
        assert!(parse_endpoint("udp/127.0.0.1:7447")
            .unwrap_err()
            .to_string()
            .contains("quic/HOST:PORT"));
        assert_eq!(
            parse_endpoint("unixsock-stream/run/b.sock"),
            Err(bad_endpoint(
                "unixsock-stream/run/b.sock",
                "the socket path must be absolute"
            ))
        );
        assert_eq!(
            parse_endpoint("unixsock-stream//run/f/b.sock"),
            Ok(Endpoint::Unix("/run/f/b.sock".into()))
        );
        let long = format!("unixsock-stream//{}", "x".repeat(120));
        assert!(parse_endpoint(&long).is_err());
        assert!(parse_endpoint("udp/127.0.0.1:7447").is_err());
        assert!(parse_endpoint("tcp/127.0.0.1").is_err());
        assert!(parse_endpoint("tcp/127.0.0.1:99999").is_err());
    }

    #[test]
    fn every_tcp_endpoint_needs_auth_and_every_tls_or_quic_endpoint_needs_certificates() {
        for (l, c) in [
            (&["tcp/0.0.0.0:7447"][..], &[][..]),
            (&["tcp/127.0.0.1:7447"][..], &[][..]),
            (&[][..], &["tcp/127.0.0.1:7447"][..]),
        ] {
            let e = opts(Mode::Daemon, l, c).check().unwrap_err();
            assert!(matches!(e, OptionError::NeedsAuth { .. }), "{e}");
            assert!(e.to_string().contains("--auth FILE") && e.to_string().contains("--tls DIR"));
        }
        let e = opts(Mode::Orchestrator, &[], &["tls/10.0.0.2:7447"])
            .check()
            .unwrap_err();
        assert_eq!(e, OptionError::NeedsTls("tls/10.0.0.2:7447".into()));
        for (l, c) in [
            (&["quic/0.0.0.0:7447"][..], &[][..]),
            (&[][..], &["quic/10.0.0.2:7447"][..]),
        ] {
            let e = opts(Mode::Daemon, l, c).check().unwrap_err();
            assert!(matches!(e, OptionError::NeedsTls(_)), "{e}");
            assert!(e.to_string().contains("--tls DIR"), "{e}");
        }
        // The telemetry export alone may listen on loopback without credentials.
        assert!(opts(Mode::Export, &["tcp/127.0.0.1:7448"], &[])
            .check()
            .is_ok());
        assert!(opts(Mode::Export, &["tcp/0.0.0.0:7448"], &[])
            .check()
            .is_err());
    }

    #[test]
    fn zenohs_own_quic_link_admits_its_ca_and_refuses_a_certificate_of_another_ca_either_way() {
        use std::os::unix::fs::PermissionsExt;
        let d = std::env::temp_dir().join(format!("fm-net-quic-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        let (ca1, ca2) = (d.join("ca1"), d.join("ca2"));
        tls::init(&ca1).unwrap();
        tls::init(&ca2).unwrap();
        let host = |ca: &Path, name: &str| {
            let what = tls::Issue {
                name: name.into(),
                addrs: vec!["127.0.0.1".parse().unwrap()],
                dns: vec![],
            };
            tls::issue(ca, &what, &d.join(name)).unwrap();
            d.join(name)
        };
        let (b, a, x, mixed) = (
            host(&ca1, "b"),
            host(&ca1, "a"),
            host(&ca2, "x"),
            host(&ca2, "m"),
        );
        // Trusting b's CA, presenting a certificate of another.
        let ca = mixed.join(tls::CA_CERT);
        std::fs::remove_file(&ca).unwrap();
        std::fs::copy(ca1.join(tls::CA_CERT), &ca).unwrap();
        std::fs::set_permissions(&ca, std::fs::Permissions::from_mode(0o600)).unwrap();
        let port = std::net::UdpSocket::bind("127.0.0.1:0")
            .and_then(|s| s.local_addr())
            .unwrap()
            .port();
        let ep = format!("quic/127.0.0.1:{port}");
        let daemon = Options {
            tls: Some(b),
            ..opts(Mode::Daemon, &[&ep], &[])
        };
        let daemon = zenoh::open(daemon.config().unwrap())
            .wait()
            .expect("listens");
        // Zenoh's link alone, without this crate's pre-flight: a client session opens only when
        // both certificates are of one CA.
        let client = |tls: &Path| {
            let o = Options {
                tls: Some(tls.to_path_buf()),
                ..opts(Mode::Client, &[], &[&ep])
            };
            let mut c = o.config().unwrap();
            c.insert_json5("connect/timeout_ms", "3000").unwrap();
            zenoh::open(c).wait().map(|s| {
                let _ = s.close().wait();
            })
        };
        assert!(
            client(&a).is_ok(),
            "a certificate of the daemon's CA is admitted"
        );
        assert!(client(&x).is_err(), "a daemon of another CA is refused");
        assert!(client(&mixed).is_err(), "a client of another CA is refused");
        let _ = daemon.close().wait();
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn a_socket_is_listened_on_without_auth_only_in_a_private_folder() {
        use std::os::unix::fs::PermissionsExt;
        let dir = std::env::temp_dir().join(format!("fm-net-sock-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let ep = format!("unixsock-stream/{}/b.sock", dir.display());
        std::fs::set_permissions(&dir, std::fs::Permissions::from_mode(0o755)).unwrap();
        let e = opts(Mode::Daemon, &[&ep], &[]).check().unwrap_err();
        assert!(matches!(e, OptionError::SharedSocket { .. }), "{e}");
        std::fs::set_permissions(&dir, std::fs::Permissions::from_mode(0o700)).unwrap();
        assert!(opts(Mode::Daemon, &[&ep], &[]).check().is_ok());
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_credentials_file_readable_by_others_is_refused() {
        use std::os::unix::fs::PermissionsExt;
        let dir = std::env::temp_dir().join(format!("fm-net-auth-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let f = dir.join("auth");
        std::fs::write(&f, "alice:secret\n").unwrap();
        std::fs::set_permissions(&f, std::fs::Permissions::from_mode(0o644)).unwrap();
        assert!(read_credentials(&f)
            .unwrap_err()
            .to_string()
            .contains("chmod 600"));
        std::fs::set_permissions(&f, std::fs::Permissions::from_mode(0o600)).unwrap();
        assert_eq!(
            read_credentials(&f).unwrap(),
            ("alice".to_string(), "secret".to_string())
        );
        let _ = std::fs::remove_dir_all(&dir);
    }
}
