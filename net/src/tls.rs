//! Mutual TLS between hosts (`tls/HOST:PORT` endpoints): the project's own certificate authority
//! and one certificate per host, made by `formation certs` ([`init`], [`issue`]); the folder a host
//! is given with `--tls DIR` ([`Material`]); and a pre-flight handshake ([`preflight`] over TCP,
//! [`preflight_quic`] over QUIC) that names the peer and the reason when a certificate is refused,
//! before Zenoh opens the link. `quic/HOST:PORT` endpoints use the same folder: Zenoh's QUIC link
//! reads the same TLS settings and runs TLS 1.3 inside QUIC (quinn).
//!
//! A host's folder holds three files, every one mode 0600 in an owner-only folder:
//!
//! | file | what |
//! |---|---|
//! | `ca.pem` | the CA certificate: the only issuer a peer's certificate is accepted from |
//! | `cert.pem` | this host's certificate (ECDSA P-256, signed by the CA; names: the host name and every `--addr`; usable to serve and to connect) |
//! | `key.pem` | this host's private key (PKCS#8) |
//!
//! The CA folder (`formation certs init --dir D`) holds `ca.pem` and `ca.key`; the CA key never
//! leaves it. Certificates and keys are made with `rcgen`, handshakes run on `rustls` (ring), the
//! TLS stack Zenoh itself uses; nothing here is home-made cryptography.

use formation_config::node::files;
use rcgen::{
    BasicConstraints, CertificateParams, DistinguishedName, DnType, ExtendedKeyUsagePurpose, IsCa,
    Issuer, KeyPair, KeyUsagePurpose,
};
use rustls::pki_types::pem::PemObject;
use rustls::pki_types::{CertificateDer, PrivateKeyDer, ServerName, UnixTime};
use std::io::{Read, Write};
use std::net::IpAddr;
use std::os::unix::fs::{MetadataExt, OpenOptionsExt};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// The CA certificate, in the CA folder and in every host folder.
pub const CA_CERT: &str = "ca.pem";
/// The CA's private key (CA folder only).
pub const CA_KEY: &str = "ca.key";
/// A host's certificate.
pub const CERT: &str = "cert.pem";
/// A host's private key.
pub const KEY: &str = "key.pem";

/// How long the CA certificate is valid, days (ten years: it is re-made with the project's keys,
/// not rotated on its own).
pub const CA_VALID_DAYS: i64 = 3650;
/// How long a host certificate is valid, days (two years; `formation certs issue` again renews it).
pub const HOST_VALID_DAYS: i64 = 730;

/// Longest the pre-flight handshake waits for the peer (connect, each read).
pub const PREFLIGHT_TIMEOUT: Duration = Duration::from_secs(3);
/// How long the pre-flight waits after its handshake for the peer to refuse this host's certificate
/// (a TLS 1.3 server judges the client's certificate after the client has finished).
pub const PREFLIGHT_VERDICT: Duration = Duration::from_millis(1000);

/// Why certificates cannot be made or read.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum CertError {
    /// The folder is unsafe (a link, another user's, writable by others) or cannot be made.
    Folder {
        /// The folder.
        dir: PathBuf,
        /// Why.
        why: String,
    },
    /// A file to be written exists already (nothing is overwritten).
    Exists(PathBuf),
    /// A file cannot be read, or is not a regular file of this user with the right mode.
    File {
        /// The file.
        path: PathBuf,
        /// Why.
        why: String,
    },
    /// A file does not hold what it should (no certificate, no key, not PEM).
    Content {
        /// The file.
        path: PathBuf,
        /// Why.
        why: String,
    },
    /// A host name or address to certify is not acceptable.
    Name(String),
    /// The certificate could not be made (rcgen's reason).
    Generate(String),
    /// rustls refused the material for a client configuration (its reason).
    Client(String),
}

impl std::fmt::Display for CertError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            CertError::Folder { dir, why } => write!(f, "folder {}: {why}", dir.display()),
            CertError::Exists(p) => write!(
                f,
                "{} exists already (nothing is overwritten: remove it or choose another folder)",
                p.display()
            ),
            CertError::File { path, why } => write!(f, "{}: {why}", path.display()),
            CertError::Content { path, why } => write!(f, "{}: {why}", path.display()),
            CertError::Name(why) => f.write_str(why),
            CertError::Generate(why) => write!(f, "cannot make the certificate: {why}"),
            CertError::Client(why) => f.write_str(why),
        }
    }
}

impl std::error::Error for CertError {}

/// Makes `dir` an owner-only folder (mode 0700; created if missing, never through a link).
fn private_folder(dir: &Path) -> Result<(), CertError> {
    files::ensure_private_dir(dir).map_err(|e| CertError::Folder {
        dir: e.path,
        why: e.why,
    })?;
    restrict(dir)
}

/// Sets mode 0700 on a folder of this user (already checked by [`files::check_private_dir`]).
fn restrict(dir: &Path) -> Result<(), CertError> {
    use std::os::unix::fs::PermissionsExt;
    std::fs::set_permissions(dir, std::fs::Permissions::from_mode(0o700)).map_err(|e| {
        CertError::Folder {
            dir: dir.to_path_buf(),
            why: format!("cannot make it owner-only: {e}"),
        }
    })
}

