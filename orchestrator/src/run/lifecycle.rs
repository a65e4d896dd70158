//! A run from its start to its summary: [`Run::start`] opens the outputs and the run's services
//! and starts every role process, [`Run::drive`] steps it to its end, [`Run::finish`] stops the
//! processes and writes the summary. The run owns its node, services, ports, processes, recorder
//! and takeover; what it holds beyond them (export, hosts, output folder, layout) is the
//! [`Site`]'s.

use super::plan::{Plan, Site};
use super::{
    driver, export, governor, host_probe, injections, remote, services, spawn, step_timing,
    takeover, timing, Live, STOP_GRACE,
};
use crate::error::RunError;
use crate::live::registry::{unix_now, ProcessEntry, Registration, RunRecord, LOCAL_HOST};
use crate::record::{Recorder, Summary};
use driver::Outcome;
use formation_config::node::args::ChildArgs;
use formation_config::node::ipc;
use formation_config::node::ports::RunNode;
use formation_config::protocol::messages::Role;
use formation_config::protocol::services as names;
use spawn::RoleProcess;
use std::path::{Path, PathBuf};
use std::rc::Rc;
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

/// The ids of a run: its id and the iceoryx2 prefix of its services.
#[derive(Debug, Clone, Copy)]
pub(super) struct Ids<'a> {
    /// Run id.
    pub run_id: &'a str,
    /// iceoryx2 prefix of every service of the run.
    pub prefix: &'a str,
}

/// Kills and reaps the role processes if the run returns early.
struct Children(Vec<RoleProcess>);

impl Drop for Children {
    fn drop(&mut self) {
        spawn::stop_all(&mut self.0, Duration::ZERO);
    }
}

/// A run whose role processes are started. Dropped without [`Run::finish`] (an early return), its
/// fields go in this order: the supervision first, then the processes (killed), the ports and
/// services, the node, the recorder, the hosts.
pub(super) struct Run<'p> {
    plan: &'p Plan,
    takeover: takeover::Takeover,
    live: Live,
    /// Stopped once the steps are over.
    governor: Option<governor::Governor>,
    children: Children,
    /// Realtime: the host's own timer noise, measured before and after the run.
    prober: Option<host_probe::Prober>,
    probed_before: Option<host_probe::ProbeStats>,
    ports: driver::Ports,
    export: Option<export::Running>,
    services: services::RunServices,
    node: RunNode,
    recorder: Recorder,
    step_timing: step_timing::StepTiming,
    run_dir: PathBuf,
    remote: Option<Rc<remote::RemoteRun>>,
    /// After [`Run::drive`]: how the run ended, its steps recorded and the wall time of its steps.
    ended: (Outcome, u64, Duration),
}

