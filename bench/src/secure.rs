//! The credentials of the Zenoh cases of `formation bench` (`--zenoh-link`): every TCP endpoint
//! needs a user and password and every TLS or QUIC endpoint certificates (docs/multi-host.md), so
//! the bench makes its own, for one invocation, in an owner-only scratch folder it removes after:
//! a `user:password` file for `tcp`, a CA and the two hosts' certificate folders for `tls` and
//! `quic`.

use crate::error::{CaseError, ResultExt};
use formation_net::bench::SPLIT_HOST;
use formation_net::cluster::LAUNCHER;
use formation_net::tls;
use std::io::Read;
use std::path::{Path, PathBuf};

/// How the two hosts of a Zenoh case are linked.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ZenohLink {
    /// TCP over loopback with Zenoh user/password authentication (plaintext).
    Tcp,
    /// Mutual TLS over TCP on loopback (encrypted).
    Tls,
    /// QUIC over UDP on loopback, with the same certificates and mutual TLS (encrypted).
    Quic,
}

impl ZenohLink {
    /// `tcp`, `tls` or `quic`.
    pub fn name(self) -> &'static str {
        match self {
            ZenohLink::Tcp => "tcp",
            ZenohLink::Tls => "tls",
            ZenohLink::Quic => "quic",
        }
    }
}

/// The link kind with its credentials, made in a folder removed on drop.
pub struct Secured {
    /// The link kind.
    pub link: ZenohLink,
    dir: PathBuf,
}

impl Secured {
    /// Makes the credentials of `link` in `dir` (created owner-only; removed on drop).
    pub fn make(link: ZenohLink, dir: &Path) -> Result<Secured, CaseError> {
        let _ = std::fs::remove_dir_all(dir);
        formation_config::node::files::ensure_private_dir(dir).map_err(CaseError::below)?;
        let s = Secured {
            link,
            dir: dir.to_path_buf(),
        };
        match link {
            ZenohLink::Tcp => {
                let mut secret = [0u8; 16];
                std::fs::File::open("/dev/urandom")
                    .and_then(|mut f| f.read_exact(&mut secret))
                    .ctx("/dev/urandom")?;
                let hex: String = secret.iter().map(|b| format!("{b:02x}")).collect();
                let mut f = formation_config::node::files::create_new(&s.auth_file(), 0o600)
                    .map_err(|e| CaseError::file(&s.auth_file(), e))?;
                std::io::Write::write_all(&mut f, format!("bench:{hex}\n").as_bytes())
                    .map_err(|e| CaseError::file(&s.auth_file(), e))?;
            }
            ZenohLink::Tls | ZenohLink::Quic => {
                let ca = dir.join("ca");
                tls::init(&ca).map_err(CaseError::below)?;
                for name in [LAUNCHER, SPLIT_HOST] {
                    let what = tls::Issue {
                        name: name.to_string(),
                        addrs: vec![std::net::IpAddr::from([127, 0, 0, 1])],
                        dns: vec![],
                    };
                    tls::issue(&ca, &what, &dir.join(name)).map_err(CaseError::below)?;
                }
            }
        }
        Ok(s)
    }

    fn auth_file(&self) -> PathBuf {
        self.dir.join("auth")
    }

    /// An endpoint of 127.0.0.1 on a port free a moment ago (a UDP port for `quic`, TCP
    /// otherwise): the peer listens on it.
    pub fn free_endpoint(&self) -> Result<String, CaseError> {
        let any = ("127.0.0.1", 0);
        let port = match self.link {
            ZenohLink::Quic => std::net::UdpSocket::bind(any).and_then(|s| s.local_addr()),
            ZenohLink::Tcp | ZenohLink::Tls => {
                std::net::TcpListener::bind(any).and_then(|l| l.local_addr())
            }
        }
        .map(|a| a.port())
        .ctx("no free port on 127.0.0.1")?;
        Ok(format!("{}/127.0.0.1:{port}", self.link.name()))
    }

    /// `(auth, tls)` of host `name` ([`LAUNCHER`] or [`SPLIT_HOST`]).
    pub fn of(&self, name: &str) -> (Option<PathBuf>, Option<PathBuf>) {
        match self.link {
            ZenohLink::Tcp => (Some(self.auth_file()), None),
            ZenohLink::Tls | ZenohLink::Quic => (None, Some(self.dir.join(name))),
        }
    }

    /// The command-line options of host `name` (`--auth FILE` or `--tls DIR`).
    pub fn args(&self, name: &str) -> Vec<String> {
        match self.of(name) {
            (Some(a), _) => vec!["--auth".into(), a.display().to_string()],
            (_, Some(t)) => vec!["--tls".into(), t.display().to_string()],
            _ => vec![],
        }
    }
}

impl Drop for Secured {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}
