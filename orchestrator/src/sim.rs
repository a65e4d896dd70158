//! `formation sim`: the whole closed loop in one process ([`ClosedLoop`]), recorded like a run.

use crate::cli;
use crate::closed_loop::ClosedLoop;
use crate::error::CommandError;
use crate::record::{Outputs, Recorder, Summary};
use formation_config::{Scenario, Variant};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Arguments of `formation sim`.
#[derive(clap::Args, Debug)]
pub struct SimArgs {
    /// Scenario, variant, output directory, overrides.
    #[command(flatten)]
    pub common: cli::RunnerArgs,
    /// Print only the summary JSON path (for scripts).
    #[arg(long)]
    pub quiet: bool,
    /// Speed report: run K times and print the median, fastest and slowest real-time factor
    /// (sim_time / wall_time of the whole run, outputs included). The outputs of the last run are kept.
    #[arg(long, value_name = "K", default_value_t = 1, value_parser = crate::cli::whole_number::<u32>, allow_negative_numbers = true)]
    pub repeat: u32,
}

/// Entry point of `formation sim`; the `formation` binary prints the error and maps it to the
/// exit code.
pub fn main(args: SimArgs) -> Result<(), CommandError> {
    let (scenario, variant) = args.common.load()?;
    let live = args.common.live_options();
    let ros2 = args.common.ros2_options();
    let out = args
        .common
        .out
        .unwrap_or_else(|| PathBuf::from(format!("out/{}-{}", scenario.name, variant.name())));
    // Held until the outputs are complete: a second run into the same folder is refused.
    let _out_lock = crate::out_lock::acquire(&out, None, "formation sim")?;
    write_resolved_scenario(&scenario, &out).map_err(|source| CommandError::WriteScenario {
        out: out.clone(),
        source,
    })?;
    let mut outputs = Outputs::with(&args.common.record);
    outputs.foxglove = live;
    outputs.ros2 = ros2;
    let written = |source| CommandError::WriteOutputs {
        out: out.clone(),
        source,
    };
    let mut factors = Vec::new();
    for _ in 1..args.repeat.max(1) {
        let s = run_in_process_with(&scenario, variant, &out, outputs).map_err(written)?;
        factors.push(s.realtime_factor);
    }
    let summary = run_in_process_with(&scenario, variant, &out, outputs).map_err(written)?;
    if args.repeat > 1 {
        factors.push(summary.realtime_factor);
        factors.sort_by(|a, b| a.total_cmp(b));
        let line = format!(
            "speed over {} runs: median {:.0}x real time (slowest {:.0}x, fastest {:.0}x), {:.2} µs per simulated step",
            factors.len(),
            factors[factors.len() / 2],
            factors[0],
            factors[factors.len() - 1],
            1e6 * scenario.simulation.dt_s / factors[factors.len() / 2]
        );
        // With --json, standard output holds the JSON only.
        if args.common.json {
            eprintln!("{line}");
        } else {
            println!("{line}");
        }
    }
    if args.common.json {
        println!("{}", summary.to_json());
    } else if args.quiet {
        println!("{}", out.join("summary.json").display());
    } else {
        summary.print_table();
        println!("wrote {}/trajectory.csv and summary.json", out.display());
    }
    result_of(&summary)
}

/// The end of a runner (`sim`, `run`) that ran to its end and wrote its outputs: `Ok`, or
/// [`CommandError::Diverged`] (exit code [`crate::cli::EXIT_RESULT_FAILED`], 3) when the run
/// diverged, [`CommandError::TooClose`] (the same code) when two quadrotors came nearer than the
/// safety distance.
pub fn result_of(summary: &Summary) -> Result<(), CommandError> {
    let sep = &summary.separation;
    match (&summary.divergence, sep.min_distance.whole) {
        (Some(d), _) => Err(CommandError::Diverged(d.clone())),
        (None, Some(a)) if sep.steps_below_safety > 0 => Err(CommandError::TooClose {
            steps: sep.steps_below_safety,
            safety_m: sep.safety_distance_m,
            closest: a,
        }),
        (None, _) => Ok(()),
    }
}

/// Writes the scenario as run (after `--set` overrides) to `out/scenario.toml`, so that a run directory
/// is self-describing (the figures read it, and it can be run again as is).
pub fn write_resolved_scenario(scenario: &Scenario, out: &Path) -> std::io::Result<()> {
    formation_config::node::files::ensure_private_dir(out)?;
    formation_config::node::files::write_atomic(
        &out.join("scenario.toml"),
        scenario.to_toml_string().as_bytes(),
    )
}

/// Runs the closed loop of `scenario` with `variant` in this process, writing the outputs to `out`.
/// Stops at the end of the scenario or at the first divergence.
pub fn run_in_process(
    scenario: &Scenario,
    variant: Variant,
    out: &Path,
) -> std::io::Result<Summary> {
    run_in_process_with(scenario, variant, out, Outputs::with(&[]))
}

/// [`run_in_process`], writing the files of `outputs` (`summary.json` always): `formation sweep`
/// keeps only the summaries, `--record mcap` adds `run.mcap`.
pub fn run_in_process_with(
    scenario: &Scenario,
    variant: Variant,
    out: &Path,
    outputs: Outputs,
) -> std::io::Result<Summary> {
    let start = Instant::now();
    let mut lp = ClosedLoop::new(scenario, variant);
    let mut recorder = Recorder::create_with(scenario, variant, "in-process", out, outputs)?;
    let steps = scenario.n_steps();
    let mut done = 0;
    for k in 0..steps {
        lp.observe();
        lp.act();
        done = k + 1;
        if recorder
            .record(k, lp.reference(), lp.truths(), lp.commands())?
            .is_some()
        {
            break;
        }
        lp.advance();
    }
    recorder.finish(done, start.elapsed().as_secs_f64())
}
