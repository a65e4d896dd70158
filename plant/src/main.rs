//! `formation-plant`: the plant process of `formation run`. It integrates every quadrotor in
//! lockstep: step k+1 starts only when all N commands of step k are in. Started by the orchestrator.
use std::process::ExitCode;

mod bin_support;

fn main() -> ExitCode {
    match bin_support::run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            tracing::error!("{e}");
            eprintln!("formation-plant: {e}");
            ExitCode::from(1)
        }
    }
}
