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

use check::CheckError;
use formation_analysis::{check, plot, scenario_gen, sweep};
use formation_bench as bench;
use formation_bench::error::{BenchError, PeerError};
use formation_live::error::LiveError;
use formation_live::{inject, inspect, ps, schema};
use formation_runtime::error::CommandError;
use formation_runtime::{cli, role, run, sim};
use plot::PlotError;
use scenario_gen::ScenarioError;
use sweep::SweepError;

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
    #[command(
        after_help = "Examples:\n  formation sim\n  formation sim --variant no-rbfnn --out out/no-rbfnn\n  formation sim --set controller.position.k_v=2.5 --set 'agents[*].delay.base_s=0.02'\n  formation sim --record mcap --json > summary.json\n  formation sim --repeat 5"
    )]
    Sim(sim::SimArgs),
    /// Run one OS process per quadrotor (plus plant and leader) over iceoryx2, in lockstep (or on
    /// the wall clock with `--realtime`).
    #[command(
        after_help = "Examples:\n  formation run\n  formation run config/scenarios/abrupt-faults.toml --out out/abrupt\n  formation run --record mcap --out out/rec   # also writes out/rec/run.mcap\n  formation run --json | jq .agents[0].rms_formation_error_m\n  formation run --realtime --set simulation.duration_s=10"
    )]
    Run(run::RunArgs),
    /// Generate a scenario with N agents (radii, graph, leaders) from the paper template.
    #[command(
        after_help = "Examples:\n  formation scenario --n 20 --graph ring --out gen20.toml\n  formation scenario --n 8 --graph random-connected --seed 3 --leader-agents 1,5\n  formation scenario --n 12 --json > gen12.json"
    )]
    Scenario(scenario_gen::ScenarioArgs),
    /// Monte Carlo or grid over scenario parameters, in parallel with the in-process runner:
    /// DIR/sweep.csv (one row per sample) and DIR/sweep.json (median / p95 / worst).
    #[command(
        after_help = "Examples:\n  formation sweep --vary delay.max=0..0.05 --vary fault.gamma=0.4..1 --samples 20 --seed 1\n  formation sweep --vary n=5,10,20 --vary graph=ring,path --grid --out out/grid"
    )]
    Sweep(sweep::SweepArgs),
    /// Render the paper's figures (PNG) from one run directory (or two, to compare variants).
    #[command(
        after_help = "Examples:\n  formation plot out/paper-proposed\n  formation plot out/paper-proposed --format svg --out figs\n  formation plot out/paper-proposed --compare out/paper-no-rbfnn --out figs/compare"
    )]
    Plot(plot::PlotArgs),
    /// Print the graph spectrum, Theorem 1's matrix M and the loop bandwidths of a scenario.
    #[command(
        after_help = "Examples:\n  formation check\n  formation check paper-exact\n  formation check --set controller.position.k_p=1.5 --json"
    )]
    Check(check::CheckArgs),
    /// Measure IPC latency and jitter (iceoryx2, Unix domain sockets, UDP loopback).
    #[command(
        after_help = "Examples:\n  formation bench --n 5 --seconds 5\n  formation bench --n 5 --transports iox2-event --rounds 9 --json"
    )]
    Bench(bench::BenchArgs),
    /// List the running runs and their processes (role, agent, pid, alive, CPU share, progress).
    #[command(after_help = "Examples:\n  formation ps\n  formation ps --json")]
    Ps(ps::PsArgs),
    /// Show one agent's live telemetry (agent ids are 1-based).
    #[command(
        after_help = "Examples:\n  formation inspect --agent 2\n  formation inspect --agent 2 --follow\n  formation inspect --agent 2 --run 3d2cb2b7 --json"
    )]
    Inspect(inspect::InspectArgs),
    /// Inject an actuator fault or a delay profile into a running run (agent ids are 1-based).
    #[command(
        after_help = "Examples:\n  formation inject fault --agent 2 --gamma 0.5,0.5,0.5 --delta 0,0,0\n  formation inject delay --agent 3 --tau '0.02+0.01*sin(0.5*t)' --at 30\n  formation inject fault --agent 1 --gamma 0.6,0.6,0.6 --delta 0.1,0,0 --json"
    )]
    Inject(inject::InjectArgs),
    /// Print every service of a run (name pattern, message type and iceoryx2 type name, size,
    /// alignment, senders, receivers, limits) from the service table.
    #[command(
        after_help = "Examples:\n  formation schema\n  formation schema --n 20 --json\n  formation schema --markdown > docs/services.md"
    )]
    Schema(schema::SchemaArgs),
    /// Print a shell completion script (e.g. `formation completions bash > ~/.local/share/bash-completion/completions/formation`).
    #[command(
        after_help = "Examples:\n  formation completions bash > ~/.local/share/bash-completion/completions/formation\n  formation completions zsh > ~/.zfunc/_formation"
    )]
    Completions(CompletionsArgs),
    /// Internal: one agent process of `formation bench`.
    #[command(hide = true)]
    BenchPeer(bench::PeerArgs),
    /// Lend this machine's CPUs to runs of other machines: a daemon that starts agents on request
    /// (docs/multi-host.md).
    #[cfg(feature = "multihost")]
    #[command(
        after_help = "Examples:\n  formation host --name b\n  formation host --name b --listen quic/0.0.0.0:7447 --tls /etc/formation/tls"
    )]
    Host(formation_host::HostArgs),
    /// List the `formation host` daemons reachable from here (name, address, CPUs, runs, build).
    #[cfg(feature = "multihost")]
    #[command(
        after_help = "Examples:\n  formation hosts\n  formation hosts --connect quic/10.0.0.2:7447 --tls ~/.formation/tls --json"
    )]
    Hosts(formation_host::HostsArgs),
    /// Make a certificate authority and per-host certificates for mutual TLS between hosts
    /// (tls/HOST:PORT and quic/HOST:PORT endpoints, --tls DIR; docs/multi-host.md).
    #[cfg(feature = "multihost")]
    #[command(
        after_help = "Examples:\n  formation certs init --dir ~/formation-ca\n  formation certs issue --dir ~/formation-ca --name b --addr 10.0.0.2 --out b-tls\n  formation certs issue --dir ~/formation-ca --name a --out a-tls"
    )]
    Certs(formation_host::CertsArgs),
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
        Some(Command::Sim(a)) => ended(sim::main(a)),
        Some(Command::Run(a)) => ended(run::main(a)),
        Some(Command::Scenario(a)) => ended(scenario_gen::main(a)),
        Some(Command::Sweep(a)) => ended(sweep::main(a)),
        Some(Command::Plot(a)) => ended(plot::main(a)),
        Some(Command::Check(a)) => ended(check::main(a)),
        Some(Command::Bench(a)) => ended(bench::main(a)),
        Some(Command::Ps(a)) => ended(ps::main(a)),
        Some(Command::Inspect(a)) => ended(inspect::main(a)),
        Some(Command::Inject(a)) => ended(inject::main(a)),
        Some(Command::Schema(a)) => ended(schema::main(a)),
        Some(Command::Completions(a)) => {
            completions(a.shell, &mut std::io::stdout());
            ExitCode::SUCCESS
        }
        Some(Command::BenchPeer(a)) => ended(bench::peer_main(a)),
        Some(Command::Node(a)) => ended(role::main(a)),
        #[cfg(feature = "multihost")]
        Some(Command::Host(a)) => ended(formation_host::host_main(a)),
        #[cfg(feature = "multihost")]
        Some(Command::Hosts(a)) => ended(formation_host::hosts_main(a)),
        #[cfg(feature = "multihost")]
        Some(Command::Certs(a)) => ended(formation_host::certs_main(a)),
        // Bare `formation` is `formation run` with every default, parsed by clap like the subcommand.
        None => ended(run::main(cli::defaults::<run::RunArgs>("run"))),
    }
}

