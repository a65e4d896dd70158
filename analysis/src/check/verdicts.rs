//! One verdict per check, derived from the computed report.

use super::freq::Margin;
use super::inner::InnerLoop;
use super::verdict::{separation_level, Level, Verdict};
use super::Report;

/// Time-scale separation a cascade wants between a loop and the one around it.
const GOOD_SEPARATION: f64 = 3.0;
/// Phase margin considered comfortable, degrees.
const GOOD_MARGIN_DEG: f64 = 45.0;

/// OK above 45°, WARN between 0 and 45°, FAIL at or below 0 (or when the loop never crosses unity).
fn margin_verdict(check: &str, what: &str, m: Option<Margin>) -> Verdict {
    match m {
        None => Verdict::new(
            check,
            Level::Warn,
            format!("{what}: the loop gain never crosses 1 in [1e-3, 1e4] rad/s"),
        ),
        Some(m) => {
            let level = if m.phase_margin_deg >= GOOD_MARGIN_DEG {
                Level::Ok
            } else if m.phase_margin_deg > 0.0 {
                Level::Warn
            } else {
                Level::Fail
            };
            Verdict::new(
                check,
                level,
                format!(
                    "{what}: phase margin {:.1} deg at {:.2} rad/s (linear model)",
                    m.phase_margin_deg, m.crossover_rad_s
                ),
            )
        }
    }
}

/// What a sufficient condition of the paper that does not hold says: information (`INFO`), not a
/// prediction; the shipped gains fly although Theorem 1's conditions cannot be met (docs/tuning.md).
fn sufficient(holds: bool) -> Level {
    if holds {
        Level::Ok
    } else {
        Level::Info
    }
}

/// A verdict on a gain set the checked variant does not fly is information: its FAIL or WARN
/// becomes INFO, naming the gain set.
fn not_flown(mut v: Verdict, gain_set: &str) -> Verdict {
    if v.level != Level::Ok {
        v.level = Level::Info;
        v.why.push_str(&format!(
            " (the `{gain_set}` gain set, not flown by the checked variant)"
        ));
    }
    v
}

/// Every verdict of a report.
pub fn all(r: &Report) -> Vec<Verdict> {
    let mut v = Vec::new();
    graph_verdicts(r, &mut v);
    theorem1_verdicts(r, &mut v);
    outer_verdicts(r, &mut v);
    for il in &r.inner {
        let mut own = Vec::new();
        inner_verdicts(il, &mut own);
        if il.gain_set == r.gain_set {
            v.extend(own);
        } else {
            v.extend(own.into_iter().map(|x| not_flown(x, il.gain_set)));
        }
    }
    barrier_verdicts(r, &mut v);
    v
}

/// Lemma 1: L + B positive definite.
fn graph_verdicts(r: &Report, v: &mut Vec<Verdict>) {
    let g = &r.graph;
    v.push(if g.positive_definite {
        Verdict::new(
            "graph.positive_definite",
            Level::Ok,
            format!("lambda_min(L+B) = {:.4} > 0 (Lemma 1)", g.lambda_min),
        )
    } else {
        Verdict::new(
            "graph.positive_definite",
            Level::Fail,
            format!(
                "lambda_min(L+B) = {:.4} <= 0: Assumption 1 fails",
                g.lambda_min
            ),
        )
    });
}

/// Theorem 1: M positive definite, and the ties between the gains.
fn theorem1_verdicts(r: &Report, v: &mut Vec<Verdict>) {
    if let Some(t) = &r.theorem1 {
        let failing: Vec<&str> = t
            .necessary
            .iter()
            .filter(|c| !c.holds)
            .map(|c| c.name)
            .collect();
        v.push(if t.search.positive_definite {
            Verdict::new(
                "theorem1.m_positive_definite",
                Level::Ok,
                format!("M > 0 with M1 = {:.3e}, M2 = {:.3e}: min eigenvalue {:.3e}", t.search.m1, t.search.m2, t.search.best_min_eigenvalue),
            )
        } else {
            Verdict::new(
                "theorem1.m_positive_definite",
                sufficient(false),
                format!(
                    "a sufficient condition of Theorem 1 is not met: no (M1, M2) makes M > 0 (best min eigenvalue {:.3e}); failing necessary conditions: {}",
                    t.search.best_min_eigenvalue,
                    if failing.is_empty() { "none (coupling terms)".to_string() } else { failing.join(", ") }
                ),
            )
        });
        v.push(Verdict::new(
            "theorem1.ties",
            sufficient(t.ties.hold),
            format!(
                "K_P/K_V = {:.4} vs k_V/k_P = {:.4}; M2 from K_P tie {:.4e}, from K_V tie {:.4e}",
                t.ties.nn_ratio,
                t.ties.required_ratio,
                t.ties.m2_from_nn_k_p,
                t.ties.m2_from_nn_k_v
            ),
        ));
    }
}

