//! `formation run`: one OS process per quadrotor, plus plant and leader, over iceoryx2 shared memory
//! under a per-run prefix, in lockstep (bit-identical to `formation sim`).
//!
//! * [`services`]: every service, created here before any process starts, sized for N.
//! * [`spawn`]: locating, starting, supervising and stopping the role processes.
//! * [`driver`]: start barrier, pacing, and the per-step feed of the [`Recorder`](crate::record::Recorder).
//! * [`cleanup`]: nothing of the run's prefix stays in /dev/shm or /tmp/iceoryx2.
//! * `plan`: the run checked from its arguments (scenario, placement, hosts) and what it holds
//!   while it lasts; `lifecycle`: the run itself, which owns its services, processes, recorder
//!   and takeover from its start to its summary.

mod cleanup;
mod driver;
pub mod export;
#[cfg(feature = "multihost")]
mod fence;
mod governor;
pub mod host_probe;
pub mod injections;
mod lifecycle;
pub(crate) mod placement;
mod plan;
mod proc_load;
mod progress;
#[cfg(feature = "multihost")]
pub(crate) mod remote;
#[cfg(not(feature = "multihost"))]
#[path = "remote_off.rs"]
pub(crate) mod remote;
pub(crate) mod remote_error;
pub mod rt;
mod services;
pub(crate) mod spawn;
pub(crate) mod step_timing;
pub(crate) mod supervise;
pub(crate) mod takeover;
mod timing;

use crate::cli;
use crate::error::CommandError;
use crate::live::registry::Registration;
use driver::Outcome;
use formation_config::protocol::services as names;
use plan::{Plan, Site};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

pub use crate::error::{PlanError, RunError};

/// Arguments of `formation run`.
#[derive(clap::Args, Debug)]
pub struct RunArgs {
    /// Scenario, variant, output directory, overrides.
    #[command(flatten)]
    pub common: cli::RunnerArgs,
    /// Realtime mode: the plant integrates on the wall clock with a deadline per step and the
    /// injected delays are real (see docs/realtime.md); timing goes into summary.json.
    #[arg(long)]
    pub realtime: bool,
    /// Realtime mode: how the plant waits for commands.
    #[arg(long, value_enum, default_value_t = timing::WaitMode::Block)]
    pub wait: timing::WaitMode,
    /// Realtime mode with `--wait spin-block`: busy-poll time before blocking, µs.
    #[arg(long, default_value_t = 20, value_parser = crate::cli::whole_number::<u32>, allow_negative_numbers = true)]
    pub spin_us: u32,
    /// Realtime mode: the scheduling of plant and agents. `auto` (default): SCHED_FIFO at
    /// priority 10 when this process is allowed to (CAP_SYS_NICE in its effective set, as root
    /// has, or RLIMIT_RTPRIO >= 10: checked) and the plant blocks (`--wait block`: never a busy
    /// loop at a realtime priority), the normal policy otherwise; `P` (1..=99): SCHED_FIFO at P
    /// (refused with `--wait spin-block`; the normal policy when not allowed); `0`: the normal
    /// policy. The run says which it got. See docs/realtime.md, "Scheduling".
    #[arg(long, default_value = "auto", value_name = "auto|P", value_parser = rt::parse)]
    pub rt_priority: rt::Requested,
    /// CPU placement of plant and agents: `auto` (lockstep: the automatic layout, plant on the
    /// first CPU this process may use with 4/5 of an even share of the agents, spread over the
    /// order, the other agents round-robin over the other CPUs; not pinned while other programs
    /// keep one of these CPUs busy, checked before the start and every 500 ms; realtime: not
    /// pinned), `always` (the automatic layout whatever the load, also in realtime), `off`, or a
    /// CPU list such as `0,1` or `0-3` (plant on the first, agent i on the CPU i + 1 places
    /// further, round-robin; whatever the load). Leader and orchestrator are never pinned. In
    /// lockstep, beside other work, plant and agents also leave SCHED_BATCH for SCHED_OTHER at
    /// nice -10 under every placement. See docs/runtime.md, "Cost of a step" and "Pinning and
    /// scheduling beside other work".
    #[arg(long, default_value = "auto", value_name = "auto|always|off|CPUS")]
    pub pin: String,
    /// Outside observers the run makes room for: K spare subscribers / listeners on every service
    /// (states, commands, telemetry, steps, events, wake-ups) and K spare nodes, for programs such
    /// as a Python client or `iox2 service subscribe` (docs/services.md). More cost shared memory.
    #[arg(
        long,
        value_name = "K",
        default_value_t = formation_config::protocol::services::DEFAULT_OBSERVERS,
        value_parser = crate::cli::whole_number::<usize>,
        allow_negative_numbers = true
    )]
    pub observers: usize,
    /// Other machines (`formation host` daemons) and the agents placed on them.
    #[command(flatten)]
    pub place: remote::PlaceArgs,
    /// Readers of the run's telemetry on other machines, over Zenoh.
    #[command(flatten)]
    pub export: export::ExportArgs,
}