impl<'p> Run<'p> {
    /// Opens the outputs, creates the run's services (here and on the other hosts), starts every
    /// role process and registers the run (`formation ps`).
    pub fn start(plan: &'p Plan, ids: Ids, site: &mut Site) -> Result<Run<'p>, RunError> {
        let (scenario, mode) = (&plan.scenario, plan.mode);
        // Released last on an early return, after the run's own services.
        let remote = site.remote.take();
        if !mode.realtime && site.pins.quiet() {
            // Lockstep on a quiet machine: this thread, the CSV writer and every role process
            // (they inherit it) run under SCHED_BATCH: a woken process waits for the running one
            // to block instead of preempting it (see formation_config::node::sched::batch_policy).
            // Beside other work they do not (governor: the role processes then preempt it).
            if let Err(e) = formation_config::node::sched::batch_policy() {
                eprintln!("warning: {e}; running under the normal policy");
            }
        }
        let n = scenario.n_agents();
        let exe = spawn::self_exe()?;
        let (mut recorder, run_dir) = open_outputs(plan, ids.prefix)?;
        let node = ipc::node(ids.prefix, "fm-orchestrator")?;
        let sizing = names::Sizing::for_scenario(scenario, mode.realtime, mode.observers);
        let services = services::RunServices::create(&node, sizing)?;
        if let Some(r) = &remote {
            r.attach(ids.prefix, sizing, &run_dir)?;
        }
        // One of the recorder's sinks, and an outside observer of the services from the first
        // step on; ended before the role processes, once it has put the last step recorded.
        let export = site.export.take().map(export::Opened::start).transpose()?;
        if let Some(e) = &export {
            recorder
                .add_sink(e.sink())
                .map_err(|source| RunError::Outputs {
                    out: plan.out.clone(),
                    source,
                })?;
        }
        let ports = driver::Ports::open(&node, n, !mode.realtime)?;
        if mode.realtime {
            // Stale files of an earlier run in the same directory must not be merged.
            let _ = std::fs::remove_dir_all(formation_config::node::timing::dir(&run_dir));
        }
        let base = child_args(plan, ids, &run_dir);
        // Realtime: the host's own timer noise just before the run, under the plant's
        // scheduling, on a thread that keeps the normal nice value the orchestrator gives up
        // below.
        let prober = mode
            .realtime
            .then(|| host_probe::Prober::start(mode.rt_priority))
            .and_then(|p| p.map_err(|e| eprintln!("warning: {e}")).ok());
        let probed_before = prober.as_ref().and_then(host_probe::Prober::measure);
        let children = Children(spawn_all(&exe, &base, n, &site.pins, remote.as_deref())?);
        // Every child is started (they keep the normal priority): from here on a lockstep
        // orchestrator records behind the plant, with slack, and yields the CPU to plant and
        // agents when they wake up; the successors of a takeover are started at the priority the
        // others were. A realtime plant does not wait for the recorder: there the orchestrator
        // keeps its priority, or a busy machine would leave it behind the wall clock until the
        // step records overflow.
        spawn::keep_launch_priority();
        if !mode.realtime {
            formation_config::node::sched::background_thread();
        }
        let mut pinned = site.pins.describe(n);
        // Stopped once the steps are over (or when the run returns on an error).
        let governor = site
            .adapt
            .take()
            .map(|(g, allowed)| governor::Governor::start(site.pins.clone(), g, allowed));
        let pids: Vec<String> = children.0.iter().map(|c| c.pid().to_string()).collect();
        if let Some(r) = &remote {
            pinned = format!("{}; {pinned}", r.describe());
        }
        eprintln!(
            "formation run: id {}, iceoryx2 prefix {}, {n} agents, {} steps; pids {}; {pinned}",
            ids.run_id,
            ids.prefix,
            scenario.n_steps(),
            pids.join(" ")
        );
        tracing::info!(placement = %pinned, "role processes started");
        let registration = register(plan, ids, &run_dir, &children.0)?;
        let live = Live {
            injections: injections::Injections::open(&node, scenario, &run_dir, mode.realtime)?,
            registration,
        };
        let respawn = takeover::Respawn {
            exe,
            args: base,
            pins: site.pins.clone(),
            remote: remote.clone(),
        };
        let mut takeover = takeover::Takeover::open(
            &node,
            scenario,
            plan.variant,
            respawn,
            formation_config::protocol::pacing::PLANT_LEAD + injections::SLACK,
        )
        .map_err(RunError::Takeover)?;
        takeover.set_realtime(mode.realtime);
        Ok(Run {
            plan,
            takeover,
            live,
            governor,
            children,
            prober,
            probed_before,
            ports,
            export,
            services,
            node,
            recorder,
            step_timing: step_timing::StepTiming::default(),
            run_dir,
            remote,
            ended: (Outcome::Completed, 0, Duration::ZERO),
        })
    }

    /// Waits for every role process, then steps the run to its end, an interruption or a
    /// failure.
    pub fn drive(mut self, interrupted: &AtomicBool) -> Run<'p> {
        let scenario = &self.plan.scenario;
        let mut crew = driver::Crew {
            ports: &self.ports,
            node: &self.node,
            children: &mut self.children.0,
            takeover: &mut self.takeover,
            interrupted,
        };
        // The wall time of the run is that of its steps: from every role process ready (after
        // any start-up) to the last step recorded.
        let mut wall = Duration::ZERO;
        let (outcome, recorded) = match driver::wait_for_hellos(&mut crew, scenario.n_agents()) {
            Ok(startup) => {
                crew.takeover.set_startup(startup);
                // An agent started afresh meanwhile: `formation ps` lists its new process.
                self.live
                    .registration
                    .follow_processes(crew.children.iter().map(|c| (c.pid(), c.host())));
                let start = Instant::now();
                let outputs = driver::Outputs {
                    recorder: &mut self.recorder,
                    live: &mut self.live,
                    step_timing: &mut self.step_timing,
                };
                let result = driver::drive(crew, outputs, scenario);
                wall = start.elapsed();
                result
            }
            Err(o) => (o, 0),
        };
        self.ended = (outcome, recorded, wall);
        self
    }