/// The exit code of a command, its error said on stderr: the one place that maps the typed
/// errors of every command to exit codes (docs/cli.md).
fn ended<E: Failure>(result: Result<(), E>) -> ExitCode {
    let Err(e) = result else {
        return ExitCode::SUCCESS;
    };
    if !e.already_said() {
        eprintln!("{}{e}", e.prefix());
    }
    ExitCode::from(e.exit_code())
}

/// A command's failure: its message and exit code.
trait Failure: std::fmt::Display {
    /// 2 for bad input, 3 for a result that is a failure, 130 after Ctrl-C, 1 for anything that
    /// failed.
    fn exit_code(&self) -> u8;
    /// Whether the message is on stderr already.
    fn already_said(&self) -> bool {
        false
    }
    /// What goes before the message on stderr: `error: ` for an error whose `Display` only says
    /// what failed (it is also part of other messages), nothing for one whose `Display` is the
    /// whole message.
    fn prefix(&self) -> &'static str {
        ""
    }
}

impl Failure for CheckError {
    fn exit_code(&self) -> u8 {
        match self {
            CheckError::Input(_) => cli::EXIT_INVALID,
            CheckError::Failed => cli::EXIT_RESULT_FAILED,
            CheckError::Json(_) => 1,
        }
    }

    fn already_said(&self) -> bool {
        // The report with its FAIL verdicts is printed.
        matches!(self, CheckError::Failed)
    }
}