/// Writes a new file, mode 0600 (`O_CREAT | O_EXCL | O_NOFOLLOW`: never over anything).
fn write_new(path: &Path, text: &str) -> Result<(), CertError> {
    let mut f = files::create_new(path, 0o600).map_err(|e| {
        if e.kind() == std::io::ErrorKind::AlreadyExists {
            CertError::Exists(path.to_path_buf())
        } else {
            CertError::File {
                path: path.to_path_buf(),
                why: format!("cannot create it: {e}"),
            }
        }
    })?;
    f.write_all(text.as_bytes())
        .and_then(|()| f.sync_all())
        .map_err(|e| CertError::File {
            path: path.to_path_buf(),
            why: format!("cannot write it: {e}"),
        })
}

/// Reads a file of this user without following a link at its name; a secret (a key) must also be
/// readable by its owner only.
fn read_own(path: &Path, secret: bool) -> Result<Vec<u8>, CertError> {
    let bad = |why: String| CertError::File {
        path: path.to_path_buf(),
        why,
    };
    let mut f = std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NOFOLLOW | libc::O_NONBLOCK)
        .open(path)
        .map_err(|e| bad(format!("cannot read it: {e}")))?;
    let m = f
        .metadata()
        .map_err(|e| bad(format!("cannot read it: {e}")))?;
    if !m.is_file() {
        return Err(bad("not a regular file".into()));
    }
    if m.uid() != files::current_uid() {
        return Err(bad(format!(
            "it belongs to {}, not to {}",
            files::user_label(m.uid()),
            files::user_label(files::current_uid())
        )));
    }
    if secret && m.mode() & 0o077 != 0 {
        return Err(bad(format!(
            "mode {:o}: a private key must be readable by its owner only (chmod 600)",
            m.mode() & 0o777
        )));
    }
    let mut v = Vec::new();
    f.read_to_end(&mut v)
        .map_err(|e| bad(format!("cannot read it: {e}")))?;
    Ok(v)
}

fn certs_of(path: &Path, pem: &[u8]) -> Result<Vec<CertificateDer<'static>>, CertError> {
    let v: Vec<CertificateDer<'static>> = CertificateDer::pem_slice_iter(pem)
        .collect::<Result<_, _>>()
        .map_err(|e| CertError::Content {
            path: path.to_path_buf(),
            why: format!("not a PEM certificate: {e}"),
        })?;
    if v.is_empty() {
        return Err(CertError::Content {
            path: path.to_path_buf(),
            why: "no certificate in it".into(),
        });
    }
    Ok(v)
}

fn key_of(path: &Path, pem: &[u8]) -> Result<PrivateKeyDer<'static>, CertError> {
    PrivateKeyDer::from_pem_slice(pem).map_err(|e| CertError::Content {
        path: path.to_path_buf(),
        why: format!("no PEM private key in it: {e}"),
    })
}

/// What a host presents and trusts: its `--tls DIR`, read and checked once.
#[derive(Clone)]
pub struct Material {
    /// The folder.
    pub dir: PathBuf,
    /// `ca.pem`, PEM.
    pub ca_pem: Vec<u8>,
    /// `cert.pem`, PEM.
    pub cert_pem: Vec<u8>,
    /// `key.pem`, PEM.
    key_pem: Vec<u8>,
}

impl std::fmt::Debug for Material {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Material")
            .field("dir", &self.dir)
            .finish_non_exhaustive()
    }
}

impl Material {
    /// Reads `dir` (a folder of this user that others cannot write to) and its three files (the
    /// key readable by its owner only); every file must parse.
    pub fn load(dir: &Path) -> Result<Material, CertError> {
        files::check_private_dir(dir).map_err(|why| CertError::Folder {
            dir: dir.to_path_buf(),
            why: why.to_string(),
        })?;
        let ca = dir.join(CA_CERT);
        let cert = dir.join(CERT);
        let key = dir.join(KEY);
        let m = Material {
            dir: dir.to_path_buf(),
            ca_pem: read_own(&ca, false)?,
            cert_pem: read_own(&cert, false)?,
            key_pem: read_own(&key, true)?,
        };
        certs_of(&ca, &m.ca_pem)?;
        certs_of(&cert, &m.cert_pem)?;
        key_of(&key, &m.key_pem)?;
        Ok(m)
    }

    /// The private key, PEM (for Zenoh's configuration).
    pub fn key_pem(&self) -> &[u8] {
        &self.key_pem
    }

