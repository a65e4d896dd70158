//! Why `formation host`, `formation hosts` or `formation certs` did not succeed: one typed error
//! per failure, whose `Display` is the message on stderr (the CLI maps each to its exit code).

use formation_net::session::OptionError;
use formation_net::survey::SurveyError;
use formation_net::tls::CertError;
use formation_runtime::run::rt::RtError;
use formation_runtime::run::SpawnError;

/// Why a command of this crate did not succeed.
#[derive(Debug, thiserror::Error)]
pub enum HostError {
    /// `--name` is no host name (bad input).
    #[error("error: --name '{0}': a host name is 1..=32 of [A-Za-z0-9_-]")]
    Name(String),
    /// The endpoints, the default socket or the credentials are refused (bad input).
    #[error("error: {0}")]
    Link(#[from] OptionError),
    /// The daemon's own executable cannot be found (its agents are started from it).
    #[error("error: {0}")]
    Exe(#[from] SpawnError),
    /// `--max-rt-priority` cannot be granted (bad input).
    #[error("error: --max-rt-priority: {0}")]
    MaxRtPriority(RtError),
    /// The daemon refused to serve or stopped on an error (its name, root folder or endpoints).
    #[error("error: {0}")]
    Serve(#[from] crate::refusal::ServeError),
    /// `formation hosts`: no endpoint could be reached: each with why, one per line.
    #[error("{}", unreachable(.0))]
    Unreachable(Vec<(String, SurveyError)>),
    /// `formation certs`: the CA or a host's certificate could not be made.
    #[error("error: {0}")]
    Certs(#[from] CertError),
}

/// `error: ENDPOINT: WHY`, one line per endpoint.
fn unreachable(failed: &[(String, SurveyError)]) -> String {
    let lines: Vec<String> = failed
        .iter()
        .map(|(ep, e)| format!("error: {ep}: {e}"))
        .collect();
    lines.join("\n")
}
