//! `summary.json`: the stable contract every runner writes (documented in README, "summary.json").

use super::metrics::{Divergence, Metrics};
use super::separation::Approach;
use formation_config::Variant;
use serde::Serialize;
use std::path::Path;

/// A value per metric window.
#[derive(Debug, Clone, Serialize)]
pub struct PerWindow {
    /// Covering window.
    pub cover: Option<f64>,
    /// Enclosing window.
    pub enclose: Option<f64>,
    /// The whole run.
    pub whole: Option<f64>,
}

/// Closest approach per metric window.
#[derive(Debug, Clone, Serialize)]
pub struct ApproachPerWindow {
    /// Covering window.
    pub cover: Option<Approach>,
    /// Enclosing window.
    pub enclose: Option<Approach>,
    /// The whole run.
    pub whole: Option<Approach>,
}

/// Separation between the quadrotors (docs/formats.md).
#[derive(Debug, Clone, Serialize)]
pub struct SeparationSummary {
    /// `metrics.safety_distance_m` of the scenario, m.
    pub safety_distance_m: f64,
    /// Steps at which the closest two quadrotors were nearer than the safety distance.
    pub steps_below_safety: u64,
    /// `"ok"`, or `"fail"` when two quadrotors came nearer than the safety distance: the run
    /// failed (`sim` and `run` exit with code 3, as for a divergence; docs/cli.md).
    pub verdict: &'static str,
    /// Closest approach (distance, time, pair) per window.
    pub min_distance: ApproachPerWindow,
}

/// One agent's separation: how long its separation layer acted (D25) and how close it came.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct AgentSeparation {
    /// Time its layer changed U_iP, s.
    pub layer_active_s: f64,
    /// Smallest separation its layer predicted from the delayed broadcast, m (null: never
    /// another quadrotor in its sensing range).
    pub min_predicted_m: Option<f64>,
    /// Smallest true distance to any other quadrotor, m (null: alone).
    pub min_actual_m: Option<f64>,
}

/// Metrics of one agent.
#[derive(Debug, Clone, Serialize)]
pub struct AgentSummary {
    /// Agent (1-based).
    pub id: usize,
    /// RMS of ||P_i - P_d - Delta_i0|| per window, m.
    pub rms_formation_error_m: PerWindow,
    /// Max of the same per window, m.
    pub max_formation_error_m: PerWindow,
    /// Steps with ||A_i|| > ||A_iC|| + margin.
    pub attitude_constraint_violations: u64,
    /// Steps with ||Omega_i|| > C-bar_i2.
    pub rate_constraint_violations: u64,
    /// min over steps of (||A_iC|| + margin - ||A_i||), rad.
    pub min_attitude_margin_rad: Option<f64>,
    /// min over steps of (C-bar_i2 - ||Omega_i||), rad/s.
    pub min_rate_margin_rad_s: Option<f64>,
    /// Share of steps with a torque channel at its limit.
    pub torque_saturation_fraction: f64,
    /// Its separation layer and closest approach (D25).
    pub separation: AgentSeparation,
    /// Times its process was restarted under `runtime.restart = "on-failure"` after a failure
    /// (a death or hang outside the timeline, its host lost): not the successors of scheduled
    /// crashes and hangs (timeline or injected), nor starts that waited for a fence.
    pub restarts: u32,
    /// Checkpoints refused at a restart (damaged, another agent's or another run's), each
    /// restarted cold at once instead.
    pub checkpoints_refused: u32,
    /// Multi-host runs: the host its process ran on at the end of the run (`local`: the
    /// launching machine; an agent lost with its host was taken over there).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub host: Option<String>,
}

