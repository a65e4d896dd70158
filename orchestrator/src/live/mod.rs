//! What the commands that look at or act on a running `formation run` from another terminal
//! (`ps`, `inspect`, `inject`: crate `formation-live`) share with the run itself, which registers
//! there and checks its injections alike.
//!
//! * [`registry`]: how runs are found (a small JSON file per run).
//! * [`procstat`]: liveness and CPU time from `/proc`.
//! * [`validate`]: injection checks and the `--tau` parser.

pub mod procstat;
pub mod registry;
pub mod validate;

use formation_config::node::ipc;
use formation_config::node::ports::RunNode;
use formation_config::Scenario;
use std::path::PathBuf;

/// Why a command on a running run cannot reach it: its scenario, its files or its services.
#[derive(Debug, thiserror::Error)]
pub enum ClientError {
    /// The run's `scenario.toml` cannot be read.
    #[error("cannot read {}: {source}", path.display())]
    ReadScenario {
        /// The file.
        path: PathBuf,
        /// The file system's error.
        source: std::io::Error,
    },
    /// The run's `scenario.toml` is no scenario.
    #[error("cannot parse {}: {source}", path.display())]
    ParseScenario {
        /// The file.
        path: PathBuf,
        /// The parser's error.
        source: formation_config::scenario::LoadError,
    },
    /// The run is another user's (the record's own message names both).
    #[error("{0}")]
    Foreign(String),
    /// A file of the run's prefix is another user's.
    #[error(
        "permission denied: {} of run {run} belongs to {owner}, not to {me}; only the run's owner can {what} it",
        path.display()
    )]
    NotOwner {
        /// The file.
        path: PathBuf,
        /// The run's id.
        run: String,
        /// Its owner.
        owner: String,
        /// This user.
        me: String,
        /// What the command does, e.g. `inspect`.
        what: String,
    },
    /// A file of the run's prefix cannot be looked at.
    #[error("permission denied on {} of run {run}: {source}", path.display())]
    Denied {
        /// The file.
        path: PathBuf,
        /// The run's id.
        run: String,
        /// The file system's error.
        source: std::io::Error,
    },
    /// The client's iceoryx2 node cannot be made.
    #[error("{0}")]
    Node(#[from] ipc::IpcError),
}

/// The scenario a run is executing (its `scenario.toml`).
pub fn run_scenario(run: &registry::RunRecord) -> Result<Scenario, ClientError> {
    let path = run.out_dir.join("scenario.toml");
    let text = std::fs::read_to_string(&path).map_err(|source| ClientError::ReadScenario {
        path: path.clone(),
        source,
    })?;
    Scenario::from_toml_str(&text).map_err(|source| ClientError::ParseScenario { path, source })
}

/// Whether this user may open the run's iceoryx2 files: the run must be this user's (its record is
/// owned by the user) and its files under the prefix too; otherwise a clear permission error that
/// names the owner (`inspect` and `inject` exit 2 with it).
pub fn check_access(run: &registry::RunRecord, what: &str) -> Result<(), ClientError> {
    if run.is_foreign() {
        return Err(ClientError::Foreign(run.permission_error(what)));
    }
    let me = formation_config::node::files::current_uid();
    for path in ipc::residue(&run.prefix).unwrap_or_default() {
        use std::os::unix::fs::MetadataExt;
        match std::fs::symlink_metadata(&path) {
            Ok(m) if m.uid() != me => {
                return Err(ClientError::NotOwner {
                    path,
                    run: run.id.clone(),
                    owner: formation_config::node::files::user_label(m.uid()),
                    me: formation_config::node::files::user_label(me),
                    what: what.to_string(),
                });
            }
            Err(e) if e.kind() == std::io::ErrorKind::PermissionDenied => {
                return Err(ClientError::Denied {
                    path,
                    run: run.id.clone(),
                    source: e,
                });
            }
            _ => {}
        }
    }
    Ok(())
}

/// The reaper of `formation ps` and `formation run`: removes this user's iceoryx2 files of run
/// prefixes whose runs are not among `live` and whose nodes are all dead (an observer killed after
/// its run ended), naming each on stderr ([`ipc::reap`]). Never another user's, never a live run's.
pub fn reap_dead_prefixes(live: &[registry::RunRecord]) {
    let live: Vec<String> = live.iter().map(|r| r.prefix.clone()).collect();
    for (prefix, n) in ipc::reap(&live, ipc::REAP_MIN_AGE) {
        eprintln!("reaped {n} iceoryx2 file(s) of {prefix}: its run and nodes are all dead");
    }
}

/// A node of this client process under the run's prefix.
pub fn client_node(run: &registry::RunRecord, role: &str) -> Result<RunNode, ClientError> {
    Ok(ipc::node(
        &run.prefix,
        &format!("fm-{role}-{}", std::process::id()),
    )?)
}

/// Call after a client's node is dropped: if the run has ended meanwhile, its orchestrator may have
/// cleaned up before this client left, so remove what is left of the run's prefix.
pub fn tidy_after(run: &registry::RunRecord) {
    if !run.is_live() {
        let _ = ipc::remove_residue(&run.prefix);
    }
}
