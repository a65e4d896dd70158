//! `formation`: the orchestrator CLI.
//!
//! * `sim`     — the whole closed loop in one process (fast; tests and sweeps).
//! * `run`     — one OS process per quadrotor, plant and leader over iceoryx2 (the product).
//! * `sweep`   — Monte Carlo or grid over scenario parameters on all cores (in-process runner).
//! * `plot`    — the paper's figures from a run directory.
//! * `check`   — what decides whether a gain set can work (graph spectrum, Theorem 1, bandwidths).
//! * `ps`, `inspect`, `inject` — look at and act on a running `run` from another terminal.
//! * `bench`   — IPC latency and jitter: iceoryx2 vs Unix sockets vs UDP.
//! * `schema`  — every service of a run (wire contract for outside clients).
//! * `completions` — shell completion script.

use clap::{CommandFactory, Parser, Subcommand};
use std::process::ExitCode;

use formation::{bench, check, cli, live, plot, role, run, scenario_gen, schema, sim, sweep};

/// Neural adaptive fault-tolerant formation control of quadrotors (enclosing and covering a target).
#[derive(Parser, Debug)]
#[command(name = "formation", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Run the closed loop in one process and write trajectory.csv and summary.json.
    Sim(sim::SimArgs),
    /// Run one OS process per quadrotor (plus plant and leader) over iceoryx2, in lockstep (or on
    /// the wall clock with `--realtime`).
    Run(run::RunArgs),
    /// Generate a scenario with N agents (radii, graph, leaders) from the paper template.
    Scenario(scenario_gen::ScenarioArgs),
    /// Monte Carlo or grid over scenario parameters, in parallel with the in-process runner:
    /// DIR/sweep.csv (one row per sample) and DIR/sweep.json (median / p95 / worst).
    Sweep(sweep::SweepArgs),
    /// Render the paper's figures (PNG) from one run directory (or two, to compare variants).
    Plot(plot::PlotArgs),
    /// Print the graph spectrum, Theorem 1's matrix M and the loop bandwidths of a scenario.
    Check(check::CheckArgs),
    /// Measure IPC latency and jitter (iceoryx2, Unix domain sockets, UDP loopback).
    Bench(bench::BenchArgs),
    /// List the running runs and their processes (role, agent, pid, alive, CPU share, progress).
    Ps(live::ps::PsArgs),
    /// Show one agent's live telemetry (agent ids are 1-based).
    Inspect(live::inspect::InspectArgs),
    /// Inject an actuator fault or a delay profile into a running run (agent ids are 1-based).
    Inject(live::inject::InjectArgs),
    /// Print every service of a run (name pattern, message type and iceoryx2 type name, size,
    /// alignment, senders, receivers, limits) from the service table.
    Schema(schema::SchemaArgs),
    /// Print a shell completion script (e.g. `formation completions bash > ~/.local/share/bash-completion/completions/formation`).
    Completions(CompletionsArgs),
    /// Internal: one agent process of `formation bench`.
    #[command(hide = true)]
    BenchPeer(bench::PeerArgs),
    /// Internal: one role process of `formation run` (plant, leader or agent), started by the
    /// orchestrator from this same executable.
    #[command(hide = true)]
    Node(role::NodeArgs),
}

/// Arguments of `formation completions`.
#[derive(clap::Args, Debug)]
struct CompletionsArgs {
    /// The shell to complete for.
    shell: clap_complete::Shell,
}

/// Writes the completion script of `formation` for `shell`.
fn completions(shell: clap_complete::Shell, out: &mut dyn std::io::Write) {
    clap_complete::generate(shell, &mut Cli::command(), "formation", out);
}

fn main() -> ExitCode {
    // Behave like a Unix tool when the reader of stdout goes away (`formation sim | head`): exit quietly
    // instead of panicking on a broken pipe.
    // SAFETY: restoring the default disposition of SIGPIPE before any thread starts.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    let cli = Cli::parse();
    match cli.command {
        Some(Command::Sim(a)) => sim::main(a),
        Some(Command::Run(a)) => run::main(a),
        Some(Command::Scenario(a)) => scenario_gen::main(a),
        Some(Command::Sweep(a)) => sweep::main(a),
        Some(Command::Plot(a)) => plot::main(a),
        Some(Command::Check(a)) => check::main(a),
        Some(Command::Bench(a)) => bench::main(a),
        Some(Command::Ps(a)) => live::ps::main(a),
        Some(Command::Inspect(a)) => live::inspect::main(a),
        Some(Command::Inject(a)) => live::inject::main(a),
        Some(Command::Schema(a)) => schema::main(a),
        Some(Command::Completions(a)) => {
            completions(a.shell, &mut std::io::stdout());
            ExitCode::SUCCESS
        }
        Some(Command::BenchPeer(a)) => bench::peer_main(a),
        Some(Command::Node(a)) => role::main(a),
        // Bare `formation` is `formation run` with every default, parsed by clap like the subcommand.
        None => run::main(cli::defaults::<run::RunArgs>("run")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(args: &[&str]) -> Result<Cli, clap::Error> {
        Cli::try_parse_from(std::iter::once("formation").chain(args.iter().copied()))
    }

    #[test]
    fn the_command_line_definition_is_consistent() {
        Cli::command().debug_assert();
    }

    #[test]
    fn negative_numbers_are_values_of_the_arguments_that_take_numbers() {
        let cli = parse(&[
            "inject",
            "fault",
            "--agent",
            "2",
            "--gamma",
            "0.5,0.5,0.5",
            "--delta",
            "-0.1,0,-0.2",
            "--at",
            "-1",
        ])
        .expect("parses");
        let Some(Command::Inject(a)) = cli.command else {
            panic!("inject")
        };
        let live::inject::InjectWhat::Fault(f) = a.what else {
            panic!("fault")
        };
        assert_eq!(f.delta, vec![-0.1, 0.0, -0.2]);
        assert_eq!(f.at, Some(-1.0));
        let cli = parse(&["bench", "--seconds", "-1"]).expect("parses");
        let Some(Command::Bench(b)) = cli.command else {
            panic!("bench")
        };
        assert_eq!(b.seconds, -1.0);
    }

    #[test]
    fn a_negative_count_is_refused_by_its_argument_saying_it_is_negative() {
        for args in [
            &["scenario", "--n", "-3"][..],
            &["bench", "--rounds", "-1"],
            &["inspect", "--agent", "-1"],
            &["sim", "--repeat", "-2"],
        ] {
            let e = parse(args).expect_err("a negative count").to_string();
            assert!(e.contains("is negative"), "{args:?}: {e}");
            assert!(!e.contains("unexpected argument"), "{args:?}: {e}");
        }
    }

    #[test]
    fn the_bash_completion_script_completes_formation_and_its_subcommands() {
        let mut out = Vec::new();
        completions(clap_complete::Shell::Bash, &mut out);
        let script = String::from_utf8(out).expect("utf-8");
        assert!(script.contains("formation"));
        for sub in [
            "sim",
            "run",
            "scenario",
            "sweep",
            "plot",
            "check",
            "bench",
            "ps",
            "inspect",
            "inject",
            "schema",
            "completions",
        ] {
            assert!(
                script.contains(&format!("formation__subcmd__{sub}")),
                "bash completion lacks the subcommand {sub}"
            );
        }
    }
}
