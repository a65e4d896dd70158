//! `formation check [SCENARIO] [--json]`: what decides whether a gain set can work.
//!
//! Pure computations live in the submodules (each unit-tested); this module assembles the
//! [`Report`], derives one [`Verdict`] per check, and prints it as text or as one JSON object.
//!
//! * [`spectrum`]: eigenvalues of L + B, positive definiteness (Lemma 1, Assumption 1).
//! * [`theorem1`]: the matrix M of eq. (18) (read as symmetric: the printed upper triangle mirrored),
//!   the (M1, M2) maximising its smallest eigenvalue, the printed ties, necessary conditions.
//! * [`outer`]: consensus modes s² + lambda k_V s + lambda k_P, uncertainty slopes (61), the RBFNN's
//!   leakage; [`inner`]: BLF gains near z = 0, time-scale ratios and phase margins of the cascade;
//!   [`freq`]: the linear-systems helpers both use.
//! * [`barrier`]: roll/pitch authority after the worst faults vs what the attitude command demands.
//!
//! Levels: OK; INFO, a sufficient condition of the paper that is not met (Theorem 1's M > 0 and
//! ties, which the shipped gains do not meet and yet fly), or a verdict on the gain set the checked
//! `--variant` does not fly; WARN, a rule of thumb broken; FAIL, the analysis predicts that the
//! design will not fly (L + B not positive definite, no leader-information window, a loop of the
//! flown gain set with no time-scale separation or phase margin).
//!
//! Exit code: 0 when the report was printed and no verdict is FAIL (INFO and WARN included), 3 when
//! one is FAIL (the report is printed all the same), 2 on an invalid scenario (docs/cli.md).
//!
//! # JSON fields (`--json`; stable names, units in the names or in the item docs)
//! * `scenario`: scenario name.
//! * `graph`: [`spectrum::Spectrum`] — `eigenvalues` (ascending), `positive_definite`,
//!   `lambda_min`, `lambda_max`, `sigma_max_g_inv`, `sigma_min_b_inv`.
//! * `theorem1`: [`theorem1::Theorem1`] — `inputs` {`k_p`, `k_v`, `nn_k_p`, `nn_k_v`, `k_w`, `tau_m`,
//!   `psi_m`, `sigma_max_g_inv`, `sigma_min_b_inv`}, `psi_m_bound`, `reading`, `search`
//!   {`positive_definite`, `best_min_eigenvalue`, `m1`, `m2`, `diagonal`, `at_search_boundary`,
//!   `range`}, `ties` {`nn_ratio`, `required_ratio`, `m2_from_nn_k_p`, `m2_from_nn_k_v`, `hold`},
//!   `necessary` [{`name`, `condition`, `lhs`, `rhs`, `holds`}]. Absent (`null`) when L + B is not
//!   positive definite.
//! * `outer`: [`OuterReport`] — `modes` [{`lambda`, `roots` [[re, im], [re, im]],
//!   `natural_frequency_rad_s`, `damping_ratio`}], `fastest_mode_rad_s`, `slowest_decay_rate`,
//!   `slowest_damping_rate`, `slowest_stiffness`, `delay_phase_deg`, `delay_only`
//!   {`crossover_rad_s`, `phase_margin_deg`}, `uncertainty` {...}, `quadratic_break_even_speed_m_s`,
//!   `rbfnn` {`forgetting_rate`, `static_p_gain_bound`, `static_d_gain_bound`}, `information`
//!   [`pinned::InformationStructure`] {`leader_broadcast`, `agents_with_leader_data`,
//!   `slowest_damping_rate`, `slowest_stiffness`, `k_v_needed`, `k_v_delay_limit`, `window_exists`}.
//! * `filters`: {`attitude`, `rate`}: [`freq::FilterPoles`] — `natural_frequency_rad_s`, `damping`,
//!   `poles`, `complex`, `slowest_rad_s`.
//! * `cascade_model`: the linear model behind the margins of `inner` (text).
//! * `inner`: [[`inner::InnerLoop`]; 2] for `constrained` and `unconstrained` — `gain_set`, `rule`,
//!   `attitude_gain`, `rate_gain`, `attitude_over_fastest_outer`, `rate_over_attitude`,
//!   `rate_filter_over_rate`, `rate_filter_over_attitude`, `attitude_loop`, `cascade`.
//! * `barrier`: [`barrier::Barrier`].
//! * `variant`, `gain_set`: the variant checked and the inner gain set it flies.
//! * `verdicts`: [{`check`, `level` ("OK" | "INFO" | "WARN" | "FAIL"), `why`}]; `worst`: the worst level.