    fn client_config(&self, seen: Arc<Mutex<Seen>>) -> Result<rustls::ClientConfig, CertError> {
        let provider = Arc::new(rustls::crypto::ring::default_provider());
        let mut roots = rustls::RootCertStore::empty();
        let ca_path = self.dir.join(CA_CERT);
        for c in certs_of(&ca_path, &self.ca_pem)? {
            roots.add(c).map_err(|e| CertError::Content {
                path: ca_path.clone(),
                why: e.to_string(),
            })?;
        }
        let webpki = rustls::client::WebPkiServerVerifier::builder_with_provider(
            Arc::new(roots),
            provider.clone(),
        )
        .build()
        .map_err(|e| CertError::Client(e.to_string()))?;
        let verifier = Arc::new(Recording {
            inner: webpki,
            seen,
        });
        let certs = certs_of(&self.dir.join(CERT), &self.cert_pem)?;
        let key = key_of(&self.dir.join(KEY), &self.key_pem)?;
        rustls::ClientConfig::builder_with_provider(provider)
            .with_protocol_versions(&[&rustls::version::TLS13])
            .map_err(|e| CertError::Client(e.to_string()))?
            .dangerous()
            .with_custom_certificate_verifier(verifier)
            .with_client_auth_cert(certs, key)
            .map_err(|e| CertError::Content {
                path: self.dir.join(CERT),
                why: e.to_string(),
            })
    }
}

/// What [`Recording`] saw of the server: its certificate (DER) and why it was refused.
#[derive(Debug, Default)]
struct Seen {
    cert: Option<Vec<u8>>,
    refused: Option<rustls::Error>,
}

impl Seen {
    /// The presented certificate, described.
    fn presented(seen: &Mutex<Seen>) -> Option<String> {
        seen.lock()
            .ok()
            .and_then(|s| s.cert.as_deref().map(describe_cert))
    }
}

/// The standard WebPKI verification (only the CA of `ca.pem`, the endpoint's name), recording
/// the certificate the peer presented and the verdict so that a refusal can name them (QUIC
/// reports a refusal as a bare TLS alert).
#[derive(Debug)]
struct Recording {
    inner: Arc<rustls::client::WebPkiServerVerifier>,
    seen: Arc<Mutex<Seen>>,
}

impl rustls::client::danger::ServerCertVerifier for Recording {
    fn verify_server_cert(
        &self,
        end_entity: &CertificateDer<'_>,
        intermediates: &[CertificateDer<'_>],
        server_name: &ServerName<'_>,
        ocsp_response: &[u8],
        now: UnixTime,
    ) -> Result<rustls::client::danger::ServerCertVerified, rustls::Error> {
        let verdict = self.inner.verify_server_cert(
            end_entity,
            intermediates,
            server_name,
            ocsp_response,
            now,
        );
        if let Ok(mut s) = self.seen.lock() {
            s.cert = Some(end_entity.to_vec());
            s.refused = verdict.as_ref().err().cloned();
        }
        verdict
    }

    fn verify_tls12_signature(
        &self,
        message: &[u8],
        cert: &CertificateDer<'_>,
        dss: &rustls::DigitallySignedStruct,
    ) -> Result<rustls::client::danger::HandshakeSignatureValid, rustls::Error> {
        self.inner.verify_tls12_signature(message, cert, dss)
    }

    fn verify_tls13_signature(
        &self,
        message: &[u8],
        cert: &CertificateDer<'_>,
        dss: &rustls::DigitallySignedStruct,
    ) -> Result<rustls::client::danger::HandshakeSignatureValid, rustls::Error> {
        self.inner.verify_tls13_signature(message, cert, dss)
    }

    fn supported_verify_schemes(&self) -> Vec<rustls::SignatureScheme> {
        self.inner.supported_verify_schemes()
    }
}

/// `subject CN "b", issued by CN "formation CA ..."` of a DER certificate (best effort).
fn describe_cert(der: &[u8]) -> String {
    match x509_parser::parse_x509_certificate(der) {
        Ok((_, c)) => format!(
            "certificate of \"{}\" issued by \"{}\"",
            c.subject(),
            c.issuer()
        ),
        Err(_) => "an unreadable certificate".into(),
    }
}

/// Why a TLS peer was refused, or refused this host, found by [`preflight`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum TlsRefusal {
    /// The peer's certificate is not signed by this host's CA (or not for the endpoint's name,
    /// expired, ...): this host refuses it.
    PeerCertificate {
        /// What was wrong (rustls' reason).
        why: String,
        /// The certificate presented (subject, issuer), if one was.
        presented: Option<String>,
    },
    /// The peer refused this host's certificate (a TLS alert).
    OwnCertificate(String),
    /// The handshake failed otherwise (not a TLS server, closed, timed out).
    Handshake(String),
    /// The peer cannot be reached at all.
    Unreachable(String),
}

impl std::fmt::Display for TlsRefusal {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            TlsRefusal::PeerCertificate { why, presented } => {
                write!(f, "its certificate is refused ({why})")?;
                if let Some(p) = presented {
                    write!(f, ": it presented the {p}")?;
                }
                Ok(())
            }
            TlsRefusal::OwnCertificate(why) => write!(
                f,
                "it refused this host's certificate ({why}): is cert.pem signed by the CA the peer trusts?"
            ),
            TlsRefusal::Handshake(why) => write!(f, "TLS handshake failed: {why}"),
            TlsRefusal::Unreachable(why) => write!(f, "cannot reach it: {why}"),
        }
    }
}

