//! Zenoh sessions of this project: which mode, which endpoints, authentication, threads.
//!
//! * Multicast scouting is off: hosts are joined by explicit endpoints only.
//! * A daemon listens on loopback (`tcp/127.0.0.1:7447`) unless told otherwise; an endpoint beyond
//!   loopback is refused without `--auth FILE` (Zenoh user/password authentication).
//! * Zenoh's runtimes default to six worker threads per process; on small machines
//!   [`bound_threads`] caps each runtime at one worker unless `ZENOH_RUNTIME` is already set.

use std::path::{Path, PathBuf};
use std::time::Duration;
use zenoh::Wait;

/// Default port of `formation host`.
pub const DEFAULT_PORT: u16 = 7447;

/// Default endpoint a daemon listens on and an orchestrator connects to.
pub fn default_endpoint() -> String {
    format!("tcp/127.0.0.1:{DEFAULT_PORT}")
}

/// Default lease: a host whose link is silent this long is declared lost (Zenoh
/// `transport/link/tx/lease`). A killed process is seen at once (its TCP link closes).
pub const DEFAULT_LEASE_MS: u64 = 3000;

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
    /// Endpoints to listen on (`tcp/ADDR:PORT`).
    pub listen: Vec<String>,
    /// Endpoints to connect to.
    pub connect: Vec<String>,
    /// `user:password` file (mode 0600): the daemon's accepted users, the orchestrator's credentials
    /// (its first line).
    pub auth: Option<PathBuf>,
    /// Link lease, ms.
    pub lease_ms: u64,
}

/// Why an endpoint or an option is refused.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct OptionError(pub String);

impl std::fmt::Display for OptionError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

/// Checks `tcp/HOST:PORT`; returns whether HOST is a loopback address.
pub fn parse_endpoint(ep: &str) -> Result<bool, OptionError> {
    let bad = |why: &str| OptionError(format!("endpoint '{ep}': {why} (expected tcp/HOST:PORT)"));
    let rest = ep
        .strip_prefix("tcp/")
        .ok_or_else(|| bad("only tcp endpoints are supported"))?;
    let (host, port) = rest.rsplit_once(':').ok_or_else(|| bad("no port"))?;
    port.parse::<u16>()
        .map_err(|_| bad("port is not a number in 0..=65535"))?;
    if host.is_empty() {
        return Err(bad("no host"));
    }
    let host = host.trim_start_matches('[').trim_end_matches(']');
    Ok(host == "localhost"
        || host == "::1"
        || host
            .parse::<std::net::Ipv4Addr>()
            .is_ok_and(|a| a.is_loopback()))
}

impl Options {
    /// Validates endpoints and the loopback rule: listening beyond loopback needs `auth`.
    pub fn check(&self) -> Result<(), OptionError> {
        for ep in &self.connect {
            parse_endpoint(ep)?;
        }
        for ep in &self.listen {
            if !parse_endpoint(ep)? && self.auth.is_none() {
                return Err(OptionError(format!(
                    "listening on {ep} (beyond loopback) requires authentication: pass --auth FILE (user:password lines, mode 0600); see docs/multi-host.md"
                )));
            }
        }
        if let Some(a) = &self.auth {
            read_credentials(a)?;
        }
        Ok(())
    }

