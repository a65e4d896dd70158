//! `formation-agent`: the controller process of one quadrotor (`--agent i`) in `formation run`.
//! Started by the orchestrator.
use std::process::ExitCode;

mod bin_support;

fn main() -> ExitCode {
    match bin_support::run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            tracing::error!("{e}");
            eprintln!("formation-agent: {e}");
            ExitCode::from(1)
        }
    }
}
