//! `formation scenario`: a scenario with N agents generated from a template (the paper scenario by
//! default) for scaling runs and sweeps.
//!
//! * [`radii`]: cover and enclose radii and the enclosing spin rate from N, the minimum neighbour
//!   spacing and the coverage geometry (the formula is documented there and in docs/scaling.md).
//! * [`graphs`]: ring, path, k-nearest, complete and random-connected graphs, leader weights.
//!
//! Agent specs (delays, faults, uncertainty, disturbance) are reused cyclically; each quadrotor
//! starts [`START_OUTSIDE_M`] radially outside its cover slot at t = 0, as in the paper.

pub mod graphs;
pub mod radii;
pub mod rings;

use formation_config::scenario::validate::{validate, ValidationErrors};
use formation_config::scenario::Scenario;

use graphs::GraphKind;
use std::path::PathBuf;

/// Arguments of `formation scenario`.
#[derive(clap::Args, Debug)]
pub struct ScenarioArgs {
    /// Number of quadrotors (2..=MAX_AGENTS, 128).
    #[arg(long, value_parser = formation_runtime::cli::whole_number::<usize>, allow_negative_numbers = true)]
    pub n: usize,
    /// Communication graph: ring, path, k-nearest, complete, random-connected.
    #[arg(long, default_value = "path")]
    pub graph: String,
    /// Neighbours per agent of `--graph k-nearest` (before symmetrisation).
    #[arg(long, default_value_t = 4, value_parser = formation_runtime::cli::whole_number::<usize>, allow_negative_numbers = true)]
    pub k: usize,
    /// Seed of `--graph random-connected`.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Agents that receive the leader (b_i = 1), 1-based, e.g. `1,5`. Default: the paper's share
    /// (2 in 5) spread evenly, from end to end on a path (N = 5 path: 1,5); on a random-connected
    /// graph the agents of the lowest degree first.
    #[arg(long, value_name = "IDS")]
    pub leader_agents: Option<String>,
    /// Minimum distance between two formation slots s_min, m. Default: the spacing of the paper's
    /// enclosing ring (2 R_e sin(pi/5) = 1.176 m), so that N = 5 gives the paper's radii.
    #[arg(long, value_name = "M")]
    pub min_spacing: Option<f64>,
    /// Output file (default: standard output).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Write the scenario as JSON (the same fields as the TOML) instead of TOML.
    #[arg(long)]
    pub json: bool,
}

/// How far outside its cover slot each quadrotor starts, m: the paper's quadrotors start on a
/// 2.64 m circle around T_g(0) at their slots' phases, 0.64 m outside the 2.0 m cover ring.
pub const START_OUTSIDE_M: f64 = 0.64;

/// What to generate.
#[derive(Debug, Clone, PartialEq)]
pub struct GenOptions {
    /// N.
    pub n: usize,
    /// Graph family.
    pub graph: GraphKind,
    /// k of k-nearest.
    pub k: usize,
    /// Seed of random-connected.
    pub seed: u64,
    /// Agents with b_i = 1 (1-based); `None`: [`graphs::default_leader_agents`]
    /// ([`graphs::least_coupled_leader_agents`] for random-connected graphs).
    pub leader_agents: Option<Vec<usize>>,
    /// s_min, m; `None`: the template's enclosing spacing.
    pub min_spacing_m: Option<f64>,
}

impl GenOptions {
    /// N agents on `graph` with every other option at its default.
    pub fn new(n: usize, graph: GraphKind) -> GenOptions {
        GenOptions {
            n,
            graph,
            k: 4,
            seed: 1,
            leader_agents: None,
            min_spacing_m: None,
        }
    }
}

/// Radius-formula inputs of a template scenario for `n` agents.
pub fn radii_inputs(
    template: &Scenario,
    n: usize,
    min_spacing_m: Option<f64>,
) -> radii::RadiiInputs {
    let f = &template.mission.formation;
    let n_tpl = template.n_agents().max(2);
    radii::RadiiInputs {
        n,
        min_spacing_m: min_spacing_m
            .unwrap_or_else(|| radii::ring_spacing(n_tpl, f.enclose_radius_m)),
        target_radius_m: template.metrics.target_radius_m,
        footprint_radius_m: template.mission.leader.cruise_altitude_m
            * (template.metrics.sensor_fov_deg.to_radians() / 2.0).tan(),
        template_cover_m: f.cover_radius_m,
        template_enclose_m: f.enclose_radius_m,
        template_spin_rad_s: f.spin_rate_rad_s,
    }
}