/// The outer loop: damping and stiffness against the uncertainty, the leader's information, the
/// delay margin, the RBFNN's leakage.
fn outer_verdicts(r: &Report, v: &mut Vec<Verdict>) {
    let o = &r.outer;
    let u = &o.uncertainty;
    v.push(Verdict::new(
        "outer.slowest_mode_damping",
        if o.slowest_damping_rate > u.worst_velocity_gain { Level::Ok } else { Level::Warn },
        format!(
            "least damping lambda_min(k_V (L+B) + k_L P) = {:.3}/s vs uncertainty negative damping up to {:.3}/s (agent {} axis {}){}",
            o.slowest_damping_rate,
            u.worst_velocity_gain,
            u.worst_velocity_at[0],
            u.worst_velocity_at[1],
            match o.quadratic_break_even_speed_m_s {
                Some(vs) => format!("; V² axes exceed it above |V| = {vs:.3} m/s"),
                None => String::new(),
            }
        ),
    ));
    let info = &o.information;
    let fmt_kv = |k: Option<f64>| k.map_or("more than 1e3/s".to_string(), |k| format!("{k:.2}/s"));
    v.push(Verdict::new(
        "outer.leader_information",
        if info.window_exists {
            if o.slowest_damping_rate > u.worst_velocity_gain {
                Level::Ok
            } else {
                Level::Warn
            }
        } else {
            Level::Fail
        },
        format!(
            "leader data reaches {} of {} agents ({:?}); least damping lambda_min(k_V (L+B) + k_L P) needs k_V >= {} against the uncertainty; the cascade (delay, filter 1, attitude loop; linear) keeps the fastest mode's margin positive {}{}",
            info.agents_with_leader_data.len(),
            r.graph.eigenvalues.len(),
            info.leader_broadcast,
            fmt_kv(info.k_v_needed),
            info.k_v_delay_limit
                .map_or("for no k_V (k_P alone is too fast)".to_string(), |k| format!("up to k_V = {k:.2}/s")),
            if info.window_exists { "" } else { ": no k_V of (14) can give both on this graph" }
        ),
    ));
    v.push(Verdict::new(
        "outer.slowest_mode_stiffness",
        if o.slowest_stiffness > u.worst_position_gain { Level::Ok } else { Level::Warn },
        format!(
            "least stiffness lambda_min(k_P (L+B) + k_LP P) = {:.3}/s^2 vs uncertainty negative stiffness up to {:.3}/s^2 (agent {} axis {})",
            o.slowest_stiffness, u.worst_position_gain, u.worst_position_at[0], u.worst_position_at[1]
        ),
    ));
    let mut d = margin_verdict(
        "outer.delay_margin",
        "fastest mode with tau_M only",
        o.delay_only,
    );
    d.why.push_str(&format!(
        "; tau_M costs {:.1} deg at {:.2} rad/s",
        o.delay_phase_deg, o.fastest_mode_rad_s
    ));
    v.push(d);
    v.push(Verdict::new(
        "outer.rbfnn_leakage",
        if o.rbfnn.forgetting_rate < o.slowest_decay_rate {
            Level::Ok
        } else {
            Level::Warn
        },
        format!(
            "RBFNN forgets at kappa K_W = {:.3}/s vs slowest mode decay {:.3}/s{}",
            o.rbfnn.forgetting_rate,
            o.slowest_decay_rate,
            if o.rbfnn.forgetting_rate < o.slowest_decay_rate {
                ": it can integrate slow uncertainties"
            } else {
                ": it acts as a lagged P/D gain, not an integrator"
            }
        ),
    ));
}

/// The barrier: the acceleration and command rate the attitude constraints leave.
fn barrier_verdicts(r: &Report, v: &mut Vec<Verdict>) {
    let b = &r.barrier;
    v.push(Verdict::new(
        "barrier.acceleration",
        if b.command_accel_estimate_rad_s2 <= b.net_accel_authority_rad_s2 { Level::Ok } else { Level::Warn },
        format!(
            "command filter 1 can demand ~{:.1} rad/s^2 (R w_B; peak {:.1}) vs {:.2} rad/s^2 left after faults and disturbance",
            b.command_accel_estimate_rad_s2, b.command_accel_peak_rad_s2, b.net_accel_authority_rad_s2
        ),
    ));
    v.push(Verdict::new(
        "barrier.command_rate",
        if b.command_rate_limit_rad_s <= b.followable_rate_rad_s {
            Level::Ok
        } else {
            Level::Warn
        },
        format!(
            "command rate limit {:.3} rad/s vs {:.3} rad/s followable inside C_i1 = {} rad",
            b.command_rate_limit_rad_s, b.followable_rate_rad_s, b.attitude_margin_rad
        ),
    ));
}

fn inner_verdicts(il: &InnerLoop, v: &mut Vec<Verdict>) {
    let name = |c: &str| format!("inner.{}.{c}", il.gain_set);
    let ratio = |v: &mut Vec<Verdict>, c: &str, what: &str, r: f64| {
        v.push(Verdict::new(
            &name(c),
            separation_level(r, GOOD_SEPARATION),
            format!("{what} = {r:.2} (want >= {GOOD_SEPARATION}; < 1 means the inner loop is the slower one)"),
        ));
    };
    ratio(
        v,
        "attitude_over_outer",
        "attitude gain / fastest outer mode",
        il.attitude_over_fastest_outer,
    );
    ratio(
        v,
        "rate_over_attitude",
        "rate gain / attitude gain",
        il.rate_over_attitude,
    );
    // The rate filter feeds alpha to the rate loop: slower than the rate gain only blurs alpha' (WARN);
    // slower than the attitude gain puts its lag inside the attitude loop (can FAIL).
    let r = il.rate_filter_over_rate;
    v.push(Verdict::new(
        &name("rate_filter_over_rate"),
        if r >= GOOD_SEPARATION { Level::Ok } else { Level::Warn },
        format!("rate filter slowest pole / rate gain = {r:.2} (want >= {GOOD_SEPARATION}: alpha and alpha' lag alpha_C on the rate loop's time scale)"),
    ));
    ratio(
        v,
        "rate_filter_over_attitude",
        "rate filter slowest pole / attitude gain",
        il.rate_filter_over_attitude,
    );
    v.push(margin_verdict(
        &name("attitude_loop_margin"),
        "attitude loop through the rate filter",
        il.attitude_loop,
    ));
    v.push(margin_verdict(
        &name("cascade_margin"),
        "fastest mode through tau_M, command filter 1 and the attitude loop",
        il.cascade,
    ));
}
