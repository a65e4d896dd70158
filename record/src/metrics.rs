//! Per-step metrics of `summary.json`: formation error per window, constraint violations and margins,
//! torque saturation, coverage, separation, and the divergence detector.

use super::coverage::CoverageGrid;
use super::separation::Separation;
use formation_config::protocol::wire::{ControlCommand, PlantTruth, ReferenceFrame};
use formation_config::Scenario;

/// Where and why a run diverged.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Divergence {
    /// Time of the first step at which a quantity left its bounds, s.
    pub time_s: f64,
    /// Agent (1-based).
    pub agent: usize,
    /// The first quantity that left its bounds, with its value.
    pub cause: String,
}

/// Running statistics of one window.
#[derive(Debug, Clone, Default)]
pub struct WindowStat {
    sum_sq: f64,
    count: u64,
    max: f64,
}

impl WindowStat {
    fn add(&mut self, e: f64) {
        self.sum_sq += e * e;
        self.count += 1;
        self.max = self.max.max(e);
    }
    /// RMS over the window, `None` when the window saw no step.
    pub fn rms(&self) -> Option<f64> {
        (self.count > 0).then(|| (self.sum_sq / self.count as f64).sqrt())
    }
    /// Max over the window.
    pub fn max(&self) -> Option<f64> {
        (self.count > 0).then_some(self.max)
    }
}

/// Per-agent accumulators.
#[derive(Debug, Clone)]
pub struct AgentStats {
    /// Formation error in the cover window.
    pub cover: WindowStat,
    /// Formation error in the enclose window.
    pub enclose: WindowStat,
    /// Formation error over the whole run.
    pub whole: WindowStat,
    /// Steps with ||A_i|| > ||A_iC|| + margin.
    pub attitude_violations: u64,
    /// Steps with ||Omega_i|| > C-bar_i2.
    pub rate_violations: u64,
    /// min over steps of C-bar_i1 - ||A_i||.
    pub min_attitude_margin: f64,
    /// min over steps of C-bar_i2 - ||Omega_i||.
    pub min_rate_margin: f64,
    /// Steps with at least one torque channel at its limit.
    pub saturated_steps: u64,
    /// Latest formation error norm (for the CSV).
    pub last_error: f64,
    /// Its separation layer (D25).
    pub separation: formation_config::view::SeparationTally,
}

/// All metrics of a run.
pub struct Metrics {
    /// Per agent.
    pub agents: Vec<AgentStats>,
    cover_window: [f64; 2],
    enclose_window: [f64; 2],
    margin: f64,
    rate_limit: f64,
    torque_lo: [f64; 3],
    torque_hi: [f64; 3],
    divergence_position: f64,
    divergence_tilt: f64,
    grid: CoverageGrid,
    coverage_sum: f64,
    coverage_count: u64,
    /// Closest approach of two quadrotors.
    pub separation: Separation,
    /// Steps recorded.
    pub steps: u64,
    /// The divergence, once detected.
    pub divergence: Option<Divergence>,
    /// Time of the last recorded step, s.
    pub last_time: f64,
}

impl Metrics {
    /// Empty metrics for a scenario.
    pub fn new(s: &Scenario) -> Metrics {
        let blank = AgentStats {
            cover: WindowStat::default(),
            enclose: WindowStat::default(),
            whole: WindowStat::default(),
            attitude_violations: 0,
            rate_violations: 0,
            min_attitude_margin: f64::INFINITY,
            min_rate_margin: f64::INFINITY,
            saturated_steps: 0,
            last_error: 0.0,
            separation: Default::default(),
        };
        Metrics {
            agents: vec![blank; s.n_agents()],
            cover_window: s.metrics.cover_window_s,
            enclose_window: s.metrics.enclose_window_s,
            margin: s.controller.attitude.attitude_margin_rad,
            rate_limit: s.controller.attitude.rate_limit_rad_s,
            torque_lo: s.vehicle.torque_min_nm,
            torque_hi: s.vehicle.torque_max_nm,
            divergence_position: s.metrics.divergence_position_m,
            divergence_tilt: s.metrics.divergence_tilt_rad,
            grid: CoverageGrid::new(s.metrics.target_radius_m, s.metrics.sensor_fov_deg),
            coverage_sum: 0.0,
            coverage_count: 0,
            separation: Separation::with_capacity(s.metrics.safety_distance_m, s.n_agents()),
            steps: 0,
            divergence: None,
            last_time: 0.0,
        }
    }

