//! A plain Zenoh client that puts and asks arbitrary bytes on arbitrary keys, as any holder of a
//! daemon's credentials can: what the end-to-end tests attack a daemon and a run with (a second
//! tenant, forged frames, fuzzed keys). Nothing of Zenoh appears in its API.

use crate::error::ZenohError;
use crate::session::{Mode, OptionError, Options};
use std::path::PathBuf;
use std::time::{Duration, Instant};
use zenoh::Wait;

/// A client session (see the module documentation).
pub struct Probe {
    session: zenoh::Session,
}

impl Probe {
    /// Connects to `endpoint` with the `user:password` file `auth`, if given.
    pub fn open(endpoint: &str, auth: Option<PathBuf>) -> Result<Probe, OptionError> {
        let o = Options {
            mode: Mode::Client,
            listen: vec![],
            connect: vec![endpoint.to_string()],
            auth,
            tls: None,
            lease_ms: crate::session::DEFAULT_LEASE_MS,
        };
        Ok(Probe { session: o.open()? })
    }

    /// Puts `bytes` on `key` (reliably: blocks rather than drops).
    pub fn put(&self, key: &str, bytes: Vec<u8>) -> Result<(), ZenohError> {
        self.session
            .put(key, bytes)
            .congestion_control(zenoh::qos::CongestionControl::Block)
            .wait()
            .map_err(|e| ZenohError::new(format!("put on {key}"), e))
    }

    /// Asks `key` with `bytes` (none: no payload); every answer's bytes within `timeout`, an
    /// error reply as `Err` text (the answering side's bytes, shown as UTF-8).
    pub fn query(
        &self,
        key: &str,
        bytes: Option<Vec<u8>>,
        timeout: Duration,
    ) -> Result<Vec<Result<Vec<u8>, String>>, ZenohError> {
        // Inner String: an error reply is the answering side's bytes, shown as text, not an error here.
        let mut g = self.session.get(key).timeout(timeout);
        if let Some(b) = bytes {
            g = g.payload(b);
        }
        let replies = g
            .wait()
            .map_err(|e| ZenohError::new(format!("query on {key}"), e))?;
        let mut out = Vec::new();
        while let Ok(r) = replies.recv() {
            out.push(match r.result() {
                Ok(s) => Ok(s.payload().to_bytes().into_owned()),
                Err(e) => Err(String::from_utf8_lossy(&e.payload().to_bytes()).into_owned()),
            });
        }
        Ok(out)
    }

    /// Starts keeping every sample put on `key` (at most `max`), for [`Capture::take`].
    pub fn capture(&self, key: &str, max: usize) -> Result<Capture, ZenohError> {
        let kept = std::sync::Arc::new(std::sync::Mutex::new(Vec::new()));
        let k = kept.clone();
        let sub = self
            .session
            .declare_subscriber(key)
            .callback(move |s| {
                let mut v = k.lock().unwrap_or_else(|p| p.into_inner());
                if v.len() < max {
                    v.push(s.payload().to_bytes().into_owned());
                }
            })
            .wait()
            .map_err(|e| ZenohError::new(format!("subscribe to {key}"), e))?;
        Ok(Capture { kept, _sub: sub })
    }

    /// The ids of the runs whose orchestrator's liveliness token is visible, waiting up to
    /// `timeout` for at least one.
    pub fn run_ids(&self, timeout: Duration) -> Vec<String> {
        let t0 = Instant::now();
        loop {
            let mut v = Vec::new();
            if let Ok(replies) = self
                .session
                .liveliness()
                .get("formation/run/*/orchestrator")
                .timeout(Duration::from_millis(500))
                .wait()
            {
                while let Ok(r) = replies.recv() {
                    if let Ok(s) = r.result() {
                        let k = s.key_expr().as_str();
                        if let Some(id) = k
                            .strip_prefix("formation/run/")
                            .and_then(|r| r.strip_suffix("/orchestrator"))
                        {
                            v.push(id.to_string());
                        }
                    }
                }
            }
            if !v.is_empty() || t0.elapsed() >= timeout {
                v.sort();
                v.dedup();
                return v;
            }
            std::thread::sleep(Duration::from_millis(100));
        }
    }
}

/// Samples kept by [`Probe::capture`] (until dropped).
pub struct Capture {
    kept: std::sync::Arc<std::sync::Mutex<Vec<Vec<u8>>>>,
    _sub: zenoh::pubsub::Subscriber<()>,
}

impl Capture {
    /// The samples kept so far (and forgets them).
    pub fn take(&self) -> Vec<Vec<u8>> {
        std::mem::take(&mut *self.kept.lock().unwrap_or_else(|p| p.into_inner()))
    }
}