    /// The Zenoh configuration.
    pub fn config(&self) -> Result<zenoh::Config, OptionError> {
        self.check()?;
        let mut c = zenoh::Config::default();
        let set = |c: &mut zenoh::Config, k: &str, v: String| {
            c.insert_json5(k, &v)
                .map_err(|e| OptionError(format!("zenoh config {k} = {v}: {e}")))
        };
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
            serde_json::to_string(&self.listen).unwrap(),
        )?;
        set(
            &mut c,
            "connect/endpoints",
            serde_json::to_string(&self.connect).unwrap(),
        )?;
        set(&mut c, "transport/link/tx/lease", self.lease_ms.to_string())?;
        // Four keep-alives per lease (Zenoh's default ratio).
        set(&mut c, "transport/link/tx/keep_alive", "4".into())?;
        // No timestamps, no adminspace: nothing this project reads.
        set(&mut c, "timestamping/enabled", "false".into())?;
        set(&mut c, "adminspace/enabled", "false".into())?;
        if self.mode == Mode::Orchestrator {
            // Fail at once if a daemon cannot be reached (the handshake names it).
            set(&mut c, "connect/timeout_ms", "2000".into())?;
            set(&mut c, "connect/exit_on_failure", "false".into())?;
        }
        if let Some(path) = &self.auth {
            let (user, password) = read_credentials(path)?;
            set(
                &mut c,
                "transport/auth/usrpwd/user",
                serde_json::to_string(&user).unwrap(),
            )?;
            set(
                &mut c,
                "transport/auth/usrpwd/password",
                serde_json::to_string(&password).unwrap(),
            )?;
            if matches!(self.mode, Mode::Daemon | Mode::Export) {
                set(
                    &mut c,
                    "transport/auth/usrpwd/dictionary_file",
                    serde_json::to_string(&path.display().to_string()).unwrap(),
                )?;
            }
        }
        Ok(c)
    }

    /// Opens the session.
    pub fn open(&self) -> Result<zenoh::Session, OptionError> {
        bound_threads();
        let c = self.config()?;
        zenoh::open(c)
            .wait()
            .map_err(|e| OptionError(format!("cannot open the Zenoh session: {e}")))
    }
}

/// The first `user:password` line of a credentials file, which must be a regular file readable
/// by its owner only (mode 0600 or stricter).
pub fn read_credentials(path: &Path) -> Result<(String, String), OptionError> {
    use std::os::unix::fs::MetadataExt;
    let bad = |why: String| OptionError(format!("--auth {}: {why}", path.display()));
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

    #[test]
    fn loopback_endpoints_are_recognised_and_malformed_ones_named() {
        assert_eq!(parse_endpoint("tcp/127.0.0.1:7447"), Ok(true));
        assert_eq!(parse_endpoint("tcp/localhost:0"), Ok(true));
        assert_eq!(parse_endpoint("tcp/[::1]:7447"), Ok(true));
        assert_eq!(parse_endpoint("tcp/10.0.0.2:7447"), Ok(false));
        assert_eq!(parse_endpoint("tcp/0.0.0.0:7447"), Ok(false));
        assert!(parse_endpoint("udp/127.0.0.1:7447").is_err());
        assert!(parse_endpoint("tcp/127.0.0.1").is_err());
        assert!(parse_endpoint("tcp/127.0.0.1:99999").is_err());
    }

    #[test]
    fn listening_beyond_loopback_without_authentication_is_refused() {
        let o = Options {
            mode: Mode::Daemon,
            listen: vec!["tcp/0.0.0.0:7447".into()],
            connect: vec![],
            auth: None,
            lease_ms: DEFAULT_LEASE_MS,
        };
        let e = o.check().unwrap_err();
        assert!(e.0.contains("requires authentication"), "{e}");
        let local = Options {
            listen: vec![default_endpoint()],
            ..o
        };
        assert!(local.check().is_ok());
    }

    #[test]
    fn a_credentials_file_readable_by_others_is_refused() {
        use std::os::unix::fs::PermissionsExt;
        let dir = std::env::temp_dir().join(format!("fm-net-auth-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let f = dir.join("auth");
        std::fs::write(&f, "alice:secret\n").unwrap();
        std::fs::set_permissions(&f, std::fs::Permissions::from_mode(0o644)).unwrap();
        assert!(read_credentials(&f).unwrap_err().0.contains("chmod 600"));
        std::fs::set_permissions(&f, std::fs::Permissions::from_mode(0o600)).unwrap();
        assert_eq!(
            read_credentials(&f).unwrap(),
            ("alice".to_string(), "secret".to_string())
        );
        let _ = std::fs::remove_dir_all(&dir);
    }
}