    /// Stops the export, the processes and the services, then writes the summary with the
    /// timing, the live timeline and the hosts of the agents.
    pub fn finish(self) -> Result<(Outcome, Summary), RunError> {
        let Run {
            plan,
            takeover,
            live,
            governor,
            mut children,
            prober,
            probed_before,
            ports,
            export,
            services,
            node,
            mut recorder,
            step_timing,
            run_dir,
            remote,
            ended: (outcome, recorded, wall),
        } = self;
        tracing::info!(recorded, outcome = ?outcome, "run ending");
        drop(governor);
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
        let completed = matches!(outcome, Outcome::Completed);
        if plan.mode.realtime && completed {
            if let Some(t) = realtime_timing(
                plan,
                &run_dir,
                remote.as_deref(),
                probed_before,
                probed_after,
            ) {
                recorder.set_timing(t);
            }
        } else if let Some(t) = step_timing.summary() {
            recorder.set_timing(t);
        }
        // The live timeline: runtime events (less the supervision's own) and the incidents.
        let runtime_events = takeover.summary_events(plan.scenario.simulation.dt_s);
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
            .map_err(|source| RunError::Summary {
                out: plan.out.clone(),
                source,
            })?;
        Ok((outcome, summary))
    }
}

/// The recorder's files in the output folder, the resolved `scenario.toml`, the run's iceoryx2
/// configuration and its logs; returns the recorder and the run's folder (absolute).
fn open_outputs(plan: &Plan, prefix: &str) -> Result<(Recorder, PathBuf), RunError> {
    let out = &plan.out;
    let recorder = Recorder::create_with(
        &plan.scenario,
        plan.variant,
        plan.mode.name(),
        out,
        plan.outputs,
    )
    .map_err(|source| RunError::Outputs {
        out: out.clone(),
        source,
    })?;
    let run_dir = std::fs::canonicalize(out).unwrap_or_else(|_| out.to_path_buf());
    crate::sim::write_resolved_scenario(&plan.scenario, &run_dir).map_err(|source| {
        RunError::Scenario {
            dir: run_dir.clone(),
            source,
        }
    })?;
    if let Err(e) = super::cleanup::write_iox2_config(&run_dir, prefix) {
        eprintln!("warning: {e}");
    }
    // The logs of an earlier run in the same folder: a log is appended to across the restarts of
    // one run only (formation_config::node::logging).
    let _ = std::fs::remove_dir_all(run_dir.join("logs"));
    if let Err(e) = formation_config::node::logging::init(&run_dir, "orchestrator.log", true) {
        eprintln!("warning: {e}");
    }
    Ok((recorder, run_dir))
}

/// The arguments of every role process of the run (`agent` unset: each agent's sets it).
fn child_args(plan: &Plan, ids: Ids, run_dir: &Path) -> ChildArgs {
    let mode = plan.mode;
    ChildArgs {
        run_id: ids.run_id.to_string(),
        prefix: ids.prefix.to_string(),
        run_dir: run_dir.to_path_buf(),
        variant: plan.variant.name().to_string(),
        agent: None,
        realtime: mode.realtime,
        spin_us: match mode.wait {
            timing::WaitMode::Block => 0,
            timing::WaitMode::SpinBlock => mode.spin_us,
        },
        rt_priority: mode.rt_priority,
        rejoin_at: None,
        members: None,
    }
}

