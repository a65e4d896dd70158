//! `formation run`: one OS process per quadrotor, plus plant and leader, over iceoryx2 shared memory
//! under a per-run prefix, in lockstep (bit-identical to `formation sim`).
//!
//! * [`services`]: every service, created here before any process starts, sized for N.
//! * [`spawn`]: locating, starting, supervising and stopping the role processes.
//! * [`driver`]: start barrier, pacing, and the per-step feed of the [`Recorder`].
//! * [`cleanup`]: nothing of the run's prefix stays in /dev/shm or /tmp/iceoryx2.

mod cleanup;
mod driver;
pub mod export;
mod governor;
pub mod host_probe;
pub mod injections;
pub(crate) mod placement;
mod proc_load;
mod progress;
#[cfg(feature = "multihost")]
pub(crate) mod remote;
#[cfg(not(feature = "multihost"))]
#[path = "remote_off.rs"]
pub(crate) mod remote;
pub mod rt;
mod services;
mod spawn;
pub(crate) mod step_timing;
pub(crate) mod supervise;
pub(crate) mod takeover;
mod timing;

use crate::cli;
use crate::live::registry::{unix_now, ProcessEntry, Registration, RunRecord, LOCAL_HOST};
use crate::record::Recorder;
use driver::Outcome;
use formation_config::node::args::ChildArgs;
use formation_config::node::ipc;
use formation_config::node::members::Membership;
use formation_config::protocol::messages::Role;
use formation_config::protocol::services as names;
use formation_config::{Scenario, Variant};
use spawn::RoleProcess;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

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

pub use spawn::self_exe;

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

