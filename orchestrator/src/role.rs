//! `formation node <role> ...`: a role process of `formation run` (plant, leader or agent), started
//! by the orchestrator from the same executable, so one install is the whole system.

use crate::error::CommandError;

/// `formation node <role> <args>`: what the orchestrator starts for each role process.
#[derive(clap::Args, Debug)]
pub struct NodeArgs {
    /// plant, leader or agent.
    pub role: String,
    /// The role's arguments, as written by the orchestrator (`ChildArgs`).
    #[arg(trailing_var_arg = true, allow_hyphen_values = true)]
    pub args: Vec<std::ffi::OsString>,
}

/// Runs one role process; a [`CommandError`] (exit code 1, with a one-line error also in its log)
/// on failure.
pub fn main(a: NodeArgs) -> Result<(), CommandError> {
    use formation_config::protocol::messages::Role;
    let role = Role::from_name(&a.role).ok_or_else(|| CommandError::UnknownRole(a.role.clone()))?;
    let args = formation_config::node::args::ChildArgs::parse(a.args)
        .map_err(|source| CommandError::NodeArgs { role, source })?;
    let result = match role {
        Role::Plant => formation_plant::node::run(args),
        Role::Leader => formation_leader::node::run(args),
        Role::Agent => formation_agent::node::run(args),
    };
    result.map_err(|source| {
        tracing::error!("{source}");
        CommandError::Node { role, source }
    })
}
