//! Client commands that look at or act on a running `formation run` from another terminal:
//! `ps` (runs and their processes), `inspect` (one agent's live telemetry) and `inject` (faults
//! and delays at runtime).
//!
//! * [`registry`]: how runs are found (a small JSON file per run).
//! * [`procstat`]: liveness and CPU time from `/proc`.
//! * [`validate`]: injection checks and the `--tau` parser.

pub mod inject;
pub mod inspect;
pub mod procstat;
pub mod ps;
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
