//! `formation hosts`: every daemon reachable through any of the given endpoints.
//!
//! A Zenoh client session keeps one link (to the first endpoint it reaches), so one session over
//! several endpoints sees the daemons behind one of them only. The survey opens one client
//! session per endpoint, all at once (one thread each), asks each for the daemons it sees (their
//! liveliness tokens, then each one's info), closes it, and merges the answers by daemon identity
//! ([`DaemonKey`]): a daemon seen through two endpoints (two endpoints of one daemon, or a daemon
//! behind another one it is linked to) is listed once, with every endpoint it was seen through.
//! Each session stays a client, the role the daemons' routing tolerates coming and going
//! (docs/multi-host.md: a router that joins the daemons and leaves at once upsets their routing
//! for seconds). An endpoint whose session cannot be opened is diagnosed
//! ([`crate::session::diagnose`]): an authentication failure is reported as one.

use crate::cluster::{Cluster, HandshakeError};
use crate::proto::HostInfo;
use crate::session::{self, Mode, Options};
use serde::Serialize;
use std::collections::BTreeMap;
use std::time::Duration;

/// What tells two daemons apart: its name, its process id and its listening endpoints. Two
/// answers with the same key are one daemon reached twice.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord)]
pub struct DaemonKey {
    /// `--name`.
    pub name: String,
    /// Daemon pid.
    pub pid: u32,
    /// `--listen` endpoints.
    pub listen: Vec<String>,
}

impl DaemonKey {
    /// The key of a daemon's info.
    pub fn of(i: &HostInfo) -> DaemonKey {
        DaemonKey {
            name: i.name.clone(),
            pid: i.pid,
            listen: i.listen.clone(),
        }
    }
}

/// A daemon of the survey: its info (the first answer) and the endpoints it was seen through, in
/// the order they were given.
#[derive(Debug, Clone, Serialize)]
pub struct Listed {
    /// What the daemon answered.
    #[serde(flatten)]
    pub info: HostInfo,
    /// The `--connect` endpoints through which it answered.
    pub via: Vec<String>,
}

/// What a survey found.
#[derive(Debug, Clone)]
pub struct Survey {
    /// Every daemon that answered, once each, by name then pid.
    pub hosts: Vec<Listed>,
    /// Endpoints whose session could not be opened, with why.
    pub failed: Vec<(String, SurveyError)>,
}

/// Why an endpoint could not be surveyed.
#[derive(Debug, Clone, thiserror::Error)]
pub enum SurveyError {
    /// The endpoint is unreachable or refused this host: the diagnosis of its link
    /// ([`session::diagnose`]).
    #[error("{0}")]
    Diagnosed(String),
    /// The client session did not open (and the link showed no problem).
    #[error(transparent)]
    Session(#[from] HandshakeError),
}

/// Merges the answers per endpoint (in the order the endpoints were given) into one entry per
/// daemon ([`DaemonKey`]), sorted by name then pid.
pub fn merge(answers: Vec<(String, Vec<HostInfo>)>) -> Vec<Listed> {
    let mut by_key: BTreeMap<DaemonKey, Listed> = BTreeMap::new();
    for (endpoint, infos) in answers {
        for info in infos {
            let l = by_key
                .entry(DaemonKey::of(&info))
                .or_insert_with(|| Listed {
                    info,
                    via: Vec::new(),
                });
            if !l.via.contains(&endpoint) {
                l.via.push(endpoint.clone());
            }
        }
    }
    by_key.into_values().collect()
}

/// The daemons one client session to `endpoint` sees, each asked for its info within `timeout`;
/// a session that cannot be opened is diagnosed.
fn ask(o: &Options, endpoint: &str, timeout: Duration) -> Result<Vec<HostInfo>, SurveyError> {
    let opts = Options {
        mode: Mode::Client,
        listen: vec![],
        connect: vec![endpoint.to_string()],
        ..o.clone()
    };
    let cluster = match Cluster::open(&opts) {
        Ok(c) => c,
        Err(e) => {
            return Err(match session::diagnose(&opts, endpoint) {
                Some(f) => SurveyError::Diagnosed(f.problem_text()),
                None => SurveyError::Session(e),
            })
        }
    };
    Ok(cluster
        .names(timeout)
        .iter()
        .filter_map(|n| cluster.info(n, timeout).map(|(i, _)| i))
        .collect())
}

/// Asks every endpoint of `o.connect` at once (one client session each, [`ask`], with `o`'s
/// credentials) and merges the answers.
pub fn survey(o: &Options, timeout: Duration) -> Survey {
    let endpoints = &o.connect;
    let results: Vec<(String, Result<Vec<HostInfo>, SurveyError>)> = std::thread::scope(|s| {
        let handles: Vec<_> = endpoints
            .iter()
            .map(|ep| s.spawn(move || ask(o, ep, timeout)))
            .collect();
        endpoints
            .iter()
            .cloned()
            .zip(handles)
            .map(|(ep, h)| {
                let r = h.join().unwrap_or_else(|_| {
                    Err(HandshakeError::Session("the survey thread panicked".into()).into())
                });
                (ep, r)
            })
            .collect()
    });
    let mut answers = Vec::new();
    let mut failed = Vec::new();
    for (ep, r) in results {
        match r {
            Ok(infos) => answers.push((ep, infos)),
            Err(e) => failed.push((ep, e)),
        }
    }
    Survey {
        hosts: merge(answers),
        failed,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::identity::Identity;

    fn info(name: &str, pid: u32, listen: &str) -> HostInfo {
        HostInfo {
            name: name.into(),
            cpus: 2,
            listen: vec![listen.into()],
            runs: 0,
            pid,
            identity: Identity {
                protocol: crate::identity::PROTOCOL,
                build: "0.1.0+test".into(),
                layout: "test".into(),
            },
            clock_us: pid as u64,
            shm: None,
            uid: None,
            iox2_root: None,
        }
    }

    #[test]
    fn a_daemon_seen_through_two_endpoints_is_listed_once_with_both_and_distinct_ones_apart() {
        let (a, b) = ("tcp/10.0.1.2:7447", "tcp/10.0.2.2:7447");
        let h1 = info("h1", 100, a);
        let h2 = info("h2", 200, b);
        // h2 is linked to h1, so the session to a sees both.
        let merged = merge(vec![
            (a.to_string(), vec![h1.clone(), h2.clone()]),
            (b.to_string(), vec![h2.clone()]),
            (a.to_string(), vec![h1.clone()]),
        ]);
        let names: Vec<_> = merged.iter().map(|l| l.info.name.as_str()).collect();
        assert_eq!(names, ["h1", "h2"]);
        assert_eq!(merged[0].via, [a]);
        assert_eq!(merged[1].via, [a, b]);
        // Same name, another process or endpoint: another daemon, listed apart.
        let other = info("h1", 300, "tcp/10.0.3.2:7447");
        let merged = merge(vec![(a.to_string(), vec![h1, other])]);
        assert_eq!(merged.len(), 2);
        let json = serde_json::to_value(&merged[0]).unwrap();
        assert_eq!(json["name"], "h1");
        assert_eq!(json["via"][0], a);
        assert!(json["identity"].is_object(), "{json}");
    }
}
