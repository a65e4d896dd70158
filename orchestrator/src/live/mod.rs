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

/// The scenario a run is executing (its `scenario.toml`).
pub fn run_scenario(run: &registry::RunRecord) -> Result<Scenario, String> {
    let path = run.out_dir.join("scenario.toml");
    let text = std::fs::read_to_string(&path)
        .map_err(|e| format!("cannot read {}: {e}", path.display()))?;
    Scenario::from_toml_str(&text).map_err(|e| format!("cannot parse {}: {e}", path.display()))
}

/// Whether this user may open the run's iceoryx2 files: the run must be this user's (its record is
/// owned by the user) and its files under the prefix too; otherwise a clear permission error that
/// names the owner (`inspect` and `inject` exit 2 with it).
pub fn check_access(run: &registry::RunRecord, what: &str) -> Result<(), String> {
    if run.is_foreign() {
        return Err(run.permission_error(what));
    }
    let me = formation_config::node::files::current_uid();
    for path in ipc::residue(&run.prefix).unwrap_or_default() {
        use std::os::unix::fs::MetadataExt;
        match std::fs::symlink_metadata(&path) {
            Ok(m) if m.uid() != me => {
                return Err(format!(
                    "permission denied: {} of run {} belongs to {}, not to {}; only the run's \
                     owner can {what} it",
                    path.display(),
                    run.id,
                    formation_config::node::files::user_label(m.uid()),
                    formation_config::node::files::user_label(me)
                ));
            }
            Err(e) if e.kind() == std::io::ErrorKind::PermissionDenied => {
                return Err(format!(
                    "permission denied on {} of run {}: {e}",
                    path.display(),
                    run.id
                ));
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
pub fn client_node(run: &registry::RunRecord, role: &str) -> Result<RunNode, String> {
    ipc::node(&run.prefix, &format!("fm-{role}-{}", std::process::id())).map_err(|e| e.to_string())
}

/// Call after a client's node is dropped: if the run has ended meanwhile, its orchestrator may have
/// cleaned up before this client left, so remove what is left of the run's prefix.
pub fn tidy_after(run: &registry::RunRecord) {
    if !run.is_live() {
        let _ = ipc::remove_residue(&run.prefix);
    }
}
