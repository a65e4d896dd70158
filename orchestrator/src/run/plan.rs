//! The plan of a run, built and checked from the arguments before anything of the run exists:
//! scenario, then placement, then hosts ([`Plan::build`]); then what the run holds on this machine
//! and the others while it lasts: export, hosts prepared, output folder, CPU slot and layout
//! ([`Site::claim`]). Every refusal here is a [`PlanError`] (exit 2) naming the argument.

use super::{export, governor, placement, remote, rt, timing, HostPacing, Mode, RunArgs};
use crate::error::{CommandError, PlanError};
use crate::out_lock::OutLock;
use crate::record::Outputs;
use formation_config::node::members::Membership;
use formation_config::{Scenario, Variant};
use std::path::PathBuf;
use std::rc::Rc;

/// What `formation run` runs, checked: scenario and variant, pacing, outputs, CPUs and hosts.
pub(super) struct Plan {
    /// The scenario, with its overrides, runtime flags and events.
    pub scenario: Scenario,
    /// Controller variant.
    pub variant: Variant,
    /// Pacing, scheduling and observers.
    pub mode: Mode,
    /// The files and live views the recorder writes.
    pub outputs: Outputs,
    /// Output folder.
    pub out: PathBuf,
    /// `--json`: the summary on stdout as JSON.
    pub json: bool,
    /// The CPUs this process may use.
    pub allowed: Vec<usize>,
    /// `--pin`.
    pub pin: placement::PinRequest,
    /// The runs folder (records of running runs, CPU slots).
    pub runs_dir: PathBuf,
    /// The other hosts, reached and checked (`None`: this machine alone).
    pub remote: Option<remote::Remote>,
}

impl Plan {
    /// Checks the arguments in order (scenario, placement, hosts) before anything of the run is
    /// created; on the way, records of runs that are over are reaped and the scheduling of a
    /// realtime run is said.
    pub fn build(args: &RunArgs) -> Result<Plan, CommandError> {
        let (scenario, variant) = args.common.load()?;
        check_scenario(&scenario, args)?;
        let allowed = crate::cpus::allowed();
        let pin = placement::PinRequest::parse(&args.pin, &allowed).map_err(PlanError::from)?;
        // The runs folder must be this user's alone (exit 2 otherwise); records of runs that are
        // over are reaped on the way.
        let runs_dir = crate::live::registry::checked_runs_dir(true)
            .and_then(|d| crate::live::registry::list().map(|live| (d, live)))
            .map(|(d, live)| {
                crate::live::reap_dead_prefixes(&live);
                d.unwrap_or_else(crate::live::registry::runs_dir)
            })
            .map_err(PlanError::from)?;
        // Hosts reached and checked before anything is created (exit 2 naming what is missing or
        // differs).
        let remote = remote::connect(&args.place, &scenario).map_err(PlanError::from)?;
        let mode = Mode {
            realtime: args.realtime,
            wait: args.wait,
            spin_us: args.spin_us,
            rt_priority: rt_priority(args)?,
            // The bridges and the export take one observer slot of every service each.
            observers: args.observers
                + usize::from(remote.is_some())
                + usize::from(args.export.enabled()),
        };
        let out = args.common.out.clone().unwrap_or_else(|| {
            PathBuf::from(format!(
                "out/{}-{}-{}",
                scenario.name,
                variant.name(),
                mode.name()
            ))
        });
        Ok(Plan {
            outputs: Outputs {
                foxglove: args.common.live_options(),
                ros2: args.common.ros2_options(),
                ..Outputs::with(&args.common.record)
            },
            json: args.common.json,
            scenario,
            variant,
            mode,
            out,
            allowed,
            pin,
            runs_dir,
            remote,
        })
    }

    /// What every host is told of the run's pacing.
    pub fn host_pacing(&self) -> HostPacing {
        HostPacing {
            realtime: self.mode.realtime,
            observers: self.mode.observers,
            rt_priority: self.mode.rt_priority,
        }
    }
}

/// The limits of a run on its scenario and `--observers`, and no event that takes an agent down
/// in a realtime run.
fn check_scenario(scenario: &Scenario, args: &RunArgs) -> Result<(), PlanError> {
    if scenario.n_agents() > formation_config::MAX_AGENTS {
        return Err(PlanError::TooManyAgents {
            n: scenario.n_agents(),
            max: formation_config::MAX_AGENTS,
        });
    }
    if args.observers > formation_config::protocol::services::MAX_OBSERVERS {
        return Err(PlanError::Observers {
            given: args.observers,
            max: formation_config::protocol::services::MAX_OBSERVERS,
        });
    }
    if args.realtime {
        // The realtime loops replace a dead agent on the fly (`--restart on-failure`), but do not
        // kill and respawn on the timeline: a timeline crash or hang is refused there.
        let down = scenario
            .events
            .iter()
            .position(|e| e.kind.takes_agent_down());
        if let Some(k) = down {
            return Err(PlanError::NeedsLockstep {
                index: k,
                kind: scenario.events[k].kind.name().to_string(),
            });
        }
    }
    Ok(())
}