    /// Mean covered share over the cover window, `None` if the window saw no step.
    pub fn coverage_fraction(&self) -> Option<f64> {
        (self.coverage_count > 0).then(|| self.coverage_sum / self.coverage_count as f64)
    }

    /// Accumulates step k; returns the divergence if it is first detected here.
    pub fn record(
        &mut self,
        _step: u64,
        r: &ReferenceFrame,
        truths: &[PlantTruth],
        commands: &[ControlCommand],
    ) -> Option<Divergence> {
        let t = r.t;
        self.steps += 1;
        self.last_time = t;
        let in_cover = t >= self.cover_window[0] && t <= self.cover_window[1];
        let in_enclose = t >= self.enclose_window[0] && t <= self.enclose_window[1];
        let mut first: Option<Divergence> = None;
        for (i, (tr, cmd)) in truths.iter().zip(commands).enumerate() {
            let st = &tr.state;
            let mut e2 = 0.0;
            for k in 0..3 {
                let e = st.position[k] - r.p_d[k] - r.offset[i][k];
                e2 += e * e;
            }
            let e = e2.sqrt();
            let a = &mut self.agents[i];
            a.last_error = e;
            a.whole.add(e);
            if in_cover {
                a.cover.add(e);
            }
            if in_enclose {
                a.enclose.add(e);
            }
            a.separation.observe(&cmd.telemetry);
            let att = norm(st.attitude);
            let c1_bar = norm(cmd.telemetry.attitude_cmd) + self.margin;
            if att > c1_bar {
                a.attitude_violations += 1;
            }
            a.min_attitude_margin = a.min_attitude_margin.min(c1_bar - att);
            let rate = norm(st.rate);
            if rate > self.rate_limit {
                a.rate_violations += 1;
            }
            a.min_rate_margin = a.min_rate_margin.min(self.rate_limit - rate);
            if (0..3).any(|k| {
                let u = tr.torque_applied_nm[k];
                u >= self.torque_hi[k] || u <= self.torque_lo[k]
            }) {
                a.saturated_steps += 1;
            }
            if self.divergence.is_none() && first.is_none() {
                let derived = Derived {
                    error: e,
                    attitude_norm: att,
                    c1_bar,
                    rate_norm: rate,
                };
                first = non_finite_output(r, i, tr, cmd, &derived)
                    .map(|name| format!("{name} is not finite"))
                    .or_else(|| {
                        divergence_cause(tr, e, self.divergence_position, self.divergence_tilt)
                    })
                    .map(|cause| Divergence {
                        time_s: t,
                        agent: i + 1,
                        cause,
                    });
            }
        }
        self.separation.record(
            t,
            in_cover,
            in_enclose,
            truths.iter().map(|tr| tr.state.position),
        );
        if in_cover {
            let pos = truths.iter().map(|tr| tr.state.position);
            self.coverage_sum += self.grid.covered_fraction([r.target[0], r.target[1]], pos);
            self.coverage_count += 1;
        }
        if first.is_some() {
            self.divergence = first.clone();
        }
        first
    }
}

fn norm(v: [f64; 3]) -> f64 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}

/// What [`Metrics::record`] has already derived for one agent at this step (written to the CSV too).
struct Derived {
    /// Formation error, m.
    error: f64,
    /// |attitude|, rad.
    attitude_norm: f64,
    /// The attitude constraint C-bar_i1 of this step, rad.
    c1_bar: f64,
    /// |body rate|, rad/s.
    rate_norm: f64,
}