pub use spawn::{self_exe, SpawnError};

/// How a run is paced.
#[derive(Debug, Clone, Copy)]
struct Mode {
    realtime: bool,
    wait: timing::WaitMode,
    spin_us: u32,
    rt_priority: u32,
    /// Outside observers the services make room for.
    observers: usize,
}

impl Mode {
    fn name(self) -> &'static str {
        if self.realtime {
            "realtime"
        } else {
            "lockstep"
        }
    }
}

/// What every host of a run spread over hosts is told of its pacing (read by `remote` alone:
/// without the feature `multihost` nothing reads it).
#[derive(Debug, Clone, Copy)]
#[cfg_attr(not(feature = "multihost"), allow(dead_code))]
pub(crate) struct HostPacing {
    /// Wall-clock run (`--realtime`) rather than lockstep.
    pub realtime: bool,
    /// Outside observers the services make room for.
    pub observers: usize,
    /// `SCHED_FIFO` priority of the role processes (0: none).
    pub rt_priority: u32,
}

/// How long the role processes get to exit by themselves before they are killed.
const STOP_GRACE: Duration = Duration::from_millis(1000);

/// Entry point of `formation run`: the plan checked from the arguments, what the run holds
/// claimed, the run started, driven and written, then everything released; the `formation` binary
/// prints the error and maps it to the exit code.
pub fn main(args: RunArgs) -> Result<(), CommandError> {
    let mut plan = Plan::build(&args)?;
    let interrupted = Arc::new(AtomicBool::new(false));
    {
        let flag = interrupted.clone();
        if let Err(e) = ctrlc::set_handler(move || flag.store(true, Ordering::SeqCst)) {
            eprintln!("warning: cannot install the Ctrl-C handler: {e}");
        }
    }
    let run_id = new_run_id();
    let prefix = names::run_prefix(&run_id);
    let mut site = Site::claim(&mut plan, &args, &run_id, &prefix)?;
    let ids = lifecycle::Ids {
        run_id: &run_id,
        prefix: &prefix,
    };
    let result = lifecycle::Run::start(&plan, ids, &mut site)
        .and_then(|run| run.drive(&interrupted).finish());
    match cleanup::remove(&prefix, cleanup::OUTSIDE_GRACE) {
        Ok(cleanup::Cleaned::All) => {}
        Ok(cleanup::Cleaned::LeftTo(nodes)) => eprintln!(
            "warning: {} outside node(s) still attached to {prefix} ({}): their files are left to them",
            nodes.len(),
            nodes
                .iter()
                .map(|n| format!("'{}' pid {}", n.name, n.pid))
                .collect::<Vec<_>>()
                .join(", ")
        ),
        Err(e) => eprintln!("warning: {e}"),
    }
    site.release();
    report(&plan, result)
}

/// Prints the end of a run (its summary, or why it stopped) and says how it ended.
fn report(
    plan: &Plan,
    result: Result<(Outcome, crate::record::Summary), RunError>,
) -> Result<(), CommandError> {
    let out = &plan.out;
    match result? {
        (Outcome::Completed, summary) if plan.json => {
            // Standard output holds the summary JSON only (the progress is on stderr).
            println!("{}", summary.to_json());
            crate::sim::result_of(&summary)
        }
        (Outcome::Completed, summary) => {
            summary.print_table();
            match &summary.timing {
                Some(t) if plan.mode.realtime => timing::print(t),
                Some(t) => step_timing::print(t),
                None => {}
            }
            println!("wrote {}/trajectory.csv and summary.json", out.display());
            crate::sim::result_of(&summary)
        }
        (Outcome::Interrupted, _) => Err(CommandError::Interrupted(out.clone())),
        // Named on stderr when it was detected.
        (Outcome::Died(_), _) => Err(CommandError::Died),
        (Outcome::Failed(e), _) => Err(RunError::Failed(e).into()),
    }
}

/// A short id, unique among concurrent runs on this machine (pid and clock).
fn new_run_id() -> String {
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.subsec_nanos())
        .unwrap_or(0);
    format!("{:x}{:04x}", std::process::id(), nanos & 0xffff)
}

/// What the driver keeps up to date for the client commands (`ps`, `inspect`, `inject`).
pub struct Live {
    /// Incoming injection requests, forwarded and logged.
    pub injections: injections::Injections,
    /// The run's registry record.
    pub registration: Registration,
}