pub mod barrier;
pub mod freq;
pub mod inner;
pub mod outer;
pub mod pinned;
mod render;
pub mod spectrum;
pub mod theorem1;
pub mod verdict;
mod verdicts;

use formation_config::scenario::graph::Topology;
use formation_config::Scenario;
use formation_runtime::cli::load_with_overrides;
use serde::Serialize;
pub use verdict::{Level, Verdict};

/// Arguments of `formation check`.
#[derive(clap::Args, Debug, Default)]
pub struct CheckArgs {
    /// Scenario: `paper` (default), `paper-exact`, or a path to a TOML file.
    pub scenario: Option<String>,
    /// Print the report as one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
    /// Override a scenario parameter, e.g. `--set controller.position.k_v=2` (repeatable).
    #[arg(long = "set", value_name = "PATH=VALUE")]
    pub sets: Vec<String>,
    /// The variant whose design is judged (proposed, no-rbfnn, unconstrained): the verdicts on
    /// the inner gain set it does not fly are information.
    #[arg(long, default_value = "proposed")]
    pub variant: String,
}

/// Outer-loop part of the report.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct OuterReport {
    /// One closed-loop mode per eigenvalue of L + B (no delay).
    pub modes: Vec<outer::OuterMode>,
    /// Magnitude of the fastest root, rad/s.
    pub fastest_mode_rad_s: f64,
    /// Decay rate of the slowest root, 1/s.
    pub slowest_decay_rate: f64,
    /// lambda_min k_V + k_L: the damping the slowest mode has against the uncertainty's negative damping, 1/s.
    pub slowest_damping_rate: f64,
    /// lambda_min k_P + k_LP: the stiffness of the slowest mode, 1/s².
    pub slowest_stiffness: f64,
    /// Phase lost to tau_M at the fastest mode: tau_M * fastest_mode_rad_s, degrees.
    pub delay_phase_deg: f64,
    /// Margin of the fastest mode with the delay only (ideal inner loop).
    pub delay_only: Option<freq::Margin>,
    /// Slopes of the uncertainty (61).
    pub uncertainty: outer::UncertaintySlopes,
    /// For velocity power 2, |∂f/∂V| = 2 |gain| |V| exceeds lambda_min k_V above this speed, m/s.
    pub quadratic_break_even_speed_m_s: Option<f64>,
    /// The RBFNN's forgetting rate and equivalent gains.
    pub rbfnn: outer::RbfnnRole,
    /// Who receives the leader's data and what that leaves to the slowest collective motion (D17).
    pub information: pinned::InformationStructure,
}

/// Poles of both command filters.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Filters {
    /// Command filter 1 (attitude command).
    pub attitude: freq::FilterPoles,
    /// Rate command filter (virtual control alpha).
    pub rate: freq::FilterPoles,
}

/// The whole report.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Report {
    /// Scenario name.
    pub scenario: String,
    /// The variant checked.
    pub variant: &'static str,
    /// The inner gain set it flies (`constrained` or `unconstrained`).
    pub gain_set: &'static str,
    /// Spectrum of L + B.
    pub graph: spectrum::Spectrum,
    /// Theorem 1 (absent when L + B is not positive definite).
    pub theorem1: Option<theorem1::Theorem1>,
    /// Outer loop.
    pub outer: OuterReport,
    /// Command filters.
    pub filters: Filters,
    /// The linear model the inner-loop and cascade margins come from.
    pub cascade_model: &'static str,
    /// Inner loops of the constrained and unconstrained gain sets.
    pub inner: Vec<inner::InnerLoop>,
    /// Barrier feasibility.
    pub barrier: barrier::Barrier,
    /// One verdict per check.
    pub verdicts: Vec<Verdict>,
    /// Worst verdict level.
    pub worst: Level,
}

/// Computes the whole report of a (validated) scenario.
pub fn report(s: &Scenario) -> Report {
    report_for(s, formation_config::Variant::Proposed)
}