impl Failure for ScenarioError {
    fn exit_code(&self) -> u8 {
        match self {
            ScenarioError::Options(_) | ScenarioError::Invalid(_) => cli::EXIT_INVALID,
            ScenarioError::Json(_) | ScenarioError::Write { .. } => 1,
        }
    }
}

impl Failure for SweepError {
    /// Every failure of a sweep is of its input: the base scenario, a `--vary`, the output
    /// folder, or samples that are all invalid.
    fn exit_code(&self) -> u8 {
        cli::EXIT_INVALID
    }

    fn prefix(&self) -> &'static str {
        "error: "
    }
}

impl Failure for PlotError {
    fn exit_code(&self) -> u8 {
        match self {
            PlotError::Input(_) => cli::EXIT_INVALID,
            PlotError::Render(_) => 1,
        }
    }

    fn prefix(&self) -> &'static str {
        "error: "
    }
}

impl Failure for BenchError {
    fn exit_code(&self) -> u8 {
        match self {
            BenchError::Arg(_) | BenchError::HostSeconds(_) => cli::EXIT_INVALID,
            BenchError::Interrupted => cli::EXIT_INTERRUPTED,
            BenchError::Node(_) | BenchError::CasesFailed(_) => 1,
        }
    }
}

impl Failure for PeerError {
    fn exit_code(&self) -> u8 {
        match self {
            PeerError::Transport(_)
            | PeerError::Wait(_)
            | PeerError::Payload(_)
            | PeerError::Prefix(_)
            | PeerError::Pin { .. }
            | PeerError::Batch(_) => cli::EXIT_INVALID,
            PeerError::Case { .. } => 1,
        }
    }
}

#[cfg(feature = "multihost")]
impl Failure for formation_host::HostError {
    fn exit_code(&self) -> u8 {
        use formation_host::HostError;
        match self {
            HostError::Name(_)
            | HostError::Link(_)
            | HostError::MaxRtPriority(_)
            | HostError::Serve(_)
            | HostError::Unreachable(_)
            | HostError::Certs(_) => cli::EXIT_INVALID,
            HostError::Exe(_) => 1,
        }
    }
}

impl Failure for LiveError {
    fn exit_code(&self) -> u8 {
        match self {
            LiveError::Registry(_)
            | LiveError::Access(_)
            | LiveError::Agent(_)
            | LiveError::Request(_)
            | LiveError::AgentCount { .. } => cli::EXIT_INVALID,
            LiveError::Confirm(formation_live::error::ConfirmError::Rejected(_)) => {
                cli::EXIT_INVALID
            }
            LiveError::Inspect(_) | LiveError::Confirm(_) | LiveError::Json(_) => 1,
        }
    }
}

impl Failure for CommandError {
    fn already_said(&self) -> bool {
        CommandError::already_said(self)
    }

    fn exit_code(&self) -> u8 {
        command_exit_code(self)
    }
}