/// Places every quadrotor `outside_m` radially outside its cover slot at t = 0 (its ring's cover
/// radius, at its slot's phase around T_g(0); one ring: phi_i = phi_0 + 2 pi (i - 1)/N), on the ground.
pub fn place_starts(s: &mut Scenario, outside_m: f64) {
    let n = s.n_agents();
    let f = s.mission.formation.clone();
    let centre = [0.0, s.mission.target.path_radius_m]; // T_g(0)
    for (i, a) in s.agents.iter_mut().enumerate() {
        let (cover, _, phi) = f.slot(i, n).unwrap_or_default();
        let r = cover + outside_m;
        a.initial_position_m = [centre[0] + r * phi.cos(), centre[1] + r * phi.sin(), 0.0];
    }
}

/// Why a scenario cannot be generated: the option named and what it expects.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GenError {
    /// `--graph` is not a graph family.
    #[error("--graph {0}: expected ring, path, k-nearest, complete or random-connected")]
    Graph(String),
    /// An entry of `--leader-agents` is not an integer.
    #[error("--leader-agents '{list}': '{part}' is not an agent id (1-based integers)")]
    LeaderId {
        /// The whole list as given.
        list: String,
        /// The entry refused.
        part: String,
    },
    /// An id of `--leader-agents` is outside 1..=N.
    #[error("--leader-agents '{list}': agent {id} is outside 1..={n}")]
    LeaderOutside {
        /// The whole list as given.
        list: String,
        /// The id refused (1-based).
        id: usize,
        /// Agents N.
        n: usize,
    },
    /// An id of `--leader-agents` is given twice.
    #[error("--leader-agents '{list}': agent {id} is listed twice")]
    LeaderTwice {
        /// The whole list as given.
        list: String,
        /// The id repeated (1-based).
        id: usize,
    },
    /// A leader agent of the options is outside 1..=N.
    #[error("--leader-agents: agent {id} is outside 1..={n}")]
    LeaderAgent {
        /// The id refused (1-based).
        id: usize,
        /// Agents N.
        n: usize,
    },
    /// `--n` is outside 2..=MAX_AGENTS.
    #[error("--n {n}: expected 2..={max}")]
    N {
        /// N given.
        n: usize,
        /// The largest N.
        max: usize,
    },
    /// `--min-spacing` is not a positive distance.
    #[error("--min-spacing {0}: expected a positive distance in m")]
    MinSpacing(f64),
    /// `--k` is outside 1..N.
    #[error("--k {k}: expected 1..={} for N = {n}", n - 1)]
    K {
        /// k given.
        k: usize,
        /// Agents N.
        n: usize,
    },
}

/// The paper scenario scaled to `opts`.
pub fn generate(opts: &GenOptions) -> Result<Scenario, GenError> {
    generate_from(&Scenario::paper(), opts)
}

