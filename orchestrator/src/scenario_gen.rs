//! `formation scenario`: a scenario with N agents generated from the paper template (for scaling
//! runs). Agent specs (delays, faults, uncertainty, disturbance) are reused cyclically, the
//! quadrotors start on a circle around T_g(0) large enough for N, and the graph is a path
//! (b_1 = b_N = 1, as in Fig. 4) or a ring (b_1 = b_{N/2+1} = 1).

use crate::cli::EXIT_INVALID;
use formation_config::scenario::{Edge, Scenario};
use formation_config::validate::validate;
use std::path::PathBuf;
use std::process::ExitCode;

/// Arguments of `formation scenario`.
#[derive(clap::Args, Debug)]
pub struct ScenarioArgs {
    /// Number of quadrotors (2..=64).
    #[arg(long, value_parser = crate::cli::whole_number::<usize>, allow_negative_numbers = true)]
    pub n: usize,
    /// Communication graph: `ring` or `path`.
    #[arg(long, default_value = "path")]
    pub graph: String,
    /// Output file (default: standard output).
    #[arg(long)]
    pub out: Option<PathBuf>,
}

/// Smallest distance between neighbouring start positions, m.
const START_SPACING_M: f64 = 1.5;

/// Builds the scenario with `n` agents on `graph` ("ring" or "path").
pub fn generate(n: usize, graph: &str) -> Result<Scenario, String> {
    if !(2..=formation_config::MAX_AGENTS).contains(&n) {
        return Err(format!(
            "--n {n}: expected 2..={}",
            formation_config::MAX_AGENTS
        ));
    }
    let ring = match graph {
        "ring" => true,
        "path" => false,
        other => return Err(format!("--graph {other}: expected ring or path")),
    };
    let mut s = Scenario::paper();
    let template = s.agents.clone();
    let centre = [0.0, s.mission.target.path_radius_m]; // T_g(0)
    let paper_radius = 2.64;
    let radius = (START_SPACING_M * n as f64 / (2.0 * std::f64::consts::PI)).max(paper_radius);
    s.agents = (0..n)
        .map(|i| {
            let mut a = template[i % template.len()].clone();
            let phi =
                std::f64::consts::FRAC_PI_2 + 2.0 * std::f64::consts::PI * i as f64 / n as f64;
            a.initial_position_m = [
                centre[0] + radius * phi.cos(),
                centre[1] + radius * phi.sin(),
                0.0,
            ];
            a
        })
        .collect();
    let mut edges: Vec<Edge> = (1..n)
        .map(|a| Edge {
            a,
            b: a + 1,
            weight: 1.0,
        })
        .collect();
    let mut b = vec![0.0; n];
    b[0] = 1.0;
    if ring && n > 2 {
        edges.push(Edge {
            a: n,
            b: 1,
            weight: 1.0,
        });
        b[n / 2] = 1.0;
    } else {
        b[n - 1] = 1.0;
    }
    s.graph.edges = edges;
    s.graph.leader_weights = b;
    s.name = format!("gen{n}-{graph}");
    s.description = format!(
        "Generated from the paper scenario: {n} agents on a {graph} graph, agent specs reused cyclically."
    );
    Ok(s)
}

/// Entry point of `formation scenario`.
pub fn main(args: ScenarioArgs) -> ExitCode {
    let s = match generate(args.n, &args.graph) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::from(EXIT_INVALID);
        }
    };
    if let Err(errs) = validate(&s) {
        eprintln!("error: the generated scenario is invalid:");
        for e in &errs.0 {
            eprintln!("  {e}");
        }
        return ExitCode::from(EXIT_INVALID);
    }
    let text = s.to_toml_string();
    match &args.out {
        Some(path) => match std::fs::write(path, text) {
            Ok(()) => {
                eprintln!("wrote {}", path.display());
                ExitCode::SUCCESS
            }
            Err(e) => {
                eprintln!("error: cannot write {}: {e}", path.display());
                ExitCode::from(1)
            }
        },
        None => {
            print!("{text}");
            ExitCode::SUCCESS
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn generated_scenarios_are_valid() {
        for n in [2, 5, 20, 50] {
            for g in ["ring", "path"] {
                let s = generate(n, g).unwrap();
                assert_eq!(s.n_agents(), n);
                validate(&s).unwrap();
            }
        }
        assert!(generate(1, "path").is_err());
        assert!(generate(5, "star").is_err());
    }
}