/// The report of a (validated) scenario flown by `variant`.
pub fn report_for(s: &Scenario, variant: formation_config::Variant) -> Report {
    let graph = spectrum::spectrum(&Topology::from_scenario(s));
    let theorem1 = theorem1_of(s, &graph);
    let outer = outer_report(s, &graph);
    let (filters, inner) = inner_reports(s, &graph, outer.fastest_mode_rad_s);
    let barrier = barrier::analyse(s);
    let mut r = Report {
        scenario: s.name.clone(),
        variant: variant.name(),
        gain_set: if variant == formation_config::Variant::Unconstrained {
            "unconstrained"
        } else {
            "constrained"
        },
        graph,
        theorem1,
        outer,
        filters,
        cascade_model: inner::CASCADE_MODEL,
        inner,
        barrier,
        verdicts: Vec::new(),
        worst: Level::Ok,
    };
    r.verdicts = verdicts::all(&r);
    r.verdicts.extend(reference_verdicts(s));
    r.worst = r
        .verdicts
        .iter()
        .map(|v| v.level)
        .max_by_key(|l| *l as u8)
        .unwrap_or(Level::Ok);
    r
}

/// Whether each transition of the mission asks more of a slot than the vehicle can fly (D26):
/// the attitude command filter's rate limit lets a quadrotor change its acceleration by about
/// g x its roll and pitch rate limit (m/s³), and D5 caps the acceleration. WARN where the
/// transition as written asks more (naming what the leader flies instead when `mission.shaping`
/// caps it), OK where it does not.
pub fn reference_verdicts(s: &Scenario) -> Vec<Verdict> {
    let pg = &s.controller.position;
    let rl = s.controller.attitude_command_filter.rate_limit;
    let jerk = s.simulation.gravity_m_s2 * rl[0].min(rl[1]);
    let accel = pg.max_horizontal_accel_m_s2;
    let mission = formation_leader::Mission::from_scenario(s);
    mission
        .transitions()
        .iter()
        .map(|t| {
            let (a, j) = t.asked;
            let check = format!("reference.{}", t.name);
            if a <= accel && j <= jerk {
                Verdict::new(
                    &check,
                    Level::Ok,
                    format!(
                        "sharpness {:.3}/s asks {a:.2} m/s² and {j:.2} m/s³ of a slot, within {accel:.2} m/s² and {jerk:.2} m/s³",
                        t.written
                    ),
                )
            } else {
                let flown = if t.flown < t.written {
                    format!(
                        "; mission.shaping flies it at {:.3}/s ({:.2} m/s², {:.2} m/s³)",
                        t.flown, t.flies.0, t.flies.1
                    )
                } else {
                    "; flown as written (mission.shaping is off)".to_string()
                };
                Verdict::new(
                    &check,
                    Level::Warn,
                    format!(
                        "sharpness {:.3}/s asks {a:.2} m/s² and {j:.2} m/s³ of a slot, more than the vehicle's {accel:.2} m/s² and {jerk:.2} m/s³{flown}",
                        t.written
                    ),
                )
            }
        })
        .collect()
}

/// Theorem 1's analysis, when L + B is positive definite.
fn theorem1_of(s: &Scenario, graph: &spectrum::Spectrum) -> Option<theorem1::Theorem1> {
    let pos = &s.controller.position;
    let tau = s.simulation.max_delay_s;
    match (graph.sigma_max_g_inv, graph.sigma_min_b_inv) {
        (Some(g_inv), Some(b_inv)) => Some(theorem1::analyse(theorem1::Theorem1Inputs {
            k_p: pos.k_p,
            k_v: pos.k_v,
            nn_k_p: pos.nn_k_p,
            nn_k_v: pos.nn_k_v,
            k_w: pos.nn_leakage,
            tau_m: tau,
            psi_m: theorem1::psi_bound(s.controller.rbfnn.neurons_per_axis),
            sigma_max_g_inv: g_inv,
            sigma_min_b_inv: b_inv,
        })),
        _ => None,
    }
}

