//! `formation-leader`: the leader process of `formation run`. It publishes the reference frame of
//! every step, paced by the orchestrator's progress. Started by the orchestrator.
use std::process::ExitCode;

mod bin_support;

fn main() -> ExitCode {
    match bin_support::run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            tracing::error!("{e}");
            eprintln!("formation-leader: {e}");
            ExitCode::from(1)
        }
    }
}