fn refusal_of(e: &rustls::Error, presented: Option<String>) -> TlsRefusal {
    use rustls::AlertDescription as A;
    match e {
        rustls::Error::InvalidCertificate(c) => {
            use rustls::CertificateError as C;
            let why = match c {
                C::UnknownIssuer | C::BadSignature => {
                    "not signed by the CA of this host's ca.pem".to_string()
                }
                C::NotValidForName | C::NotValidForNameContext { .. } => format!(
                    "not issued for the endpoint's address ({c:?}): issue it with `formation certs issue --addr ADDRESS`"
                ),
                C::Expired | C::ExpiredContext { .. } => format!("expired ({c:?})"),
                other => format!("{other:?}"),
            };
            TlsRefusal::PeerCertificate { why, presented }
        }
        rustls::Error::AlertReceived(a)
            if matches!(
                a,
                A::UnknownCA
                    | A::BadCertificate
                    | A::CertificateRequired
                    | A::CertificateUnknown
                    | A::UnsupportedCertificate
                    | A::CertificateExpired
                    | A::CertificateRevoked
                    | A::DecryptError
                    | A::AccessDenied
            ) =>
        {
            TlsRefusal::OwnCertificate(format!("TLS alert {a:?}"))
        }
        other => TlsRefusal::Handshake(other.to_string()),
    }
}

fn io_refusal(e: &std::io::Error, presented: Option<String>) -> TlsRefusal {
    match e.get_ref().and_then(|i| i.downcast_ref::<rustls::Error>()) {
        Some(t) => refusal_of(t, presented),
        None => TlsRefusal::Handshake(e.to_string()),
    }
}

/// A TLS 1.3 handshake with the `tls/HOST:PORT` endpoint's server, as Zenoh would make it (this
/// host's certificate presented, the server's checked against `ca.pem` only, and its name against
/// HOST), then a short wait for the server's verdict on this host's certificate. `Ok` when both
/// sides accept; otherwise who refused whom and why. The link is closed (close_notify) after.
pub fn preflight(host: &str, port: u16, m: &Material) -> Result<(), TlsRefusal> {
    let seen = Arc::new(Mutex::new(Seen::default()));
    let cfg = m
        .client_config(seen.clone())
        .map_err(|e| TlsRefusal::Handshake(e.to_string()))?;
    let (name, addr) = resolve(host, port)?;
    let mut sock = std::net::TcpStream::connect_timeout(&addr, PREFLIGHT_TIMEOUT)
        .map_err(|e| TlsRefusal::Unreachable(e.to_string()))?;
    let _ = sock.set_read_timeout(Some(PREFLIGHT_TIMEOUT));
    let _ = sock.set_write_timeout(Some(PREFLIGHT_TIMEOUT));
    let mut conn = rustls::ClientConnection::new(Arc::new(cfg), name)
        .map_err(|e| TlsRefusal::Handshake(e.to_string()))?;
    let presented = || Seen::presented(&seen);
    while conn.is_handshaking() {
        if let Err(e) = conn.complete_io(&mut sock) {
            return Err(io_refusal(&e, presented()));
        }
    }
    // A TLS 1.3 server judges the client's certificate after the client's Finished: an alert
    // comes now, or its session tickets (accepted), or nothing within the verdict time.
    let _ = sock.set_read_timeout(Some(PREFLIGHT_VERDICT));
    let verdict = match conn.read_tls(&mut sock) {
        Ok(0) => Err(TlsRefusal::OwnCertificate(
            "it closed the link after the handshake".into(),
        )),
        Ok(_) => conn
            .process_new_packets()
            .map(|_| ())
            .map_err(|e| refusal_of(&e, presented())),
        Err(e)
            if matches!(
                e.kind(),
                std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
            ) =>
        {
            Ok(())
        }
        Err(e) => Err(io_refusal(&e, presented())),
    };
    conn.send_close_notify();
    let _ = conn.write_tls(&mut sock);
    verdict
}

/// The server name (checked against the certificate) and the first address of `host`.
fn resolve(
    host: &str,
    port: u16,
) -> Result<(ServerName<'static>, std::net::SocketAddr), TlsRefusal> {
    use std::net::ToSocketAddrs;
    let bare = host.trim_start_matches('[').trim_end_matches(']');
    let name = ServerName::try_from(bare.to_string())
        .map_err(|e| TlsRefusal::Handshake(format!("'{bare}' is not a server name: {e}")))?;
    let addr = (bare, port)
        .to_socket_addrs()
        .map_err(|e| TlsRefusal::Unreachable(e.to_string()))?
        .next()
        .ok_or_else(|| TlsRefusal::Unreachable(format!("'{bare}' has no address")))?;
    Ok((name, addr))
}

/// The ALPN protocol names a Zenoh 1.10 QUIC listener may agree to (its streamed and legacy
/// ones, `zenoh-link-commons` `quic/utils.rs`). QUIC requires an agreed protocol, so the
/// pre-flight offers them all; it opens no stream, whichever is agreed.
const ZENOH_QUIC_ALPN: [&[u8]; 5] = [b"zenoh-ms-mr", b"zenoh-ms", b"zenoh-mr", b"zenoh", b"hq-29"];