/// `template` scaled to `opts`: N agents (specs reused cyclically), radii and spin rate of
/// [`radii`], the graph of [`graphs`], starts [`START_OUTSIDE_M`] outside the cover slots.
pub fn generate_from(template: &Scenario, opts: &GenOptions) -> Result<Scenario, GenError> {
    let n = opts.n;
    if !(2..=formation_config::MAX_AGENTS).contains(&n) {
        return Err(GenError::N {
            n,
            max: formation_config::MAX_AGENTS,
        });
    }
    if let Some(s) = opts.min_spacing_m {
        if !(s.is_finite() && s > 0.0) {
            return Err(GenError::MinSpacing(s));
        }
    }
    if opts.graph == GraphKind::KNearest && !(1..n).contains(&opts.k) {
        return Err(GenError::K { k: opts.k, n });
    }
    let mut s = template.clone();
    let inputs = radii_inputs(template, n, opts.min_spacing_m);
    let r = radii::radii(&inputs);
    s.mission.formation.cover_radius_m = r.cover_m;
    s.mission.formation.enclose_radius_m = r.enclose_m;
    s.mission.formation.spin_rate_rad_s = r.spin_rad_s;
    s.mission.formation.rings.clear();
    let n_tpl = template.n_agents().max(2);
    let inner = radii::radii(&radii_inputs(template, n_tpl, opts.min_spacing_m));
    let layout =
        if rings::one_ring_cannot_cover(&r) && !rings::one_ring_cannot_cover(&inner) && n > n_tpl {
            // Concentric rings (rings.rs): the template's ring inside, covering; the rest around it.
            let f = &mut s.mission.formation;
            f.rings = rings::concentric(
                n,
                n_tpl,
                inner.cover_m,
                inner.enclose_m,
                inputs.min_spacing_m,
                f.first_phase_rad,
            );
            f.cover_radius_m = inner.cover_m;
            f.enclose_radius_m = inner.enclose_m;
            let outer = &f.rings[f.rings.len() - 1];
            f.spin_rate_rad_s = rings::spin_rate(
                inputs.template_spin_rad_s,
                inputs.template_enclose_m,
                outer.enclose_radius_m,
            );
            let counts: Vec<String> = f.rings.iter().map(|r| r.agents.to_string()).collect();
            format!(
                "{} concentric rings ({} agents), cover radii {}..{} m, enclose radii {}..{} m",
                f.rings.len(),
                counts.join(" + "),
                f.rings[0].cover_radius_m,
                outer.cover_radius_m,
                f.rings[0].enclose_radius_m,
                outer.enclose_radius_m
            )
        } else {
            format!(
                "cover radius {} m, enclose radius {} m",
                r.cover_m, r.enclose_m
            )
        };
    s.agents = (0..n)
        .map(|i| template.agents[i % template.agents.len()].clone())
        .collect();
    place_starts(&mut s, START_OUTSIDE_M);
    let e = graphs::edges(opts.graph, n, opts.k, opts.seed);
    let leaders = match &opts.leader_agents {
        Some(l) => l.clone(),
        None if opts.graph == GraphKind::RandomConnected => {
            graphs::least_coupled_leader_agents(n, &e)
        }
        None => graphs::default_leader_agents(opts.graph, n),
    };
    let (a_w, b_w) = graphs::weights(n, &e, &leaders);
    s.graph.edges = graphs::to_scenario_edges(&e, &a_w);
    let mut b = vec![0.0; n];
    for &id in &leaders {
        if !(1..=n).contains(&id) {
            return Err(GenError::LeaderAgent { id, n });
        }
        b[id - 1] = b_w;
    }
    s.graph.leader_weights = b;
    let g = opts.graph.name();
    s.name = format!("gen{n}-{g}");
    s.description = format!(
        "Generated from '{}': {n} agents on a {g} graph (leaders {leaders:?}), {layout}, spin {:.4} \
         rad/s, agent specs reused cyclically.",
        template.name, s.mission.formation.spin_rate_rad_s
    );
    Ok(s)
}

fn options(args: &ScenarioArgs) -> Result<GenOptions, GenError> {
    let graph = GraphKind::parse(&args.graph)?;
    let leader_agents = args
        .leader_agents
        .as_deref()
        .map(|l| graphs::parse_leader_agents(l, args.n))
        .transpose()?;
    Ok(GenOptions {
        n: args.n,
        graph,
        k: args.k,
        seed: args.seed,
        leader_agents,
        min_spacing_m: args.min_spacing,
    })
}