/// The outer loop's modes, margins and information structure.
fn outer_report(s: &Scenario, graph: &spectrum::Spectrum) -> OuterReport {
    let pos = &s.controller.position;
    let tau = s.simulation.max_delay_s;
    // The leader-relative terms (D11) add k_L to every mode's damping and k_LP to its stiffness:
    // s² + (lambda k_V + k_L) s + (lambda k_P + k_LP). For one mode this equals the consensus law with
    // the effective gains k_V + k_L / lambda and k_P + k_LP / lambda, which is how the loop models get them.
    let (k_l, k_lp) = (pos.leader_velocity_damping, pos.leader_position_gain);
    let modes = outer::outer_modes(&graph.eigenvalues, pos.k_p, pos.k_v, k_lp, k_l);
    let lmax = graph.lambda_max.max(1e-12);
    let (kp_fast, kv_fast) = (pos.k_p + k_lp / lmax, pos.k_v + k_l / lmax);
    let fastest = outer::fastest_root(&modes);
    let uncertainty = outer::uncertainty_slopes(&s.agents);
    // The k_V window of the information structure, with the fastest mode's margin from the same linear
    // cascade as `inner` (delay, command filter 1, attitude loop).
    let (fa, fr) = (
        &s.controller.attitude_command_filter,
        &s.controller.rate_command_filter,
    );
    let k_att =
        inner::blf_attitude_gain(s.controller.attitude.k1_alpha, s.controller.attitude.eps1_c);
    let cascade_margin = |k_v: f64| {
        freq::phase_margin(|w| {
            inner::outer_loop_cascade(
                lmax,
                (pos.k_p + k_lp / lmax, k_v + k_l / lmax, tau),
                inner::Filter {
                    w: fa.natural_frequency_rad_s,
                    xi: fa.damping,
                },
                inner::Filter {
                    w: fr.natural_frequency_rad_s,
                    xi: fr.damping,
                },
                k_att,
                w,
            )
        })
    };
    let information = pinned::analyse(
        &Topology::from_scenario(s),
        s.graph.leader_broadcast,
        (pos.k_p, pos.k_v, k_lp, k_l),
        &cascade_margin,
        uncertainty.worst_velocity_gain,
    );
    // Under `pinned` only some agents add k_L, k_LP: the least damping and stiffness come from the
    // matrices k_V (L+B) + k_L P, k_P (L+B) + k_LP P (under `all` they equal the per-mode values).
    let pinned = s.graph.leader_broadcast == formation_config::scenario::LeaderBroadcast::Pinned;
    let slowest_damping = if pinned {
        information.slowest_damping_rate
    } else {
        graph.lambda_min * pos.k_v + k_l
    };
    let slowest_stiffness = if pinned {
        information.slowest_stiffness
    } else {
        graph.lambda_min * pos.k_p + k_lp
    };
    OuterReport {
        fastest_mode_rad_s: fastest,
        slowest_decay_rate: outer::slowest_decay(&modes),
        slowest_damping_rate: slowest_damping,
        slowest_stiffness,
        delay_phase_deg: (tau * fastest).to_degrees(),
        delay_only: freq::phase_margin(|w| {
            inner::outer_loop_delay_only(graph.lambda_max, kp_fast, kv_fast, tau, w)
        }),
        quadratic_break_even_speed_m_s: (uncertainty.quadratic_slope_per_m_s > 0.0)
            .then(|| slowest_damping / uncertainty.quadratic_slope_per_m_s),
        uncertainty,
        rbfnn: outer::rbfnn_role(
            pos.nn_learning_rate,
            pos.nn_k_p,
            pos.nn_k_v,
            pos.nn_leakage,
            s.controller.rbfnn.neurons_per_axis,
        ),
        information,
        modes,
    }
}

/// The command filters' poles and the inner loops of both gain sets, against the fastest outer
/// mode `fastest` (rad/s).
fn inner_reports(
    s: &Scenario,
    graph: &spectrum::Spectrum,
    fastest: f64,
) -> (Filters, Vec<inner::InnerLoop>) {
    let pos = &s.controller.position;
    let tau = s.simulation.max_delay_s;
    let (k_l, k_lp) = (pos.leader_velocity_damping, pos.leader_position_gain);
    let lmax = graph.lambda_max.max(1e-12);
    let (kp_fast, kv_fast) = (pos.k_p + k_lp / lmax, pos.k_v + k_l / lmax);
    let (fa, fr) = (
        &s.controller.attitude_command_filter,
        &s.controller.rate_command_filter,
    );
    let filters = Filters {
        attitude: freq::filter_poles(fa.natural_frequency_rad_s, fa.damping),
        rate: freq::filter_poles(fr.natural_frequency_rad_s, fr.damping),
    };
    let cascade = inner::CascadeInputs {
        lambda_max: graph.lambda_max,
        fastest_outer_rad_s: fastest,
        outer: (kp_fast, kv_fast, tau),
        f1: inner::Filter {
            w: fa.natural_frequency_rad_s,
            xi: fa.damping,
        },
        f2: inner::Filter {
            w: fr.natural_frequency_rad_s,
            xi: fr.damping,
        },
        rate_filter_slowest_rad_s: filters.rate.slowest_rad_s,
    };
    let att = &s.controller.attitude;
    let un = &s.controller.unconstrained;
    let inner = vec![
        inner::analyse(
            "constrained",
            inner::BLF_RULE,
            inner::blf_attitude_gain(att.k1_alpha, att.eps1_c),
            inner::blf_rate_gain(att.k2_phi, att.eps2_c),
            &cascade,
        ),
        inner::analyse(
            "unconstrained",
            inner::UNCONSTRAINED_RULE,
            un.attitude_gain,
            un.rate_gain,
            &cascade,
        ),
    ];
    (filters, inner)
}