/// The TLS alert a QUIC CONNECTION_CLOSE carries (RFC 9001 §4.8: error codes 0x100 + alert), if
/// it carries one.
fn quic_alert(code: quinn::TransportErrorCode) -> Option<rustls::AlertDescription> {
    let code = u64::from(code);
    (0x100..0x200)
        .contains(&code)
        .then(|| rustls::AlertDescription::from((code - 0x100) as u8))
}

/// [`preflight`] for a `quic/HOST:PORT` endpoint: the same TLS 1.3 handshake (this host's
/// certificate presented, the server's checked against `ca.pem` only and its name against HOST),
/// carried by QUIC over UDP as Zenoh's QUIC link carries it (quinn, the library under that
/// link), then the same wait for the server's verdict on this host's certificate. UDP has no
/// refused connection: a peer that does not answer within [`PREFLIGHT_TIMEOUT`] is
/// [`TlsRefusal::Unreachable`]. Runs on a thread of its own (quinn needs an async runtime, and
/// the caller may be inside one).
pub fn preflight_quic(host: &str, port: u16, m: &Material) -> Result<(), TlsRefusal> {
    let seen = Arc::new(Mutex::new(Seen::default()));
    let mut cfg = m
        .client_config(seen.clone())
        .map_err(|e| TlsRefusal::Handshake(e.to_string()))?;
    cfg.alpn_protocols = ZENOH_QUIC_ALPN.iter().map(|p| p.to_vec()).collect();
    let crypto = quinn::crypto::rustls::QuicClientConfig::try_from(cfg)
        .map_err(|e| TlsRefusal::Handshake(e.to_string()))?;
    let (name, addr) = resolve(host, port)?;
    let name = name.to_str().into_owned();
    std::thread::spawn(move || {
        let rt = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .map_err(|e| TlsRefusal::Handshake(format!("no runtime for QUIC: {e}")))?;
        rt.block_on(quic_handshake(crypto, addr, name, seen))
    })
    .join()
    .unwrap_or_else(|_| Err(TlsRefusal::Handshake("the QUIC pre-flight failed".into())))
}

async fn quic_handshake(
    crypto: quinn::crypto::rustls::QuicClientConfig,
    addr: std::net::SocketAddr,
    name: String,
    seen: Arc<Mutex<Seen>>,
) -> Result<(), TlsRefusal> {
    use quinn::ConnectionError as E;
    let local: std::net::SocketAddr = if addr.is_ipv4() {
        (std::net::Ipv4Addr::UNSPECIFIED, 0).into()
    } else {
        (std::net::Ipv6Addr::UNSPECIFIED, 0).into()
    };
    let endpoint =
        quinn::Endpoint::client(local).map_err(|e| TlsRefusal::Handshake(e.to_string()))?;
    let config = quinn::ClientConfig::new(Arc::new(crypto));
    // Why a connection ended: this host refused the server (its verifier recorded why), the
    // server refused this host (a TLS alert), or something else.
    let refusal = |e: E| match e {
        E::TransportError(t) => match seen.lock().ok().and_then(|mut s| s.refused.take()) {
            Some(r) => refusal_of(&r, Seen::presented(&seen)),
            None => TlsRefusal::Handshake(t.to_string()),
        },
        E::ConnectionClosed(c) => match quic_alert(c.error_code) {
            Some(a) => refusal_of(&rustls::Error::AlertReceived(a), None),
            None => TlsRefusal::Handshake(c.to_string()),
        },
        E::TimedOut => TlsRefusal::Unreachable("no QUIC answer".into()),
        other => TlsRefusal::Handshake(other.to_string()),
    };
    let connecting = endpoint
        .connect_with(config, addr, &name)
        .map_err(|e| TlsRefusal::Handshake(e.to_string()))?;
    let conn = match tokio::time::timeout(PREFLIGHT_TIMEOUT, connecting).await {
        Err(_) => {
            return Err(TlsRefusal::Unreachable(format!(
                "no QUIC answer within {PREFLIGHT_TIMEOUT:?}"
            )))
        }
        Ok(Err(e)) => return Err(refusal(e)),
        Ok(Ok(c)) => c,
    };
    // As over TCP: the server judges this host's certificate after the client's Finished.
    let verdict = match tokio::time::timeout(PREFLIGHT_VERDICT, conn.closed()).await {
        Err(_) => Ok(()),
        Ok(e) => Err(refusal(e)),
    };
    conn.close(0u32.into(), b"pre-flight");
    let _ = tokio::time::timeout(PREFLIGHT_VERDICT, endpoint.wait_idle()).await;
    verdict
}

/// Checks a host name for a certificate: 1..=32 of `[A-Za-z0-9_-]` (as `formation host --name`).
fn check_name(name: &str) -> Result<(), CertError> {
    if crate::proto::valid_name(name) {
        Ok(())
    } else {
        Err(CertError::Name(format!(
            "--name '{name}': a host name is 1..=32 of [A-Za-z0-9_-]"
        )))
    }
}