/// Realtime: SCHED_FIFO or not, decided once here and said (exit 2 for a busy loop at a realtime
/// priority); lockstep runs never use it (0).
fn rt_priority(args: &RunArgs) -> Result<u32, PlanError> {
    if !args.realtime {
        return Ok(0);
    }
    let s = rt::decide(
        args.rt_priority,
        args.wait == timing::WaitMode::SpinBlock,
        rt::Privilege::of_this_process(),
    )?;
    eprintln!("formation run: plant and agents under {s}");
    Ok(s.priority)
}

/// What a run holds while it lasts, claimed in order before any process starts: the export's
/// endpoints, every host prepared, the output folder's lock, a CPU slot, the layout and the
/// membership file. Released by [`Site::release`].
pub(super) struct Site {
    /// The export, its endpoints bound.
    pub export: Option<export::Opened>,
    /// Every host prepared (services, bridge).
    pub remote: Option<Rc<remote::RemoteRun>>,
    /// Held until the outputs are complete: a second run into the same folder is refused.
    out_lock: OutLock,
    /// The rotation of an automatic layout, claimed atomically (see placement::claim_slot).
    slot: placement::Slot,
    /// Where plant and agents run, decided at the start.
    pub pins: governor::Pins,
    /// Lockstep beside other work: the governor of the placement, and the CPUs it may use.
    pub adapt: Option<(governor::PinGovernor, Vec<usize>)>,
    /// Held until the run's iceoryx2 files are removed; if this process dies, the last role
    /// process to exit removes them (formation_config::node::members).
    membership: Option<Membership>,
}

impl Site {
    /// Claims what run `run_id` (iceoryx2 prefix `prefix`) holds, in order: export endpoints,
    /// hosts, output folder, CPU slot and layout, membership.
    pub fn claim(
        plan: &mut Plan,
        args: &RunArgs,
        run_id: &str,
        prefix: &str,
    ) -> Result<Site, PlanError> {
        // Its endpoints bound before anything of the run exists (exit 2 naming what is refused).
        let export = export::open(
            &args.export,
            args.place.auth(),
            prefix,
            &export::Facts {
                run_id,
                scenario: &plan.scenario,
                variant: plan.variant.name(),
                mode: plan.mode.name(),
            },
        )?;
        // Every host prepares the run (services, bridge) before any process starts anywhere.
        let pacing = plan.host_pacing();
        let remote = plan
            .remote
            .take()
            .map(|r| r.prepare(run_id, prefix, &plan.scenario, plan.variant.name(), pacing))
            .transpose()?
            .map(Rc::new);
        let out_lock = crate::out_lock::acquire(&plan.out, Some(run_id), "formation run")?;
        let (slot, pins, adapt) = layout(plan);
        let membership = match Membership::create(&plan.out, prefix) {
            Ok(m) => Some(m),
            Err(e) => {
                eprintln!("warning: {e}: a killed run would leave its iceoryx2 files behind");
                None
            }
        };
        Ok(Site {
            export,
            remote,
            out_lock,
            slot,
            pins,
            adapt,
            membership,
        })
    }

    /// Releases membership, CPU slot and output folder, in that order (after the run's iceoryx2
    /// files are removed).
    pub fn release(self) {
        let Site {
            out_lock,
            slot,
            membership,
            ..
        } = self;
        drop(membership);
        drop(slot);
        drop(out_lock);
    }
}

/// The CPU slot (an automatic layout is rotated by it), the layout and, in lockstep, whether it
/// adapts to other work (the CPUs are sampled first: governor::START_WINDOW).
fn layout(
    plan: &Plan,
) -> (
    placement::Slot,
    governor::Pins,
    Option<(governor::PinGovernor, Vec<usize>)>,
) {
    let realtime = plan.mode.realtime;
    let slot = if placement::Placement::rotates(&plan.pin, realtime) {
        placement::claim_slot(&plan.runs_dir).unwrap_or_else(|e| {
            eprintln!("warning: {e}; the layout is not rotated");
            placement::Slot::none()
        })
    } else {
        placement::Slot::none()
    };
    let layout = placement::Placement::resolve(&plan.pin, realtime, &plan.allowed, slot.index);
    let adapts = match (realtime, placement::Placement::adapts(&plan.pin, realtime)) {
        (true, _) => governor::Adapts::Nothing,
        (false, true) => governor::Adapts::SchedulingAndPinning,
        (false, false) => governor::Adapts::Scheduling,
    };
    let (pins, adapt) = governor::decide_start(layout, adapts, &plan.allowed);
    (slot, pins, adapt.map(|g| (g, plan.allowed.clone())))
}
