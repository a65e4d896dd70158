//! `formation sim`: the whole closed loop in one process. The loop passes the same wire messages
//! between the same library calls as the processes of `formation run` do.

use crate::cli;
use crate::record::{Recorder, Summary};
use formation_agent::Agent;
use formation_config::wire::{
    ControlCommand, NeighborState, PlantTruth, ReferenceFrame, VehicleState,
};
use formation_config::{Scenario, Variant};
use formation_leader::Mission;
use formation_plant::Plant;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
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

/// Entry point of `formation sim`.
pub fn main(args: SimArgs) -> ExitCode {
    let (scenario, variant) = match args.common.load() {
        Ok(v) => v,
        Err(code) => return code,
    };
    let out = args
        .common
        .out
        .unwrap_or_else(|| PathBuf::from(format!("out/{}-{}", scenario.name, variant.name())));
    if let Err(e) = write_resolved_scenario(&scenario, &out) {
        eprintln!("error: cannot write {}/scenario.toml: {e}", out.display());
        return ExitCode::from(1);
    }
    let mut factors = Vec::new();
    for _ in 1..args.repeat.max(1) {
        match run_in_process(&scenario, variant, &out) {
            Ok(s) => factors.push(s.realtime_factor),
            Err(e) => {
                eprintln!("error: cannot write outputs to {}: {e}", out.display());
                return ExitCode::from(1);
            }
        }
    }
    match run_in_process(&scenario, variant, &out) {
        Ok(summary) => {
            if args.repeat > 1 {
                factors.push(summary.realtime_factor);
                factors.sort_by(|a, b| a.total_cmp(b));
                println!(
                    "speed over {} runs: median {:.0}x real time (slowest {:.0}x, fastest {:.0}x), {:.2} µs per simulated step",
                    factors.len(),
                    factors[factors.len() / 2],
                    factors[0],
                    factors[factors.len() - 1],
                    1e6 * scenario.simulation.dt_s / factors[factors.len() / 2]
                );
            }
            if args.quiet {
                println!("{}", out.join("summary.json").display());
            } else {
                summary.print_table();
                println!("wrote {}/trajectory.csv and summary.json", out.display());
            }
            exit_code(&summary)
        }
        Err(e) => {
            eprintln!("error: cannot write outputs to {}: {e}", out.display());
            ExitCode::from(1)
        }
    }
}

/// Exit code of a runner (`sim`, `run`) that ran to its end and wrote its outputs: 0, or
/// [`cli::EXIT_RESULT_FAILED`] (3) when the run diverged, with the divergence named on stderr.
pub fn exit_code(summary: &Summary) -> ExitCode {
    match &summary.divergence {
        None => ExitCode::SUCCESS,
        Some(d) => {
            eprintln!(
                "diverged: t = {:.3} s, agent {}: {} (outputs up to that step are written; exit code {})",
                d.time_s,
                d.agent,
                d.cause,
                cli::EXIT_RESULT_FAILED
            );
            ExitCode::from(cli::EXIT_RESULT_FAILED)
        }
    }
}

/// Writes the scenario as run (after `--set` overrides) to `out/scenario.toml`, so that a run directory
/// is self-describing (the figures read it, and it can be run again as is).
pub fn write_resolved_scenario(scenario: &Scenario, out: &Path) -> std::io::Result<()> {
    std::fs::create_dir_all(out)?;
    std::fs::write(out.join("scenario.toml"), scenario.to_toml_string())
}

/// Runs the closed loop of `scenario` with `variant` in this process, writing the outputs to `out`.
/// Stops at the end of the scenario or at the first divergence.
pub fn run_in_process(
    scenario: &Scenario,
    variant: Variant,
    out: &Path,
) -> std::io::Result<Summary> {
    let start = Instant::now();
    let n = scenario.n_agents();
    let mut plant = Plant::from_scenario(scenario);
    let mission = Mission::from_scenario(scenario);
    let mut agents: Vec<Agent> = (0..n).map(|i| Agent::new(scenario, i, variant)).collect();
    let neighbours: Vec<Vec<usize>> = agents.iter().map(|a| a.neighbour_ids().collect()).collect();
    let mut recorder = Recorder::create(scenario, variant, "in-process", out)?;
    let mut reference = ReferenceFrame::default();
    let mut states = vec![VehicleState::default(); n];
    let mut shares = vec![NeighborState::default(); n];
    let mut commands = vec![ControlCommand::default(); n];
    let mut truths = vec![PlantTruth::default(); n];
    let dt = scenario.simulation.dt_s;
    let steps = scenario.n_steps();
    let mut done = 0;
    for k in 0..steps {
        mission.reference(k, k as f64 * dt, &mut reference);
        for a in agents.iter_mut() {
            a.observe_reference(&reference);
        }
        for i in 0..n {
            states[i] = plant.vehicle_state(i);
            shares[i] = agents[i].observe_own(&states[i]);
        }
        for i in 0..n {
            for &j in &neighbours[i] {
                agents[i].observe_neighbor(&shares[j]);
            }
        }
        for i in 0..n {
            commands[i] = agents[i].step(&states[i]);
            plant.apply(i, &commands[i]);
            truths[i] = plant.truth(i);
        }
        done = k + 1;
        if recorder
            .record(k, &reference, &truths, &commands)?
            .is_some()
        {
            break;
        }
        plant.advance();
    }
    recorder.finish(done, start.elapsed().as_secs_f64())
}