/// Why `formation check` did not succeed; its `Display` is the message on stderr.
#[derive(Debug, thiserror::Error)]
pub enum CheckError {
    /// The scenario, an override or the variant is refused (bad input).
    #[error("error: {0}")]
    Input(#[from] formation_runtime::cli::InputError),
    /// The report could not be written as JSON.
    #[error("error: cannot write the report as JSON: {0}")]
    Json(serde_json::Error),
    /// The report is printed and a verdict is FAIL (a result that is a failure; WARN verdicts do
    /// not fail the command). Nothing more is said.
    #[error("a verdict is FAIL")]
    Failed,
}

/// Entry point of `formation check`: prints the report; fails when a verdict is FAIL.
pub fn main(args: CheckArgs) -> Result<(), CheckError> {
    let s = load_with_overrides(args.scenario.as_deref(), &args.sets)?;
    let variant = formation_runtime::cli::parse_variant(&args.variant)?;
    let r = report_for(&s, variant);
    if args.json {
        let text = serde_json::to_string_pretty(&r).map_err(CheckError::Json)?;
        println!("{text}");
    } else {
        print!("{}", render::text(&r));
    }
    verdict_of(r.worst)
}

/// The outcome of a report that was printed: [`CheckError::Failed`] when a verdict is FAIL.
pub fn verdict_of(worst: Level) -> Result<(), CheckError> {
    match worst {
        Level::Fail => Err(CheckError::Failed),
        Level::Ok | Level::Info | Level::Warn => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paper_exact_report_fails_theorem1_and_the_time_scale_separation() {
        let r = report(&Scenario::paper_exact());
        let find = |name: &str| r.verdicts.iter().find(|v| v.check == name).unwrap().level;
        assert_eq!(find("graph.positive_definite"), Level::Ok);
        assert_eq!(find("theorem1.m_positive_definite"), Level::Info);
        assert_eq!(find("theorem1.ties"), Level::Info);
        assert_eq!(find("inner.constrained.attitude_over_outer"), Level::Fail);
        assert_eq!(r.worst, Level::Fail);
    }

    #[test]
    fn the_shipped_design_meets_no_sufficient_condition_of_theorem1_and_is_not_predicted_to_fail() {
        let r = report(&Scenario::paper());
        let find = |name: &str| r.verdicts.iter().find(|v| v.check == name).unwrap().level;
        assert_eq!(find("theorem1.m_positive_definite"), Level::Info);
        assert_eq!(find("inner.unconstrained.cascade_margin"), Level::Info);
        assert!(r.worst != Level::Fail, "{:?}", r.verdicts);
        let u = report_for(&Scenario::paper(), formation_config::Variant::Unconstrained);
        let level = u
            .verdicts
            .iter()
            .find(|v| v.check == "inner.unconstrained.cascade_margin")
            .unwrap()
            .level;
        assert_eq!(level, Level::Fail, "the flown gain set's margin is judged");
    }

    #[test]
    fn report_serialises_to_json_with_stable_top_level_fields() {
        let r = report(&Scenario::paper());
        let v: serde_json::Value = serde_json::to_value(&r).unwrap();
        for key in [
            "scenario", "graph", "theorem1", "outer", "filters", "inner", "barrier", "verdicts",
            "worst",
        ] {
            assert!(v.get(key).is_some(), "missing {key}");
        }
        assert_eq!(v["inner"][1]["gain_set"], "unconstrained");
        assert!(v["graph"]["eigenvalues"].as_array().unwrap().len() == 5);
    }
}