fn validity(p: &mut CertificateParams, days: i64) {
    let now = time::OffsetDateTime::now_utc();
    // An hour back: clocks of two hosts differ a little.
    p.not_before = now - time::Duration::hours(1);
    p.not_after = now + time::Duration::days(days);
}

/// `formation certs init --dir DIR`: a new CA, `DIR/ca.pem` and `DIR/ca.key` (both 0600; DIR
/// owner-only, created if missing). Nothing existing is overwritten. Returns the files written.
pub fn init(dir: &Path) -> Result<Vec<PathBuf>, CertError> {
    private_folder(dir)?;
    let (cert_path, key_path) = (dir.join(CA_CERT), dir.join(CA_KEY));
    for p in [&cert_path, &key_path] {
        if std::fs::symlink_metadata(p).is_ok() {
            return Err(CertError::Exists(p.clone()));
        }
    }
    let key = KeyPair::generate().map_err(|e| CertError::Generate(e.to_string()))?;
    let mut p = CertificateParams::default();
    let mut dn = DistinguishedName::new();
    dn.push(DnType::CommonName, "formation CA");
    dn.push(DnType::OrganizationName, "formation");
    p.distinguished_name = dn;
    p.is_ca = IsCa::Ca(BasicConstraints::Constrained(0));
    p.key_usages = vec![
        KeyUsagePurpose::KeyCertSign,
        KeyUsagePurpose::CrlSign,
        KeyUsagePurpose::DigitalSignature,
    ];
    validity(&mut p, CA_VALID_DAYS);
    let cert = p
        .self_signed(&key)
        .map_err(|e| CertError::Generate(e.to_string()))?;
    write_new(&key_path, &key.serialize_pem())?;
    write_new(&cert_path, &cert.pem())?;
    Ok(vec![cert_path, key_path])
}

/// What `formation certs issue` certifies.
#[derive(Debug, Clone)]
pub struct Issue {
    /// The host's name (`formation host --name`): the certificate's common name and a DNS name.
    pub name: String,
    /// Addresses the host is reached at (`tls/ADDR:PORT`): each one a name of the certificate.
    pub addrs: Vec<IpAddr>,
    /// Further DNS names it is reached by.
    pub dns: Vec<String>,
}