/// Starts plant, leader and the `n` agents (here, or on their host), placed by `pins`.
fn spawn_all(
    exe: &Path,
    base: &ChildArgs,
    n: usize,
    pins: &governor::Pins,
    remote: Option<&remote::RemoteRun>,
) -> Result<Vec<RoleProcess>, RunError> {
    let mut children = Vec::with_capacity(n + 2);
    children.push(pins.spawn(governor::Place::Plant, |cpu| {
        spawn::spawn(exe, Role::Plant, "plant".into(), base, cpu)
    })?);
    children.push(pins.spawn(governor::Place::Anywhere, |_| {
        spawn::spawn(exe, Role::Leader, "leader".into(), base, None)
    })?);
    pins.add_anywhere(std::process::id());
    for i in 0..n {
        let label = format!("agent {} (--agent {i})", i + 1);
        let args = ChildArgs {
            agent: Some(i),
            ..base.clone()
        };
        children.push(match remote.filter(|r| r.is_remote(i)) {
            Some(r) => r.spawn(i, label, &args)?,
            None => pins.spawn(governor::Place::Agent(i), |cpu| {
                spawn::spawn(exe, Role::Agent, label, &args, cpu)
            })?,
        });
    }
    Ok(children)
}

/// Writes the run's record (`formation ps`): the orchestrator, then plant, leader and agents.
fn register(
    plan: &Plan,
    ids: Ids,
    run_dir: &Path,
    children: &[RoleProcess],
) -> Result<Registration, RunError> {
    let scenario = &plan.scenario;
    let mut processes = vec![ProcessEntry {
        role: "orchestrator".into(),
        agent: None,
        pid: std::process::id(),
        host: LOCAL_HOST.into(),
    }];
    for (k, c) in children.iter().enumerate() {
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
        id: ids.run_id.to_string(),
        prefix: ids.prefix.to_string(),
        out_dir: run_dir.to_path_buf(),
        scenario: scenario.name.clone(),
        variant: plan.variant.name().to_string(),
        n_agents: scenario.n_agents(),
        steps: scenario.n_steps(),
        dt_s: scenario.simulation.dt_s,
        orchestrator_start_ticks: 0,
        started_unix_s: unix_now(),
        processes,
        last_step: 0,
        steps_per_s: 0.0,
    })?;
    tracing::info!(
        run = ids.run_id,
        record = %registration.path().display(),
        "run registered (see `formation ps`)"
    );
    Ok(registration)
}

/// A completed realtime run's timing statistics (here and on the other hosts, with the clocks
/// and the host's timer noise), or `None` (said on stderr) when they cannot be collected.
fn realtime_timing(
    plan: &Plan,
    run_dir: &Path,
    remote: Option<&remote::RemoteRun>,
    probed_before: Option<host_probe::ProbeStats>,
    probed_after: Option<host_probe::ProbeStats>,
) -> Option<serde_json::Value> {
    let mode = plan.mode;
    if let Some(r) = remote {
        if let Err(e) = r.collect_timing(run_dir) {
            eprintln!("warning: timing statistics of the other hosts: {e}");
        }
    }
    match timing::collect(
        run_dir,
        plan.scenario.n_agents(),
        mode.wait,
        mode.spin_us,
        mode.rt_priority,
        plan.scenario.simulation.max_delay_s,
    ) {
        Ok(mut t) => {
            if let Some(r) = remote {
                t["clocks"] = r.clocks_json();
            }
            timing::warn_over_tau_m(&t);
            if let (Some(b), Some(a)) = (probed_before, probed_after) {
                t["host_probe"] = timing::host_probe_json(&b, &a, &t);
            }
            Some(t)
        }
        Err(e) => {
            eprintln!("warning: no timing statistics: {e}");
            None
        }
    }
}