/// Why `formation scenario` did not write its scenario; its `Display` is the message on stderr.
#[derive(Debug, thiserror::Error)]
pub enum ScenarioError {
    /// An option is refused (bad input).
    #[error("error: {0}")]
    Options(#[from] GenError),
    /// The generated scenario breaks an assumption of the paper (bad input: the options ask for
    /// it): every error, one per line.
    #[error("error: the generated scenario is invalid:\n{}", indented(.0))]
    Invalid(ValidationErrors),
    /// The scenario could not be written as JSON.
    #[error("error: cannot write the scenario as JSON: {0}")]
    Json(serde_json::Error),
    /// `--out` could not be written.
    #[error("error: cannot write {}: {source}", path.display())]
    Write {
        /// The file of `--out`.
        path: std::path::PathBuf,
        /// What the system said.
        source: std::io::Error,
    },
}

/// Each error on its own line, indented by two spaces.
fn indented(errors: &ValidationErrors) -> String {
    let lines: Vec<String> = errors.0.iter().map(|e| format!("  {e}")).collect();
    lines.join("\n")
}

/// Entry point of `formation scenario`: writes the generated scenario to `--out` or stdout.
pub fn main(args: ScenarioArgs) -> Result<(), ScenarioError> {
    let s = generate(&options(&args)?)?;
    validate(&s).map_err(ScenarioError::Invalid)?;
    let text = if args.json {
        serde_json::to_string_pretty(&s).map_err(ScenarioError::Json)? + "\n"
    } else {
        s.to_toml_string()
    };
    match &args.out {
        Some(path) => {
            std::fs::write(path, text).map_err(|source| ScenarioError::Write {
                path: path.clone(),
                source,
            })?;
            eprintln!("wrote {}", path.display());
        }
        None => print!("{text}"),
    }
    Ok(())
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// Every agent's slot at transition level `level` (1: covering, 0: enclosing), before the spin.
    fn slots(s: &Scenario, level: f64) -> Vec<[f64; 2]> {
        let n = s.n_agents();
        (0..n)
            .map(|i| {
                let (c, e, phi) = s.mission.formation.slot(i, n).unwrap();
                let r = e + (c - e) * level;
                [r * phi.cos(), r * phi.sin()]
            })
            .collect()
    }

    /// The smallest distance between two of the points `p`, m.
    pub(crate) fn min_distance(p: &[[f64; 2]]) -> f64 {
        let mut m = f64::INFINITY;
        for i in 0..p.len() {
            for j in i + 1..p.len() {
                m = m.min((p[i][0] - p[j][0]).hypot(p[i][1] - p[j][1]));
            }
        }
        m
    }

    #[test]
    fn generated_scenarios_of_every_graph_family_validate() {
        for n in [2, 3, 5, 20, 50, 100, 128] {
            for g in ["ring", "path", "k-nearest", "complete", "random-connected"] {
                let mut o = GenOptions::new(n, GraphKind::parse(g).unwrap());
                o.k = 4.min(n - 1);
                let s = generate(&o).unwrap();
                assert_eq!(s.n_agents(), n);
                validate(&s).unwrap_or_else(|e| panic!("n = {n}, {g}: {e:?}"));
            }
        }
        assert!(generate(&GenOptions::new(1, GraphKind::Path)).is_err());
        assert!(generate(&GenOptions::new(129, GraphKind::Path)).is_err());
        assert!(GraphKind::parse("star").is_err());
    }

    #[test]
    fn five_agent_path_is_the_paper_scenario_up_to_rounding_of_the_starts() {
        let g = generate(&GenOptions::new(5, GraphKind::Path)).unwrap();
        let p = Scenario::paper();
        assert_eq!(g.mission, p.mission);
        assert_eq!(g.graph, p.graph);
        for (a, b) in g.agents.iter().zip(&p.agents) {
            for k in 0..3 {
                assert!((a.initial_position_m[k] - b.initial_position_m[k]).abs() < 0.02);
            }
            assert_eq!(a.fault, b.fault);
            assert_eq!(a.delay, b.delay);
        }
    }

    #[test]
    fn generated_twenty_ring_neighbours_are_at_least_the_minimum_spacing_apart_at_their_slots() {
        let s = generate(&GenOptions::new(20, GraphKind::Ring)).unwrap();
        let s_min = radii::ring_spacing(5, 1.0);
        // Twenty agents fly concentric rings (5 + 11 + 4), whose inner ring is the paper's.
        let counts: Vec<usize> = s.mission.formation.rings.iter().map(|r| r.agents).collect();
        assert_eq!(counts, vec![5, 11, 4]);
        for level in [1.0, 0.5, 0.0] {
            let d = min_distance(&slots(&s, level));
            assert!(d >= s_min - 1e-3, "level {level}: slots {d} m apart");
        }
        // Starts are farther apart still.
        let starts: Vec<[f64; 2]> = s
            .agents
            .iter()
            .map(|a| [a.initial_position_m[0], a.initial_position_m[1]])
            .collect();
        assert!(min_distance(&starts) >= s_min);
    }

    #[test]
    fn leader_agents_option_sets_b_for_the_listed_one_based_ids_only() {
        let mut o = GenOptions::new(7, GraphKind::Ring);
        o.leader_agents = Some(vec![1, 5]);
        let s = generate(&o).unwrap();
        // Pinned agents 1 and 5 sit between two neighbours: row sum 2 + 1 = 3 is scaled to
        // graphs::MAX_ROW_SUM, so b = a = 0.9.
        let expected = [0.9, 0.0, 0.0, 0.0, 0.9, 0.0, 0.0];
        for (b, e) in s.graph.leader_weights.iter().zip(expected) {
            assert!((b - e).abs() < 1e-12, "{:?}", s.graph.leader_weights);
        }
        assert!(s.graph.edges.iter().all(|e| (e.weight - 0.9).abs() < 1e-12));
    }
}
