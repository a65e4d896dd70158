//! The Zenoh link options shared by `formation run --hosts`, `formation host` and `formation
//! hosts` (crate `formation-host`), and what a process with Zenoh links does about SIGPIPE.

use formation_net::session::{self, Mode, Options};
use std::path::PathBuf;

/// Zenoh link options shared by `host`, `hosts` and `run --hosts`.
#[derive(clap::Args, Debug, Clone)]
pub struct LinkArgs {
    /// `user:password` file (mode 0600): a daemon accepts only orchestrators that present one of
    /// its lines; an orchestrator presents its first line. Required by every tcp/ endpoint.
    #[arg(long, value_name = "FILE")]
    pub auth: Option<PathBuf>,
    /// Folder with `ca.pem`, `cert.pem` and `key.pem` (`formation certs issue`): mutual TLS on
    /// tls/HOST:PORT and quic/HOST:PORT endpoints; a peer whose certificate this CA did not sign
    /// is refused.
    #[arg(long, value_name = "DIR")]
    pub tls: Option<PathBuf>,
    /// Zenoh link lease, ms: a host whose link stays silent this long is declared lost (a killed
    /// daemon is seen at once over a socket, TCP or TLS, whose link closes; over QUIC, which is
    /// UDP, only when the lease runs out).
    #[arg(long, default_value_t = session::DEFAULT_LEASE_MS, value_name = "MS")]
    pub lease_ms: u64,
}

impl LinkArgs {
    /// The session options of these link options.
    pub fn options(&self, mode: Mode, listen: Vec<String>, connect: Vec<String>) -> Options {
        Options {
            mode,
            listen,
            connect,
            auth: self.auth.clone(),
            tls: self.tls.clone(),
            lease_ms: self.lease_ms,
        }
    }
}

/// Ignores SIGPIPE (restored to its default by `main` for pipelines): Zenoh's TLS link writes to
/// its socket with `writev`, which raises SIGPIPE on a link whose peer is gone, and the default
/// would kill a daemon or an orchestrator instead of failing the link's write.
pub fn ignore_sigpipe() {
    // SAFETY: setting a signal disposition to SIG_IGN has no preconditions.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_IGN);
    }
}