/// 2 for bad input, 3 for a run that diverged, 130 after Ctrl-C, 1 for anything that failed.
fn command_exit_code(e: &CommandError) -> u8 {
    match e {
        CommandError::Input(_)
        | CommandError::Plan(_)
        | CommandError::OutFolder(_)
        | CommandError::UnknownRole(_)
        | CommandError::NodeArgs { .. } => cli::EXIT_INVALID,
        CommandError::Diverged(_) | CommandError::TooClose { .. } => cli::EXIT_RESULT_FAILED,
        CommandError::Interrupted(_) => cli::EXIT_INTERRUPTED,
        CommandError::Node { source, .. } if source.port_held() => cli::EXIT_PORT_HELD,
        CommandError::WriteScenario { .. }
        | CommandError::WriteOutputs { .. }
        | CommandError::Run(_)
        | CommandError::Died
        | CommandError::Node { .. } => 1,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(args: &[&str]) -> Result<Cli, clap::Error> {
        Cli::try_parse_from(std::iter::once("formation").chain(args.iter().copied()))
    }

    #[test]
    fn each_failure_has_the_exit_code_docs_cli_md_gives_it() {
        use formation_live::error::ConfirmError;
        use formation_runtime::cli::InputError;
        use formation_runtime::record::metrics::Divergence;
        let bad = CommandError::Input(InputError::Variant("x".into()));
        assert_eq!((bad.exit_code(), bad.already_said()), (2, false));
        let diverged = CommandError::Diverged(Divergence {
            time_s: 1.0,
            agent: 2,
            cause: "nn_norm".into(),
        });
        assert_eq!(diverged.exit_code(), 3);
        assert!(diverged
            .to_string()
            .starts_with("diverged: t = 1.000 s, agent 2"));
        let stopped = CommandError::Interrupted("out".into());
        assert_eq!(stopped.exit_code(), 130);
        assert_eq!(
            (
                CommandError::Died.exit_code(),
                CommandError::Died.already_said()
            ),
            (1, true)
        );
        use formation_config::node::error::{NodeError, PortError, PortErrorKind};
        use formation_config::protocol::messages::Role;
        let held = |detail: &str| CommandError::Node {
            role: Role::Agent,
            source: NodeError::Port(PortError::new(
                "formation/agent/3/share",
                PortErrorKind::Port,
                format_args!("{detail}"),
            )),
        };
        assert_eq!(held("ExceedsMaxSupportedPublishers").exit_code(), 75);
        assert_eq!(held("InternalFailure").exit_code(), 1);
        let rejected = LiveError::Confirm(ConfirmError::Rejected("needs a lockstep run".into()));
        assert_eq!(rejected.exit_code(), 2, "a rejected injection is bad input");
        let count = LiveError::AgentCount { n: 0, max: 128 };
        assert_eq!(count.exit_code(), 2);
        assert_eq!(
            count.to_string(),
            "error: --n 0: must be within 1..=128 agents"
        );
        assert_eq!(
            LiveError::Confirm(ConfirmError::Ended("r".into())).exit_code(),
            1
        );
    }

    /// Exit code, whether already said, and the line on stderr of `e`.
    fn said<E: Failure>(e: &E) -> (u8, bool, String) {
        (
            e.exit_code(),
            e.already_said(),
            format!("{}{e}", e.prefix()),
        )
    }

    fn json_error() -> serde_json::Error {
        serde_json::from_str::<u8>("x").expect_err("not a number")
    }

    #[test]
    fn check_refuses_bad_input_with_2_fails_a_fail_verdict_with_3_and_a_report_it_cannot_write_with_1(
    ) {
        use formation_runtime::cli::InputError;
        let (code, quiet, line) = said(&CheckError::Input(InputError::Variant("x".into())));
        assert_eq!((code, quiet), (2, false));
        assert!(line.starts_with("error: ") && line.contains('x'), "{line}");
        assert_eq!(said(&CheckError::Failed).0, 3);
        assert!(CheckError::Failed.already_said(), "the report said it");
        let (code, _, line) = said(&CheckError::Json(json_error()));
        assert_eq!(code, 1);
        assert!(line.starts_with("error: cannot write the report as JSON: "));
    }

    #[test]
    fn scenario_refuses_an_option_with_2_and_a_file_it_cannot_write_with_1() {
        use formation_analysis::scenario_gen::GenError;
        let (code, _, line) = said(&ScenarioError::Options(GenError::Graph("star".into())));
        assert_eq!(code, 2);
        assert_eq!(
            line,
            "error: --graph star: expected ring, path, k-nearest, complete or random-connected"
        );
        let write = ScenarioError::Write {
            path: "x.toml".into(),
            source: std::io::Error::other("disk full"),
        };
        assert_eq!(
            said(&write),
            (1, false, "error: cannot write x.toml: disk full".into())
        );
        assert_eq!(said(&ScenarioError::Json(json_error())).0, 1);
    }

    #[test]
    fn sweep_refuses_every_failure_as_bad_input_naming_the_option() {
        let twice = SweepError::Twice("delay.max".into());
        assert_eq!(
            said(&twice),
            (2, false, "error: --vary delay.max: given twice".into())
        );
        assert_eq!(said(&SweepError::NoSamples).0, 2);
    }

    #[test]
    fn plot_refuses_a_bad_run_folder_with_2_and_a_figure_it_cannot_draw_with_1() {
        let missing = PlotError::Input("no trajectory.csv in out/x".into());
        assert_eq!(
            said(&missing),
            (2, false, "error: no trajectory.csv in out/x".into())
        );
        assert_eq!(said(&PlotError::Render("font".into())).0, 1);
    }

    #[test]
    fn bench_refuses_an_argument_with_2_fails_a_case_with_1_and_stops_on_ctrl_c_with_130() {
        use formation_bench::error::ArgError;
        assert_eq!(
            said(&BenchError::Arg(ArgError::Seconds(-1.0))),
            (
                2,
                false,
                "error: --seconds must be in (0, 3600], got -1".into()
            )
        );
        assert_eq!(
            said(&BenchError::HostSeconds(0.0)),
            (
                2,
                false,
                "error: --seconds 0: expected 0 < s <= 3600".into()
            )
        );
        assert_eq!(
            said(&BenchError::CasesFailed(2)),
            (1, false, "formation bench: 2 case(s) failed".into())
        );
        assert_eq!(
            said(&BenchError::Interrupted),
            (130, false, "formation bench: interrupted".into())
        );
    }

    #[test]
    fn a_bench_peer_refuses_an_argument_with_2_and_fails_its_case_with_1() {
        use formation_bench::error::CaseError;
        assert_eq!(
            said(&PeerError::Transport("tcp".into())),
            (
                2,
                false,
                "formation bench-peer: unknown transport 'tcp'".into()
            )
        );
        let case = PeerError::Case {
            transport: "udp".into(),
            index: 3,
            case: 7,
            source: CaseError::Idle,
        };
        assert_eq!(
            said(&case),
            (
                1,
                false,
                "formation bench-peer udp #3 (case 7): no step arrived in time".into()
            )
        );
    }

    #[cfg(feature = "multihost")]
    #[test]
    fn host_refuses_a_bad_name_with_2_and_fails_without_its_executable_with_1() {
        use formation_host::HostError;
        assert_eq!(
            said(&HostError::Name("a b".into())),
            (
                2,
                false,
                "error: --name 'a b': a host name is 1..=32 of [A-Za-z0-9_-]".into()
            )
        );
        let exe = HostError::Exe(formation_runtime::run::SpawnError::Exe(
            std::io::Error::other("gone"),
        ));
        assert_eq!(said(&exe).0, 1);
        assert_eq!(said(&HostError::Unreachable(Vec::new())).0, 2);
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
        let inject::InjectWhat::Fault(f) = a.what else {
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

    /// The words of one example line as the shell would pass them (single quotes; a comment,
    /// redirection or pipe ends the command).
    fn words(line: &str) -> Vec<String> {
        let mut out = Vec::new();
        let (mut word, mut quoted, mut any) = (String::new(), false, false);
        for c in line.chars() {
            match c {
                '\'' => (quoted, any) = (!quoted, true),
                ' ' if !quoted => {
                    if any {
                        out.push(std::mem::take(&mut word));
                    }
                    any = false;
                }
                '#' | '>' | '|' if !quoted => break,
                c => (word, any) = (word + &c.to_string(), true),
            }
        }
        if any {
            out.push(word);
        }
        out
    }

    #[test]
    fn every_subcommand_has_examples_in_its_help_and_each_example_parses() {
        let cli = Cli::command();
        for sub in cli.get_subcommands().filter(|s| !s.is_hide_set()) {
            let name = sub.get_name();
            let help = sub
                .get_after_help()
                .unwrap_or_else(|| panic!("`formation {name}` has no after_help"))
                .to_string();
            let examples: Vec<&str> = help
                .lines()
                .skip_while(|l| *l != "Examples:")
                .skip(1)
                .map(str::trim)
                .collect();
            assert!(!examples.is_empty(), "`formation {name}`: no examples");
            for line in examples {
                let args = words(line);
                assert_eq!(args[..2], ["formation", name], "{line}");
                if let Err(e) = Cli::try_parse_from(&args) {
                    panic!("example `{line}` of `formation {name}` does not parse: {e}");
                }
            }
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
