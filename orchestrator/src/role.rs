//! `formation node <role> ...`: a role process of `formation run` (plant, leader or agent), started
//! by the orchestrator from the same executable, so one install is the whole system.

use crate::cli;
use std::process::ExitCode;

/// `formation node <role> <args>`: what the orchestrator starts for each role process.
#[derive(clap::Args, Debug)]
pub struct NodeArgs {
    /// plant, leader or agent.
    pub role: String,
    /// The role's arguments, as written by the orchestrator (`ChildArgs`).
    #[arg(trailing_var_arg = true, allow_hyphen_values = true)]
    pub args: Vec<std::ffi::OsString>,
}

/// Runs one role process; exit code 1 with a one-line error (also in its log) on failure.
pub fn main(a: NodeArgs) -> ExitCode {
    use formation_config::protocol::messages::Role;
    let Some(role) = Role::from_name(&a.role) else {
        eprintln!(
            "formation node: unknown role '{}' (plant, leader or agent)",
            a.role
        );
        return ExitCode::from(cli::EXIT_INVALID);
    };
    let args = match formation_config::node::args::ChildArgs::parse(a.args) {
        Ok(args) => args,
        Err(e) => {
            eprintln!("formation node {role}: {e}");
            return ExitCode::from(cli::EXIT_INVALID);
        }
    };
    let result = match role {
        Role::Plant => formation_plant::node::run(args),
        Role::Leader => formation_leader::node::run(args),
        Role::Agent => formation_agent::node::run(args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            tracing::error!("{e}");
            eprintln!("fm-{role}: {e}");
            ExitCode::from(1)
        }
    }
}
