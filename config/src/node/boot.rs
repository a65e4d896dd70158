//! Start-up of a role process: arguments, process name, scenario, node, and the final hello.

use super::args::ChildArgs;
use super::error::{NodeError, PortError};
use super::members::{LeaveOnDrop, Membership};
use super::ports::{publisher, RunNode};
use super::process::Lifeline;
use crate::node::ipc;
use crate::protocol::messages::{Hello, Role};
use crate::protocol::services;
use crate::{Scenario, Variant};

/// Everything a role process starts with.
#[derive(Debug)]
pub struct Boot {
    /// Its command line.
    pub args: ChildArgs,
    /// The run's scenario (from `<run dir>/scenario.toml`).
    pub scenario: Scenario,
    /// [`super::restart::scenario_hash`] of that file: what the run's checkpoints carry.
    pub scenario_hash: u64,
    /// The controller variant.
    pub variant: Variant,
    /// Parent and signal watch.
    pub lifeline: Lifeline,
    /// Its iceoryx2 node under the run prefix.
    pub node: RunNode,
    /// Its membership of the run, left after the node is dropped (declared after it): the last
    /// process of a run whose orchestrator is gone removes the run's iceoryx2 files
    /// ([`super::members`]).
    pub membership: LeaveOnDrop,
}

/// Names the process and its node `fm-<role>[-<agent id>]`, starts its log
/// (`<run dir>/logs/<role>[-<agent id>].log`), loads the scenario and creates the node. Agent ids
/// are 1-based wherever a person reads them (`--agent` itself is the 0-based index of the wire).
pub fn boot(role: Role, args: ChildArgs) -> Result<Boot, NodeError> {
    let name = role.process_name(args.agent);
    let lifeline = Lifeline::install(&name);
    let log_name = super::logging::log_file_name(role.name(), args.agent);
    if let Err(e) = super::logging::init(&args.run_dir, &log_name, false) {
        eprintln!("{name}: {e}");
    }
    tracing::info!(
        pid = std::process::id(),
        run = %args.run_id,
        agent = args.agent.map(|i| i + 1),
        "{name} starting"
    );
    let path = args.run_dir.join("scenario.toml");
    let text = std::fs::read_to_string(&path).map_err(|e| NodeError::File {
        path: path.clone(),
        detail: format!("cannot read: {e}"),
    })?;
    let scenario = Scenario::from_toml_str(&text).map_err(|e| NodeError::File {
        path: path.clone(),
        detail: format!("cannot parse: {e}"),
    })?;
    let variant = Variant::parse(&args.variant)
        .ok_or_else(|| NodeError::Args(format!("unknown variant '{}'", args.variant)))?;
    if let Some(i) = args.agent {
        if i >= scenario.n_agents() {
            return Err(NodeError::Scenario(format!(
                "agent {} (--agent {i}) does not exist (N = {})",
                i + 1,
                scenario.n_agents()
            )));
        }
    }
    let joined = match &args.members {
        Some(lock) => Membership::join_file(lock, &args.prefix),
        None => Membership::join(&args.run_dir, &args.prefix),
    };
    let membership = match joined {
        Ok(m) => Some(m),
        Err(e) => {
            tracing::warn!("{e}: this process will not clean up after a dead orchestrator");
            None
        }
    };
    let membership = LeaveOnDrop(membership);
    let node = ipc::node(&args.prefix, &name)?;
    Ok(Boot {
        args,
        scenario_hash: super::restart::scenario_hash(text.as_bytes()),
        scenario,
        variant,
        lifeline,
        node,
        membership,
    })
}

/// The ports of the hello; keep them alive until the run ends (a dropped publisher may take its
/// undelivered samples with it).
pub struct Greeting {
    _publisher: super::ports::Output<Hello>,
    _notifier: iceoryx2::port::notifier::Notifier<super::ports::Svc>,
}

impl std::fmt::Debug for Greeting {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Greeting")
    }
}

/// Tells the orchestrator that every port of this process exists.
pub fn hello(node: &RunNode, role: Role, agent: u32) -> Result<Greeting, PortError> {
    let p = publisher(node, &services::HELLO.named())?;
    let n = super::ports::notifier(node, &services::WAKE_ORCHESTRATOR.named())?;
    super::ports::send(
        &p,
        Hello {
            role: role as u32,
            agent,
            pid: std::process::id(),
            _pad: 0,
        },
    )?;
    super::ports::poke(&n);
    Ok(Greeting {
        _publisher: p,
        _notifier: n,
    })
}
