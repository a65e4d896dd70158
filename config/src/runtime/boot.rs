//! Start-up of a role process: arguments, process name, scenario, node, and the final hello.

use super::args::ChildArgs;
use super::messages::Hello;
use super::ports::{publisher, RunNode};
use super::process::Lifeline;
use crate::{ipc, Scenario, Variant};

/// Everything a role process starts with.
#[derive(Debug)]
pub struct Boot {
    /// Its command line.
    pub args: ChildArgs,
    /// The run's scenario (from `<run dir>/scenario.toml`).
    pub scenario: Scenario,
    /// The controller variant.
    pub variant: Variant,
    /// Parent and signal watch.
    pub lifeline: Lifeline,
    /// Its iceoryx2 node under the run prefix.
    pub node: RunNode,
}

/// Parses the command line, names the process and its node `fm-<role>[-<agent id>]`, starts its
/// log (`<run dir>/logs/<role>[-<agent id>].log`), loads the scenario and creates the node. Agent ids
/// are 1-based wherever a person reads them (`--agent` itself is the 0-based index of the wire).
pub fn boot(role: &str) -> Result<Boot, String> {
    let args = ChildArgs::parse(std::env::args_os().skip(1))?;
    let name = match args.agent {
        Some(i) => format!("fm-{role}-{}", i + 1),
        None => format!("fm-{role}"),
    };
    let lifeline = Lifeline::install(&name);
    let log_name = super::logging::log_file_name(role, args.agent);
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
    let text = std::fs::read_to_string(&path)
        .map_err(|e| format!("cannot read {}: {e}", path.display()))?;
    let scenario = Scenario::from_toml_str(&text)
        .map_err(|e| format!("cannot parse {}: {e}", path.display()))?;
    let variant = Variant::parse(&args.variant)
        .ok_or_else(|| format!("unknown variant '{}'", args.variant))?;
    if let Some(i) = args.agent {
        if i >= scenario.n_agents() {
            return Err(format!(
                "agent {} (--agent {i}) does not exist (N = {})",
                i + 1,
                scenario.n_agents()
            ));
        }
    }
    let node = ipc::node(&args.prefix, &name).map_err(|e| e.to_string())?;
    Ok(Boot {
        args,
        scenario,
        variant,
        lifeline,
        node,
    })
}

/// The ports of the hello; keep them alive until the run ends (a dropped publisher may take its
/// undelivered samples with it).
pub struct Greeting {
    _publisher: super::ports::Pub<Hello>,
    _notifier: iceoryx2::port::notifier::Notifier<super::ports::Svc>,
}

impl std::fmt::Debug for Greeting {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Greeting")
    }
}

/// Tells the orchestrator that every port of this process exists.
pub fn hello(node: &RunNode, role: u32, agent: u32) -> Result<Greeting, String> {
    let p = publisher::<Hello>(node, super::HELLO)?;
    let n = super::ports::notifier(node, super::WAKE_ORCHESTRATOR)?;
    super::ports::send(
        &p,
        Hello {
            role,
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