/// Entry point of `formation run`.
pub fn main(args: RunArgs) -> ExitCode {
    let (scenario, variant) = match args.common.load() {
        Ok(v) => v,
        Err(code) => return code,
    };
    if scenario.n_agents() > formation_config::MAX_AGENTS {
        eprintln!(
            "error: {} agents: at most {} are supported",
            scenario.n_agents(),
            formation_config::MAX_AGENTS
        );
        return ExitCode::from(cli::EXIT_INVALID);
    }
    if args.observers > formation_config::protocol::services::MAX_OBSERVERS {
        eprintln!(
            "error: --observers {}: at most {} outside observers are supported",
            args.observers,
            formation_config::protocol::services::MAX_OBSERVERS
        );
        return ExitCode::from(cli::EXIT_INVALID);
    }
    if args.realtime {
        // The realtime loops replace a dead agent on the fly (`--restart on-failure`), but do not
        // kill and respawn on the timeline: a timeline crash or hang is refused there.
        let down = scenario
            .events
            .iter()
            .position(|e| e.kind.takes_agent_down());
        if let Some(k) = down {
            eprintln!(
                "error: events[{k}]: a `{}` event needs a lockstep run (realtime runs take faults, delays, link faults and message loss; docs/failures.md)",
                scenario.events[k].kind.name()
            );
            return ExitCode::from(cli::EXIT_INVALID);
        }
    }
    let allowed = crate::cpus::allowed();
    let pin = match placement::PinRequest::parse(&args.pin, &allowed) {
        Ok(p) => p,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::from(cli::EXIT_INVALID);
        }
    };
    // The runs folder must be this user's alone (exit 2 otherwise); records of runs that are over
    // are reaped on the way.
    let runs_dir = match crate::live::registry::checked_runs_dir(true)
        .and_then(|d| crate::live::registry::list().map(|live| (d, live)))
    {
        Ok((d, live)) => {
            crate::live::reap_dead_prefixes(&live);
            d.unwrap_or_else(crate::live::registry::runs_dir)
        }
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::from(cli::EXIT_INVALID);
        }
    };
    // Hosts reached and checked before anything is created (exit 2 naming what is missing or
    // differs).
    let remote = match remote::connect(&args.place, &scenario) {
        Ok(r) => r,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::from(cli::EXIT_INVALID);
        }
    };
    // Realtime: SCHED_FIFO or not, decided once here and said (exit 2 for a busy loop at a
    // realtime priority); lockstep runs never use it.
    let rt_priority = if args.realtime {
        match rt::decide(
            args.rt_priority,
            args.wait == timing::WaitMode::SpinBlock,
            rt::Privilege::of_this_process(),
        ) {
            Ok(s) => {
                eprintln!("formation run: plant and agents under {s}");
                s.priority
            }
            Err(e) => {
                eprintln!("error: {e}");
                return ExitCode::from(cli::EXIT_INVALID);
            }
        }
    } else {
        0
    };
    let mode = Mode {
        realtime: args.realtime,
        wait: args.wait,
        spin_us: args.spin_us,
        rt_priority,
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
    let interrupted = Arc::new(AtomicBool::new(false));
    {
        let flag = interrupted.clone();
        if let Err(e) = ctrlc::set_handler(move || flag.store(true, Ordering::SeqCst)) {
            eprintln!("warning: cannot install the Ctrl-C handler: {e}");
        }
    }
    let run_id = new_run_id();
    let prefix = names::run_prefix(&run_id);
    // Its endpoints bound before anything of the run exists (exit 2 naming what is refused).
    let export = match export::open(
        &args.export,
        args.place.auth(),
        &prefix,
        &export::Facts {
            run_id: &run_id,
            scenario: &scenario,
            variant: variant.name(),
            mode: mode.name(),
        },
    ) {
        Ok(e) => e,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::from(cli::EXIT_INVALID);
        }
    };
    // Every host prepares the run (services, bridge) before any process starts anywhere.
    let remote = match remote
        .map(|r| {
            r.prepare(
                &run_id,
                &prefix,
                &scenario,
                variant.name(),
                HostPacing {
                    realtime: mode.realtime,
                    observers: mode.observers,
                    rt_priority: mode.rt_priority,
                },
            )
        })
        .transpose()
    {
        Ok(r) => r.map(std::rc::Rc::new),
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::from(cli::EXIT_INVALID);
        }
    };
    // Held until the outputs are complete: a second run into the same folder is refused.
    let out_lock = match crate::out_lock::acquire(&out, Some(&run_id), "formation run") {
        Ok(l) => l,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::from(cli::EXIT_INVALID);
        }
    };
    // The rotation of an automatic layout, claimed atomically (see placement::claim_slot).
    let rotating = placement::Placement::rotates(&pin, args.realtime);
    let slot = if rotating {
        placement::claim_slot(&runs_dir).unwrap_or_else(|e| {
            eprintln!("warning: {e}; the layout is not rotated");
            placement::Slot::none()
        })
    } else {
        placement::Slot::none()
    };
    let layout = placement::Placement::resolve(&pin, args.realtime, &allowed, slot.index);
    // Lockstep: the CPUs are sampled first (governor::START_WINDOW).
    let adapts = match (
        args.realtime,
        placement::Placement::adapts(&pin, args.realtime),
    ) {
        (true, _) => governor::Adapts::Nothing,
        (false, true) => governor::Adapts::SchedulingAndPinning,
        (false, false) => governor::Adapts::Scheduling,
    };
    let (pins, adapt) = governor::decide_start(layout, adapts, &allowed);
    // Held until the run's iceoryx2 files are removed below; if this process dies, the last role
    // process to exit removes them (formation_config::node::members).
    let membership = match Membership::create(&out, &prefix) {
        Ok(m) => Some(m),
        Err(e) => {
            eprintln!("warning: {e}: a killed run would leave its iceoryx2 files behind");
            None
        }
    };
    let result = run(
        &scenario,
        variant,
        mode,
        crate::record::Outputs {
            foxglove: args.common.live_options(),
            ros2: args.common.ros2_options(),
            ..crate::record::Outputs::with(&args.common.record)
        },
        (&pins, adapt.map(|g| (g, allowed))),
        &out,
        &run_id,
        &prefix,
        &interrupted,
        remote,
        export,
    );
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
    drop(membership);
    drop(slot);
    drop(out_lock);
    match result {
        Ok((Outcome::Completed, summary)) if args.common.json => {
            // Standard output holds the summary JSON only (the progress is on stderr).
            println!("{}", summary.to_json());
            crate::sim::exit_code(&summary)
        }
        Ok((Outcome::Completed, summary)) => {
            summary.print_table();
            match &summary.timing {
                Some(t) if mode.realtime => timing::print(t),
                Some(t) => step_timing::print(t),
                None => {}
            }
            println!("wrote {}/trajectory.csv and summary.json", out.display());
            crate::sim::exit_code(&summary)
        }
        Ok((Outcome::Interrupted, _)) => {
            eprintln!(
                "interrupted: outputs up to the last recorded step are in {}",
                out.display()
            );
            ExitCode::from(cli::EXIT_INTERRUPTED)
        }
        // Named on stderr when it was detected.
        Ok((Outcome::Died(_), _)) => ExitCode::from(1),
        Ok((Outcome::Failed(e), _)) | Err(e) => {
            eprintln!("error: {e}");
            ExitCode::from(1)
        }
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

/// Kills and reaps the role processes if the run returns early.
struct Children(Vec<RoleProcess>);

impl Drop for Children {
    fn drop(&mut self) {
        spawn::stop_all(&mut self.0, Duration::ZERO);
    }
}

#[allow(clippy::too_many_arguments)] // the run's settings, each of its own kind
fn run(
    scenario: &Scenario,
    variant: Variant,
    mode: Mode,
    outputs: crate::record::Outputs,
    (pins, adapt): (&governor::Pins, Option<(governor::PinGovernor, Vec<usize>)>),
    out: &Path,
    run_id: &str,
    prefix: &str,
    interrupted: &AtomicBool,
    remote: Option<std::rc::Rc<remote::RemoteRun>>,
    export: Option<export::Opened>,
) -> Result<(Outcome, crate::record::Summary), String> {
    if !mode.realtime && pins.quiet() {
        // Lockstep on a quiet machine: this thread, the CSV writer and every role process (they
        // inherit it) run under SCHED_BATCH: a woken process waits for the running one to block
        // instead of preempting it (see formation_config::node::sched::batch_policy). Beside other
        // work they do not (governor: the role processes then preempt it).
        if let Err(e) = formation_config::node::sched::batch_policy() {
            eprintln!("warning: {e}; running under the normal policy");
        }
    }
    let n = scenario.n_agents();
    let exe = spawn::self_exe()?;
    let mut recorder = Recorder::create_with(scenario, variant, mode.name(), out, outputs)
        .map_err(|e| format!("cannot write outputs to {}: {e}", out.display()))?;
    let run_dir = std::fs::canonicalize(out).unwrap_or_else(|_| out.to_path_buf());
    crate::sim::write_resolved_scenario(scenario, &run_dir)
        .map_err(|e| format!("cannot write {}/scenario.toml: {e}", run_dir.display()))?;
    if let Err(e) = cleanup::write_iox2_config(&run_dir, prefix) {
        eprintln!("warning: {e}");
    }
    // The logs of an earlier run in the same folder: a log is appended to across the restarts of
    // one run only (formation_config::node::logging).
    let _ = std::fs::remove_dir_all(run_dir.join("logs"));
    if let Err(e) = formation_config::node::logging::init(&run_dir, "orchestrator.log", true) {
        eprintln!("warning: {e}");
    }
    let node = ipc::node(prefix, "fm-orchestrator").map_err(|e| e.to_string())?;
    let sizing = names::Sizing::for_scenario(scenario, mode.realtime, mode.observers);
    let services = services::RunServices::create(&node, sizing)?;
    if let Some(r) = &remote {
        r.attach(prefix, sizing, &run_dir)?;
    }
    // Reads the services as an outside observer from the first step on; stopped after the role
    // processes, once it has put their last samples.
    let export = export.map(export::Opened::start).transpose()?;
    let ports = driver::Ports::open(&node, n, !mode.realtime)?;
    let timing_dir = formation_config::node::timing::dir(&run_dir);
    if mode.realtime {
        // Stale files of an earlier run in the same directory must not be merged.
        let _ = std::fs::remove_dir_all(&timing_dir);
    }
    let child_args = |agent: Option<usize>| ChildArgs {
        run_id: run_id.to_string(),
        prefix: prefix.to_string(),
        run_dir: run_dir.clone(),
        variant: variant.name().to_string(),
        agent,
        realtime: mode.realtime,
        spin_us: match mode.wait {
            timing::WaitMode::Block => 0,
            timing::WaitMode::SpinBlock => mode.spin_us,
        },
        rt_priority: mode.rt_priority,
        rejoin_at: None,
        members: None,
    };
    // Realtime: the host's own timer noise just before the run, under the plant's scheduling, on
    // a thread that keeps the normal nice value the orchestrator gives up below.
    let prober = mode
        .realtime
        .then(|| host_probe::Prober::start(mode.rt_priority))
        .and_then(|p| p.map_err(|e| eprintln!("warning: {e}")).ok());
    let probed_before = prober.as_ref().and_then(host_probe::Prober::measure);
    let mut children = Children(Vec::with_capacity(n + 2));
    children.0.push(pins.spawn(governor::Place::Plant, |cpu| {
        spawn::spawn(&exe, Role::Plant, "plant".into(), &child_args(None), cpu)
    })?);
    children.0.push(pins.spawn(governor::Place::Anywhere, |_| {
        spawn::spawn(&exe, Role::Leader, "leader".into(), &child_args(None), None)
    })?);
    pins.add_anywhere(std::process::id());
    for i in 0..n {
        let label = format!("agent {} (--agent {i})", i + 1);
        children
            .0
            .push(match remote.as_ref().filter(|r| r.is_remote(i)) {
                Some(r) => r.spawn(i, label, &child_args(Some(i)))?,
                None => pins.spawn(governor::Place::Agent(i), |cpu| {
                    spawn::spawn(&exe, Role::Agent, label, &child_args(Some(i)), cpu)
                })?,
            });
    }
    // Every child is started (they keep the normal priority): from here on a lockstep orchestrator
    // records behind the plant, with slack, and yields the CPU to plant and agents when they wake
    // up; the successors of a takeover are started at the priority the others were. A realtime
    // plant does not wait for the recorder: there the orchestrator keeps its priority, or a busy
    // machine would leave it behind the wall clock until the step records overflow.
    spawn::keep_launch_priority();
    if !mode.realtime {
        formation_config::node::sched::background_thread();
    }
    let mut pinned = pins.describe(n);
    // Stopped once the steps are over (or when the run returns on an error).
    let governor_thread =
        adapt.map(|(g, allowed)| governor::Governor::start(pins.clone(), g, allowed));
    let pids: Vec<String> = children.0.iter().map(|c| c.pid().to_string()).collect();
    if let Some(r) = &remote {
        pinned = format!("{}; {pinned}", r.describe());
    }
    eprintln!(
        "formation run: id {run_id}, iceoryx2 prefix {prefix}, {n} agents, {} steps; pids {}; {pinned}",
        scenario.n_steps(),
        pids.join(" ")
    );
    tracing::info!(placement = %pinned, "role processes started");
    let mut processes = vec![ProcessEntry {
        role: "orchestrator".into(),
        agent: None,
        pid: std::process::id(),
        host: LOCAL_HOST.into(),
    }];
    for (k, c) in children.0.iter().enumerate() {
        processes.push(ProcessEntry {
            role: ["plant", "leader"]
                .get(k)
                .copied()
                .unwrap_or("agent")
                .into(),
            agent: k.checked_sub(1).filter(|&a| a >= 1),
            pid: c.pid(),
            host: c.host().unwrap_or(LOCAL_HOST).into(),
        });
    }
    let registration = Registration::create(RunRecord {
        format: String::new(),
        owner_uid: 0,
        id: run_id.to_string(),
        prefix: prefix.to_string(),
        out_dir: run_dir.clone(),
        scenario: scenario.name.clone(),
        variant: variant.name().to_string(),
        n_agents: n,
        steps: scenario.n_steps(),
        dt_s: scenario.simulation.dt_s,
        orchestrator_start_ticks: 0,
        started_unix_s: unix_now(),
        processes,
        last_step: 0,
        steps_per_s: 0.0,
    })?;
    tracing::info!(
        run = run_id,
        record = %registration.path().display(),
        "run registered (see `formation ps`)"
    );
    let mut live = Live {
        injections: injections::Injections::open(&node, scenario, &run_dir)?,
        registration,
    };
    let mut takeover = takeover::Takeover::open(
        &node,
        scenario,
        variant,
        exe.clone(),
        child_args(None),
        pins.clone(),
        formation_config::protocol::pacing::PLANT_LEAD + injections::SLACK,
        remote.clone(),
    )?;
    takeover.set_realtime(mode.realtime);
    let mut step_timing = step_timing::StepTiming::default();
    // The wall time of the run is that of its steps: from every role process ready (after any
    // start-up) to the last step recorded.
    let mut wall = Duration::ZERO;
    let (outcome, recorded) = match driver::wait_for_hellos(
        &ports,
        n,
        &mut children.0,
        interrupted,
        &mut takeover,
        &node,
    ) {
        Ok(startup) => {
            takeover.set_startup(startup);
            // An agent started afresh meanwhile: `formation ps` lists its new process.
            live.registration
                .follow_processes(children.0.iter().map(|c| (c.pid(), c.host())));
            let start = Instant::now();
            let result = driver::drive(
                &ports,
                &mut live,
                &formation_leader::Mission::from_scenario(scenario),
                &mut recorder,
                scenario,
                &mut children.0,
                interrupted,
                &mut step_timing,
                &mut takeover,
                &node,
            );
            wall = start.elapsed();
            result
        }
        Err(o) => (o, 0),
    };
    tracing::info!(recorded, outcome = ?outcome, "run ending");
    drop(governor_thread);
    // The export ends first, while the plant still holds the last steps it has not read.
    if let Some(report) = export.map(|e| e.finish(recorded)) {
        recorder.set_export(report);
    }
    ports.stop(recorded);
    recorder.add_events(live.injections.changes());
    drop(live);
    spawn::stop_all(&mut children.0, STOP_GRACE);
    let probed_after = prober.as_ref().and_then(host_probe::Prober::measure);
    drop(ports);
    drop(services);
    drop(node);
    if mode.realtime && matches!(outcome, Outcome::Completed) {
        if let Some(r) = &remote {
            if let Err(e) = r.collect_timing(&run_dir) {
                eprintln!("warning: timing statistics of the other hosts: {e}");
            }
        }
        match timing::collect(
            &run_dir,
            n,
            mode.wait,
            mode.spin_us,
            mode.rt_priority,
            scenario.simulation.max_delay_s,
        ) {
            Ok(mut t) => {
                if let Some(r) = &remote {
                    t["clocks"] = r.clocks_json();
                }
                timing::warn_over_tau_m(&t);
                if let (Some(b), Some(a)) = (probed_before, probed_after) {
                    t["host_probe"] = timing::host_probe_json(&b, &a, &t);
                }
                recorder.set_timing(t)
            }
            Err(e) => eprintln!("warning: no timing statistics: {e}"),
        }
    } else if let Some(t) = step_timing.summary() {
        recorder.set_timing(t);
    }
    // The live timeline: runtime events (less the supervision's own) and the incidents.
    let runtime_events = takeover.summary_events(scenario.simulation.dt_s);
    recorder.set_runtime(
        runtime_events,
        takeover.marks(),
        takeover.restarts().to_vec(),
    );
    recorder.set_checkpoints_refused(takeover.checkpoints_refused().to_vec());
    if let Some(r) = &remote {
        recorder.set_agent_hosts(r.agent_hosts());
    }
    let summary = recorder
        .finish(recorded, wall.as_secs_f64())
        .map_err(|e| format!("cannot write {}/summary.json: {e}", out.display()))?;
    Ok((outcome, summary))
}