/// 0.0 when every value of `vals` is finite, NaN otherwise: x - x is exactly 0 for a finite x and
/// NaN for +-inf and NaN, and NaN survives every sum.
#[inline(always)]
#[allow(clippy::eq_op)] // v - v is the probe: 0 for a finite v, NaN otherwise
fn nan_unless_finite<const N: usize>(vals: &[f64; N]) -> f64 {
    let mut z = 0.0;
    for v in vals {
        z += v - v;
    }
    z
}

/// The outputs checked for finiteness, as a list of (name, values); expands `$found` with the list
/// as an array of `(&'static str, &[f64])` once some value is not finite, and to `None` otherwise.
/// One list feeds both parts, so the check and the name it reports cannot drift apart.
macro_rules! first_non_finite {
    ($(($name:literal, $vals:expr)),* $(,)?) => {{
        // Branch-free check first: four independent sums (no long chain of dependent additions),
        // each NaN iff one of its values is not finite. The group indices are constants, so the
        // array below lives in registers.
        let mut acc = [0.0f64; 4];
        let mut g = 0usize;
        $(
            acc[g % 4] += nan_unless_finite($vals);
            g += 1;
        )*
        let _ = g;
        if ((acc[0] + acc[1]) + (acc[2] + acc[3])).is_nan() {
            let groups: &[(&'static str, &[f64])] = &[$(($name, &$vals[..])),*];
            groups
                .iter()
                .find(|(_, vals)| vals.iter().any(|v| !v.is_finite()))
                .map(|(name, _)| *name)
        } else {
            None
        }
    }};
}

/// The first output of agent `i` at this step that is not a finite number, if any: every value
/// `trajectory.csv` writes for it (state, reference, errors, commands, constraint bounds, barrier
/// values, faults, estimates) and the rest of the controller's telemetry but the barrier widths
/// C_i1, C_i2 (infinite by design in the `unconstrained` variant, Remark 4). A non-finite output is
/// a divergence: the run stops there, and `summary.json` says so.
fn non_finite_output(
    r: &ReferenceFrame,
    i: usize,
    tr: &PlantTruth,
    cmd: &ControlCommand,
    d: &Derived,
) -> Option<&'static str> {
    let (st, tm) = (&tr.state, &cmd.telemetry);
    let one = |v: f64| [v];
    let (error, thrust_cmd, thrust) = (one(d.error), one(cmd.thrust_n), one(tr.thrust_n));
    let (att_norm, c1_bar) = (one(d.attitude_norm), one(d.c1_bar));
    let (rate_norm, alpha_norm) = (one(d.rate_norm), one(norm(tm.alpha)));
    let (blf1, blf2) = (one(tm.blf1), one(tm.blf2));
    let (d_norm, d_hat) = (one(norm(tr.disturbance)), one(tm.d_hat));
    let (nn_norm, tau, model_dev) = (one(tm.nn_weight_norm), one(tm.tau_s), one(tm.model_hat_dev));
    first_non_finite![
        ("position", &st.position),
        ("velocity", &st.velocity),
        ("attitude", &st.attitude),
        ("body rate", &st.rate),
        ("reference position P_d", &r.p_d),
        ("formation offset", &r.offset[i]),
        ("target position", &r.target),
        ("formation error", &error),
        ("position control U_iP", &tm.u_p),
        ("thrust command", &thrust_cmd),
        ("applied thrust", &thrust),
        ("attitude command A_iC", &tm.attitude_cmd),
        ("raw attitude command", &tm.attitude_cmd_raw),
        ("virtual control alpha_i", &tm.alpha),
        ("attitude norm", &att_norm),
        ("attitude constraint C-bar_i1", &c1_bar),
        ("rate norm", &rate_norm),
        ("alpha norm", &alpha_norm),
        ("barrier value V_i1B (blf1)", &blf1),
        ("barrier value V_i2B (blf2)", &blf2),
        ("torque command U_iAC", &cmd.torque_nm),
        ("applied torque U_iA", &tr.torque_applied_nm),
        ("fault Gamma_i", &tr.gamma),
        ("estimate Gamma-hat_i", &tm.gamma_hat),
        ("fault delta_i", &tr.delta),
        ("estimate delta-hat_i", &tm.delta_hat),
        ("disturbance D_iA", &tr.disturbance),
        ("disturbance norm", &d_norm),
        ("estimate D-hat_iA", &d_hat),
        ("uncertainty F_iP", &tr.uncertainty),
        ("RBFNN output F-hat_iP", &tm.f_hat),
        ("RBFNN weight norm (nn_norm)", &nn_norm),
        ("delay tau_i", &tau),
        ("consensus error e_iP", &tm.e_p),
        ("consensus error e_iV", &tm.e_v),
        ("attitude error z_i1", &tm.z1),
        ("rate error z_i2", &tm.z2),
        ("auxiliary state E_i1", &tm.e1),
        ("auxiliary state E_i2", &tm.e2),
        ("estimate Delta F-hat_i", &model_dev),
    ]
}

/// The first quantity of one agent that left its bounds (tilt, formation error), if any.
fn divergence_cause(tr: &PlantTruth, e: f64, pos_bound: f64, tilt_bound: f64) -> Option<String> {
    let st = &tr.state;
    for (k, name) in [(0usize, "roll phi"), (1, "pitch theta")] {
        if st.attitude[k].abs() > tilt_bound {
            return Some(format!(
                "{name} = {:.3} rad beyond {tilt_bound} rad",
                st.attitude[k]
            ));
        }
    }
    if e > pos_bound {
        return Some(format!("formation error {e:.1} m beyond {pos_bound} m"));
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    fn one_step(tr: PlantTruth, cmd: ControlCommand) -> Option<Divergence> {
        let s = Scenario::paper();
        let mut m = Metrics::new(&s);
        let n = s.n_agents();
        let mut truths = vec![PlantTruth::default(); n];
        let mut commands = vec![ControlCommand::default(); n];
        truths[2] = tr;
        commands[2] = cmd;
        let r = ReferenceFrame::default();
        m.record(0, &r, &truths, &commands)
    }

    #[test]
    fn finite_outputs_within_bounds_are_no_divergence() {
        assert_eq!(
            one_step(PlantTruth::default(), ControlCommand::default()),
            None
        );
    }

    #[test]
    fn a_non_finite_barrier_value_is_a_divergence_naming_it() {
        let mut cmd = ControlCommand::default();
        cmd.telemetry.blf1 = f64::NAN;
        let d = one_step(PlantTruth::default(), cmd).expect("NaN in blf1 is a divergence");
        assert_eq!(d.agent, 3);
        assert!(
            d.cause.contains("blf1") && d.cause.contains("not finite"),
            "{}",
            d.cause
        );
    }

    #[test]
    fn an_infinite_estimate_is_a_divergence_naming_it() {
        let mut cmd = ControlCommand::default();
        cmd.telemetry.nn_weight_norm = f64::INFINITY;
        let d = one_step(PlantTruth::default(), cmd).expect("inf in nn_norm is a divergence");
        assert!(d.cause.contains("nn_norm"), "{}", d.cause);
        let mut cmd = ControlCommand::default();
        cmd.telemetry.e2[1] = f64::NEG_INFINITY;
        assert!(one_step(PlantTruth::default(), cmd).is_some());
    }

    #[test]
    fn a_non_finite_plant_quantity_or_an_overflowing_norm_is_a_divergence() {
        let mut tr = PlantTruth::default();
        tr.uncertainty[0] = f64::NAN;
        let d = one_step(tr, ControlCommand::default()).expect("NaN uncertainty");
        assert!(d.cause.contains("uncertainty"), "{}", d.cause);
        // Every component finite, the norm written to the CSV is not.
        let tr = PlantTruth {
            disturbance: [1e200, 0.0, 0.0],
            ..PlantTruth::default()
        };
        let d = one_step(tr, ControlCommand::default()).expect("overflowing norm");
        assert!(d.cause.contains("disturbance norm"), "{}", d.cause);
    }
}