/// `formation certs issue --dir CA_DIR --name NAME ... --out OUT`: a key and a certificate for the
/// host, signed by the CA of `ca_dir`, written with a copy of the CA certificate to `out`
/// (`ca.pem`, `cert.pem`, `key.pem`, all 0600; `out` owner-only, created if missing): the folder
/// to copy to that host and give to `--tls`. Nothing existing is overwritten.
pub fn issue(ca_dir: &Path, what: &Issue, out: &Path) -> Result<Vec<PathBuf>, CertError> {
    check_name(&what.name)?;
    files::check_private_dir(ca_dir).map_err(|why| CertError::Folder {
        dir: ca_dir.to_path_buf(),
        why: why.to_string(),
    })?;
    let ca_cert_path = ca_dir.join(CA_CERT);
    let ca_key_path = ca_dir.join(CA_KEY);
    let ca_pem = read_own(&ca_cert_path, false)?;
    let ca_key_pem = read_own(&ca_key_path, true)?;
    let ca_pem_text = String::from_utf8(ca_pem).map_err(|_| CertError::Content {
        path: ca_cert_path.clone(),
        why: "not text".into(),
    })?;
    let ca_key_text = String::from_utf8(ca_key_pem).map_err(|_| CertError::Content {
        path: ca_key_path.clone(),
        why: "not text".into(),
    })?;
    let ca_key = KeyPair::from_pem(&ca_key_text).map_err(|e| CertError::Content {
        path: ca_key_path.clone(),
        why: format!("not a private key: {e}"),
    })?;
    let issuer =
        Issuer::from_ca_cert_pem(&ca_pem_text, ca_key).map_err(|e| CertError::Content {
            path: ca_cert_path.clone(),
            why: format!("not a CA certificate: {e}"),
        })?;
    let mut names = vec![what.name.clone()];
    for d in &what.dns {
        if d.is_empty()
            || d.len() > 253
            || !d
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '.')
        {
            return Err(CertError::Name(format!("--dns '{d}': not a DNS name")));
        }
        names.push(d.clone());
    }
    names.extend(what.addrs.iter().map(IpAddr::to_string));
    let mut p = CertificateParams::new(names).map_err(|e| CertError::Name(e.to_string()))?;
    let mut dn = DistinguishedName::new();
    dn.push(DnType::CommonName, what.name.as_str());
    dn.push(DnType::OrganizationName, "formation");
    p.distinguished_name = dn;
    p.is_ca = IsCa::ExplicitNoCa;
    p.key_usages = vec![KeyUsagePurpose::DigitalSignature];
    p.extended_key_usages = vec![
        ExtendedKeyUsagePurpose::ServerAuth,
        ExtendedKeyUsagePurpose::ClientAuth,
    ];
    p.use_authority_key_identifier_extension = true;
    validity(&mut p, HOST_VALID_DAYS);
    let key = KeyPair::generate().map_err(|e| CertError::Generate(e.to_string()))?;
    let cert = p
        .signed_by(&key, &issuer)
        .map_err(|e| CertError::Generate(e.to_string()))?;
    private_folder(out)?;
    let written = [
        (out.join(KEY), key.serialize_pem()),
        (out.join(CERT), cert.pem()),
        (out.join(CA_CERT), ca_pem_text),
    ];
    for (p, _) in &written {
        if std::fs::symlink_metadata(p).is_ok() {
            return Err(CertError::Exists(p.clone()));
        }
    }
    for (p, text) in &written {
        write_new(p, text)?;
    }
    Ok(written.into_iter().map(|(p, _)| p).collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::os::unix::fs::PermissionsExt;

    fn scratch(tag: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("fm-net-tls-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        d
    }

    fn mode(p: &Path) -> u32 {
        std::fs::symlink_metadata(p).unwrap().mode() & 0o777
    }

    #[test]
    fn a_ca_and_a_host_certificate_are_owner_only_load_and_nothing_is_overwritten() {
        let d = scratch("init");
        let ca = d.join("ca");
        let files = init(&ca).unwrap();
        assert_eq!(mode(&ca), 0o700);
        for f in &files {
            assert_eq!(mode(f), 0o600, "{}", f.display());
        }
        assert!(matches!(init(&ca), Err(CertError::Exists(_))));
        let what = Issue {
            name: "b".into(),
            addrs: vec!["10.0.0.2".parse().unwrap()],
            dns: vec![],
        };
        let out = d.join("b");
        for f in issue(&ca, &what, &out).unwrap() {
            assert_eq!(mode(&f), 0o600, "{}", f.display());
        }
        assert_eq!(mode(&out), 0o700);
        let m = Material::load(&out).unwrap();
        let text = describe_cert(&certs_of(&out.join(CERT), &m.cert_pem).unwrap()[0]);
        assert!(
            text.contains("CN=b") && text.contains("CN=formation CA"),
            "{text}"
        );
        assert!(matches!(issue(&ca, &what, &out), Err(CertError::Exists(_))));
        // A key others may read is refused, named.
        std::fs::set_permissions(out.join(KEY), std::fs::Permissions::from_mode(0o644)).unwrap();
        let e = Material::load(&out).unwrap_err().to_string();
        assert!(e.contains("key.pem") && e.contains("chmod 600"), "{e}");
        // A link in place of the key is refused, not followed.
        std::fs::remove_file(out.join(KEY)).unwrap();
        std::os::unix::fs::symlink(ca.join(CA_KEY), out.join(KEY)).unwrap();
        assert!(Material::load(&out).is_err());
        let bad = Issue {
            name: "no/slash".into(),
            ..what
        };
        assert!(matches!(
            issue(&ca, &bad, &d.join("x")),
            Err(CertError::Name(_))
        ));
        let _ = std::fs::remove_dir_all(&d);
    }

    /// A TLS 1.3 server configuration with `server`'s certificate that requires a client
    /// certificate of `client_ca`'s CA.
    fn server_config(server: &Material, client_ca: &Material) -> rustls::ServerConfig {
        let provider = Arc::new(rustls::crypto::ring::default_provider());
        let mut roots = rustls::RootCertStore::empty();
        for c in certs_of(Path::new("ca"), &client_ca.ca_pem).unwrap() {
            roots.add(c).unwrap();
        }
        let verifier = rustls::server::WebPkiClientVerifier::builder_with_provider(
            Arc::new(roots),
            provider.clone(),
        )
        .build()
        .unwrap();
        rustls::ServerConfig::builder_with_provider(provider)
            .with_protocol_versions(&[&rustls::version::TLS13])
            .unwrap()
            .with_client_cert_verifier(verifier)
            .with_single_cert(
                certs_of(Path::new("cert"), &server.cert_pem).unwrap(),
                key_of(Path::new("key"), server.key_pem()).unwrap(),
            )
            .unwrap()
    }

    /// A rustls server with `server`'s certificate that requires a client certificate of
    /// `client_ca`'s CA; serves one handshake.
    fn serve_once(server: &Material, client_ca: &Material) -> (u16, std::thread::JoinHandle<()>) {
        let cfg = server_config(server, client_ca);
        let l = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
        let port = l.local_addr().unwrap().port();
        let h = std::thread::spawn(move || {
            let (mut s, _) = l.accept().unwrap();
            let _ = s.set_read_timeout(Some(Duration::from_secs(5)));
            let mut c = rustls::ServerConnection::new(Arc::new(cfg)).unwrap();
            while c.is_handshaking() {
                if c.complete_io(&mut s).is_err() {
                    let _ = c.write_tls(&mut s);
                    return;
                }
            }
            let _ = c.complete_io(&mut s);
            let mut buf = [0u8; 64];
            let _ = s.read(&mut buf);
        });
        (port, h)
    }

    /// A QUIC server (quinn, as under Zenoh's QUIC link) on `server_config`, agreeing to one of
    /// Zenoh's protocol names; serves one handshake and waits for the client to close.
    fn serve_quic_once(
        server: &Material,
        client_ca: &Material,
    ) -> (u16, std::thread::JoinHandle<()>) {
        let mut cfg = server_config(server, client_ca);
        cfg.alpn_protocols = vec![b"zenoh".to_vec()];
        let crypto = quinn::crypto::rustls::QuicServerConfig::try_from(cfg).unwrap();
        let (tx, rx) = std::sync::mpsc::channel();
        let h = std::thread::spawn(move || {
            let rt = tokio::runtime::Builder::new_current_thread()
                .enable_all()
                .build()
                .unwrap();
            rt.block_on(async move {
                let config = quinn::ServerConfig::with_crypto(Arc::new(crypto));
                let ep = quinn::Endpoint::server(config, ([127, 0, 0, 1], 0).into()).unwrap();
                tx.send(ep.local_addr().unwrap().port()).unwrap();
                if let Some(incoming) = ep.accept().await {
                    if let Ok(c) = incoming.await {
                        let _ = tokio::time::timeout(Duration::from_secs(5), c.closed()).await;
                    }
                }
                let _ = tokio::time::timeout(Duration::from_secs(1), ep.wait_idle()).await;
            })
        });
        (rx.recv().unwrap(), h)
    }

    /// Host folders of the pre-flight tests: `a` and `b` of one CA, `x` of another, all
    /// certified for 127.0.0.1.
    fn three_hosts(d: &Path) -> (Material, Material, Material) {
        let (ca1, ca2) = (d.join("ca1"), d.join("ca2"));
        init(&ca1).unwrap();
        init(&ca2).unwrap();
        let local = |name: &str| Issue {
            name: name.into(),
            addrs: vec!["127.0.0.1".parse().unwrap()],
            dns: vec![],
        };
        issue(&ca1, &local("b"), &d.join("b")).unwrap();
        issue(&ca1, &local("a"), &d.join("a")).unwrap();
        issue(&ca2, &local("x"), &d.join("x")).unwrap();
        (
            Material::load(&d.join("a")).unwrap(),
            Material::load(&d.join("b")).unwrap(),
            Material::load(&d.join("x")).unwrap(),
        )
    }

    type Serve = fn(&Material, &Material) -> (u16, std::thread::JoinHandle<()>);
    type Preflight = fn(&str, u16, &Material) -> Result<(), TlsRefusal>;

    /// `preflight` against servers of `serve`: admitted with its own CA; a server of another CA
    /// refused here, its certificate named; this host's certificate of another CA (trusting the
    /// server's CA) refused there. The three hosts `three_hosts` made in `d`.
    fn own_ca_admitted_and_another_refused_either_way(
        d: &Path,
        serve: Serve,
        preflight: Preflight,
    ) -> (Material, Material, Material) {
        let (a, b, x) = three_hosts(d);
        let (port, h) = serve(&b, &b);
        assert_eq!(preflight("127.0.0.1", port, &a), Ok(()));
        h.join().unwrap();
        let (port, h) = serve(&x, &x);
        match preflight("127.0.0.1", port, &a) {
            Err(TlsRefusal::PeerCertificate { why, presented }) => {
                assert!(why.contains("not signed by the CA"), "{why}");
                assert!(presented.unwrap().contains("CN=x"));
            }
            other => panic!("{other:?}"),
        }
        h.join().unwrap();
        let mixed = Material {
            ca_pem: b.ca_pem.clone(),
            ..x.clone()
        };
        let (port, h) = serve(&b, &b);
        match preflight("127.0.0.1", port, &mixed) {
            Err(TlsRefusal::OwnCertificate(_)) => {}
            other => panic!("a client certificate of another CA must be refused: {other:?}"),
        }
        h.join().unwrap();
        (a, b, x)
    }

    #[test]
    fn the_quic_preflight_accepts_its_own_ca_and_names_a_certificate_of_another_ca_either_way() {
        let d = scratch("preflight-quic");
        let (a, _, _) =
            own_ca_admitted_and_another_refused_either_way(&d, serve_quic_once, preflight_quic);
        // Nobody on the port: UDP has no refusal, the handshake goes unanswered.
        let port = std::net::UdpSocket::bind("127.0.0.1:0")
            .unwrap()
            .local_addr()
            .unwrap()
            .port();
        assert!(matches!(
            preflight_quic("127.0.0.1", port, &a),
            Err(TlsRefusal::Unreachable(_))
        ));
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn the_preflight_accepts_its_own_ca_and_names_a_certificate_of_another_ca_either_way() {
        let d = scratch("preflight");
        let (a, _, _) = own_ca_admitted_and_another_refused_either_way(&d, serve_once, preflight);
        // The name: a certificate not issued for the address connected to.
        let far = Issue {
            name: "far".into(),
            addrs: vec!["10.9.9.9".parse().unwrap()],
            dns: vec![],
        };
        issue(&d.join("ca1"), &far, &d.join("far")).unwrap();
        let far = Material::load(&d.join("far")).unwrap();
        let (port, h) = serve_once(&far, &far);
        let e = preflight("127.0.0.1", port, &a).unwrap_err().to_string();
        assert!(e.contains("not issued for"), "{e}");
        h.join().unwrap();
        let _ = std::fs::remove_dir_all(&d);
    }
}