/// The whole summary.
#[derive(Debug, Clone, Serialize)]
pub struct Summary {
    /// Scenario name.
    pub scenario: String,
    /// Controller variant.
    pub variant: String,
    /// "in-process", "lockstep" or "realtime".
    pub mode: String,
    /// N.
    pub n_agents: usize,
    /// Integration step, s.
    pub dt_s: f64,
    /// Simulated time reached, s.
    pub sim_time_s: f64,
    /// Steps simulated.
    pub steps: u64,
    /// Wall-clock time of the whole run, s.
    pub wall_time_s: f64,
    /// sim_time_s / wall_time_s.
    pub realtime_factor: f64,
    /// True when a quantity left its bounds (the run stopped there).
    pub diverged: bool,
    /// Where and why, or null.
    pub divergence: Option<Divergence>,
    /// Mean covered share of the target disk over the cover window.
    pub coverage_fraction: Option<f64>,
    /// Closest approach of two quadrotors and steps below the safety distance.
    pub separation: SeparationSummary,
    /// Per-agent metrics.
    pub agents: Vec<AgentSummary>,
    /// Timing statistics: realtime runs (latencies, jitter, deadline misses) and lockstep runs
    /// (steady-state wall time per step); absent for `formation sim`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub timing: Option<serde_json::Value>,
    /// The end of the export of a run with `--zenoh-listen` (`formation_net::export::EndReport`):
    /// steps put, steps the export missed, how long its end took; absent without the export.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub export: Option<serde_json::Value>,
    /// Each event of the timeline and each incident of the supervision, with how the formation
    /// came through it (docs/failures.md).
    pub events: Vec<super::recovery::EventSummary>,
    /// Whether Assumption 1 held at every step (only when the timeline can break it).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub connectivity: Option<super::recovery::Connectivity>,
}

fn finite(v: f64) -> Option<f64> {
    v.is_finite().then_some(v)
}

impl Summary {
    /// Builds the summary from the metrics.
    pub fn build(
        m: &Metrics,
        scenario: &str,
        variant: Variant,
        mode: &str,
        dt: f64,
        steps: u64,
        wall_time_s: f64,
    ) -> Summary {
        let sim_time = steps as f64 * dt;
        Summary {
            scenario: scenario.to_string(),
            variant: variant.name().to_string(),
            mode: mode.to_string(),
            n_agents: m.agents.len(),
            dt_s: dt,
            sim_time_s: sim_time,
            steps,
            wall_time_s,
            realtime_factor: if wall_time_s > 0.0 {
                sim_time / wall_time_s
            } else {
                0.0
            },
            diverged: m.divergence.is_some(),
            divergence: m.divergence.clone(),
            coverage_fraction: m.coverage_fraction(),
            separation: SeparationSummary {
                safety_distance_m: m.separation.safety_distance_m,
                steps_below_safety: m.separation.steps_below_safety,
                verdict: if m.separation.steps_below_safety == 0 {
                    "ok"
                } else {
                    "fail"
                },
                min_distance: ApproachPerWindow {
                    cover: m.separation.cover,
                    enclose: m.separation.enclose,
                    whole: m.separation.whole,
                },
            },
            agents: m
                .agents
                .iter()
                .enumerate()
                .map(|(i, a)| AgentSummary {
                    id: i + 1,
                    rms_formation_error_m: PerWindow {
                        cover: a.cover.rms(),
                        enclose: a.enclose.rms(),
                        whole: a.whole.rms(),
                    },
                    max_formation_error_m: PerWindow {
                        cover: a.cover.max(),
                        enclose: a.enclose.max(),
                        whole: a.whole.max(),
                    },
                    attitude_constraint_violations: a.attitude_violations,
                    rate_constraint_violations: a.rate_violations,
                    min_attitude_margin_rad: finite(a.min_attitude_margin),
                    min_rate_margin_rad_s: finite(a.min_rate_margin),
                    torque_saturation_fraction: if m.steps > 0 {
                        a.saturated_steps as f64 / m.steps as f64
                    } else {
                        0.0
                    },
                    separation: AgentSeparation {
                        layer_active_s: a.separation.active_s(dt),
                        min_predicted_m: finite(a.separation.min_predicted_m),
                        min_actual_m: m.separation.nearest_m(i).and_then(finite),
                    },
                    restarts: 0,
                    checkpoints_refused: 0,
                    host: None,
                })
                .collect(),
            timing: None,
            export: None,
            events: Vec::new(),
            connectivity: None,
        }
    }

    /// Writes it as pretty JSON.
    pub fn write(&self, path: &Path) -> std::io::Result<()> {
        formation_config::node::files::write_atomic(path, (self.to_json() + "\n").as_bytes())
    }

    /// The pretty JSON of `summary.json` (without the final line break).
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self)
            .expect("a summary serialises (no map with non-string keys)")
    }

    /// Prints the human-readable table.
    pub fn print_table(&self) {
        let f = |v: Option<f64>| v.map_or("-".to_string(), |x| format!("{x:.3}"));
        println!(
            "{} / {} / {}: N = {}, {:.1} s simulated in {:.2} s ({:.0}x real time), coverage {}",
            self.scenario,
            self.variant,
            self.mode,
            self.n_agents,
            self.sim_time_s,
            self.wall_time_s,
            self.realtime_factor,
            self.coverage_fraction
                .map_or("-".into(), |c| format!("{:.1} %", 100.0 * c))
        );
        println!(
            "{:>5} {:>9} {:>9} {:>9} {:>9} {:>7} {:>7} {:>9} {:>9} {:>6} {:>7} {:>8} {:>8}",
            "agent",
            "rms_cov",
            "max_cov",
            "rms_enc",
            "max_enc",
            "att_vio",
            "rate_vio",
            "att_marg",
            "rate_marg",
            "sat%",
            "sep_s",
            "sep_pred",
            "sep_min"
        );
        for a in &self.agents {
            println!(
                "{:>5} {:>9} {:>9} {:>9} {:>9} {:>7} {:>7} {:>9} {:>9} {:>6.2} {:>7.2} {:>8} {:>8}",
                a.id,
                f(a.rms_formation_error_m.cover),
                f(a.max_formation_error_m.cover),
                f(a.rms_formation_error_m.enclose),
                f(a.max_formation_error_m.enclose),
                a.attitude_constraint_violations,
                a.rate_constraint_violations,
                f(a.min_attitude_margin_rad),
                f(a.min_rate_margin_rad_s),
                100.0 * a.torque_saturation_fraction,
                a.separation.layer_active_s,
                f(a.separation.min_predicted_m),
                f(a.separation.min_actual_m)
            );
        }
        let sep = &self.separation;
        match sep.min_distance.whole {
            Some(a) => {
                println!(
                "separation: min {:.3} m (agents {} and {} at t = {:.3} s), {} steps below {} m",
                a.distance_m, a.agents[0], a.agents[1], a.time_s, sep.steps_below_safety,
                sep.safety_distance_m
            )
            }
            None => println!("separation: - (fewer than two quadrotors)"),
        }
        if sep.steps_below_safety > 0 {
            println!(
                "FAIL: two quadrotors came nearer than the safety distance of {} m ({} steps)",
                sep.safety_distance_m, sep.steps_below_safety
            );
        }
        for e in &self.events {
            let who = match (e.agent, e.agents) {
                (_, Some([a, b])) => format!(" {a}-{b}"),
                (Some(a), None) => format!(" agent {a}"),
                (None, None) => String::new(),
            };
            let recovered = e
                .recovered_after_s
                .map_or("not recovered".to_string(), |r| {
                    format!("recovered after {r:.3} s")
                });
            let restarted = e
                .restarted_after_ms
                .map_or(String::new(), |r| format!(", new process after {r:.0} ms"));
            println!(
                "event {}{who} at t = {:.3} s: {recovered} (under {:.2} m), peak error {:.3} m, {} violations{restarted}",
                e.kind, e.at_s, e.recovery_threshold_m, e.peak_error_m, e.violations_during
            );
        }
        if let Some(c) = &self.connectivity {
            match (c.assumption1_held, c.first_violated_at_s, c.last_violated_at_s) {
                (true, _, _) => println!("connectivity: Assumption 1 held at every step"),
                (false, Some(a), Some(b)) => println!(
                    "connectivity: Assumption 1 broken at {} steps, from t = {a:.3} s to {b:.3} s (graph of the agents and links that are up not connected, or no pinned agent up)",
                    c.steps_violated
                ),
                _ => {}
            }
        }
        if let Some(d) = &self.divergence {
            println!(
                "DIVERGED at t = {:.3} s, agent {}: {}",
                d.time_s, d.agent, d.cause
            );
        }
    }
}
