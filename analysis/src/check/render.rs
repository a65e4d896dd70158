//! Text rendering of the check report.

use super::freq::{Margin, Pair};
use super::Report;
use std::fmt::Write;

fn root(r: &Pair) -> String {
    if r[1] == 0.0 {
        format!("{:.3}", r[0])
    } else {
        format!("{:.3}{:+.3}j", r[0], r[1])
    }
}

fn margin(m: &Option<Margin>) -> String {
    match m {
        Some(m) => format!(
            "{:.1} deg at {:.2} rad/s",
            m.phase_margin_deg, m.crossover_rad_s
        ),
        None => "no unity-gain crossover in [1e-3, 1e4] rad/s".to_string(),
    }
}

/// The report as text.
pub fn text(r: &Report) -> String {
    let mut o = String::new();
    let _ = write_all(r, &mut o);
    o
}

fn write_all(r: &Report, o: &mut String) -> std::fmt::Result {
    writeln!(o, "formation check: scenario '{}'", r.scenario)?;
    write_graph(r, o)?;
    write_theorem1(r, o)?;
    write_outer(r, o)?;
    write_inner(r, o)?;
    write_barrier(r, o)?;
    writeln!(o, "\n== Verdicts")?;
    for v in &r.verdicts {
        writeln!(o, "{:<4} {}: {}", v.level.label(), v.check, v.why)?;
    }
    writeln!(o, "worst: {}", r.worst.label())?;
    Ok(())
}

/// Section 1: the eigenvalues of L + B.
fn write_graph(r: &Report, o: &mut String) -> std::fmt::Result {
    writeln!(o, "\n== 1. Graph: L + B (Lemma 1, Assumption 1)")?;
    let ev: Vec<String> = r
        .graph
        .eigenvalues
        .iter()
        .map(|e| format!("{e:.4}"))
        .collect();
    writeln!(o, "eigenvalues (ascending): [{}]", ev.join(", "))?;
    writeln!(o, "positive definite: {}", r.graph.positive_definite)?;
    if let (Some(a), Some(b)) = (r.graph.sigma_max_g_inv, r.graph.sigma_min_b_inv) {
        writeln!(
            o,
            "sigma_max(G^-1) = {a:.4}, sigma_min(B^-1) = {b:.5}  (G = (L+B) x I3, B = G^T G)"
        )?;
    }
    Ok(())
}

/// Section 2: Theorem 1's matrix M.
fn write_theorem1(r: &Report, o: &mut String) -> std::fmt::Result {
    writeln!(o, "\n== 2. Theorem 1: matrix M of eq. (18)")?;
    match &r.theorem1 {
        None => writeln!(o, "skipped: L + B is not positive definite")?,
        Some(t) => {
            let i = &t.inputs;
            writeln!(
                o,
                "k_P = {}, k_V = {}, K_P = {}, K_V = {}, K_W = {}, tau_M = {} s, Psi_M = {:.4}",
                i.k_p, i.k_v, i.nn_k_p, i.nn_k_v, i.k_w, i.tau_m, i.psi_m
            )?;
            writeln!(o, "Psi_M bound: {}", t.psi_m_bound)?;
            writeln!(o, "reading: {}", t.reading)?;
            let s = &t.search;
            writeln!(
                o,
                "search over (M1, M2) in [{:.0e}, {:.0e}]^2 (log grid + pattern search):",
                s.range[0], s.range[1]
            )?;
            writeln!(
                o,
                "  best min eigenvalue {:.4e} at M1 = {:.4e}, M2 = {:.4e}{}",
                s.best_min_eigenvalue,
                s.m1,
                s.m2,
                if s.at_search_boundary {
                    " (at the edge of the range: a supremum)"
                } else {
                    ""
                }
            )?;
            let d: Vec<String> = s.diagonal.iter().map(|x| format!("{x:.3e}")).collect();
            writeln!(o, "  diagonal there: [{}]", d.join(", "))?;
            writeln!(
                o,
                "  M can be made positive definite: {}",
                s.positive_definite
            )?;
            writeln!(o, "necessary conditions (independent of M1, M2):")?;
            for c in &t.necessary {
                writeln!(
                    o,
                    "  [{}] {}: {} ({:.4e} vs {:.4e})",
                    if c.holds { "holds" } else { "FAILS" },
                    c.name,
                    c.condition,
                    c.lhs,
                    c.rhs
                )?;
            }
            let ti = &t.ties;
            writeln!(
                o,
                "ties K_P = 4 M2 tau_M^2 k_V, K_V = 4 M2 tau_M^2 k_P: K_P/K_V = {:.4}, k_V/k_P = {:.4}; M2 = {:.4e} vs {:.4e}; hold: {}",
                ti.nn_ratio, ti.required_ratio, ti.m2_from_nn_k_p, ti.m2_from_nn_k_v, ti.hold
            )?;
        }
    }
    Ok(())
}

/// Section 3, first part: the outer modes against the uncertainty, the delay and the RBFNN.
fn write_outer(r: &Report, o: &mut String) -> std::fmt::Result {
    writeln!(o, "\n== 3. Loop bandwidths (linearised, near hover)")?;
    let ou = &r.outer;
    writeln!(o, "outer modes s^2 + lambda k_V s + lambda k_P (no delay):")?;
    for m in &ou.modes {
        writeln!(
            o,
            "  lambda = {:.4}: roots {}, {}  (w_n = {:.3} rad/s, zeta = {:.3})",
            m.lambda,
            root(&m.roots[0]),
            root(&m.roots[1]),
            m.natural_frequency_rad_s,
            m.damping_ratio
        )?;
    }
    writeln!(
        o,
        "fastest outer mode: {:.3} rad/s; slowest decay rate: {:.3}/s",
        ou.fastest_mode_rad_s, ou.slowest_decay_rate
    )?;
    let u = &ou.uncertainty;
    writeln!(
        o,
        "slowest mode: lambda_min k_V + k_L = {:.3}/s vs uncertainty (61) |df/dV| up to {:.3}/s (agent {}, axis {}; velocity power 1)",
        ou.slowest_damping_rate, u.worst_velocity_gain, u.worst_velocity_at[0], u.worst_velocity_at[1]
    )?;
    if let Some(vs) = ou.quadratic_break_even_speed_m_s {
        writeln!(
            o,
            "  velocity power 2 axes: |df/dV| = 2|gain||V| depends on V (slope up to {:.3} per m/s, agent {}, axis {}); exceeds lambda_min k_V + k_L above |V| = {:.3} m/s",
            u.quadratic_slope_per_m_s, u.quadratic_at[0], u.quadratic_at[1], vs
        )?;
    }
    writeln!(
        o,
        "  lambda_min k_P + k_LP = {:.3}/s^2 vs |df/dP| up to {:.3}/s^2 (agent {}, axis {})",
        ou.slowest_stiffness, u.worst_position_gain, u.worst_position_at[0], u.worst_position_at[1]
    )?;
    writeln!(
        o,
        "delay: tau_M * w_fastest = {:.1} deg; fastest mode with delay only: {}",
        ou.delay_phase_deg,
        margin(&ou.delay_only)
    )?;
    writeln!(
        o,
        "RBFNN (15): forgets at kappa K_W = {:.4}/s; static gains up to l K_P/K_W = {:.3}, l K_V/K_W = {:.3}",
        ou.rbfnn.forgetting_rate, ou.rbfnn.static_p_gain_bound, ou.rbfnn.static_d_gain_bound
    )?;
    Ok(())
}

/// Section 3, second part: the command filters and the inner loops' margins.
fn write_inner(r: &Report, o: &mut String) -> std::fmt::Result {
    for (name, f) in [
        ("attitude command filter 1", &r.filters.attitude),
        ("rate command filter", &r.filters.rate),
    ] {
        writeln!(
            o,
            "{name}: w_B = {}, xi_B = {}: poles {}, {}{}; slowest {:.3} rad/s",
            f.natural_frequency_rad_s,
            f.damping,
            root(&f.poles[0]),
            root(&f.poles[1]),
            if f.complex {
                " (complex: natural frequency)"
            } else {
                ""
            },
            f.slowest_rad_s
        )?;
    }
    writeln!(o, "margins below: {}", r.cascade_model)?;
    for il in &r.inner {
        writeln!(o, "inner loops, {} gains: {}", il.gain_set, il.rule)?;
        writeln!(
            o,
            "  attitude gain {:.3}/s, rate gain {:.3}/s",
            il.attitude_gain, il.rate_gain
        )?;
        writeln!(
            o,
            "  ratios: attitude/fastest outer {:.3}, rate/attitude {:.3}, rate filter/rate {:.3}, rate filter/attitude {:.3}",
            il.attitude_over_fastest_outer, il.rate_over_attitude, il.rate_filter_over_rate, il.rate_filter_over_attitude
        )?;
        writeln!(
            o,
            "  attitude loop (through the rate filter): {}",
            margin(&il.attitude_loop)
        )?;
        writeln!(
            o,
            "  fastest outer mode through tau_M, filter 1 and attitude loop: {}",
            margin(&il.cascade)
        )?;
    }
    Ok(())
}

/// Section 4: the barrier's feasibility.
fn write_barrier(r: &Report, o: &mut String) -> std::fmt::Result {
    let b = &r.barrier;
    writeln!(o, "\n== 4. Barrier feasibility (roll/pitch)")?;
    writeln!(
        o,
        "torque left after the worst faults: {:.4} N m (agent {}, axis {}, t = {:.2} s) -> {:.3} rad/s^2",
        b.torque_authority_nm, b.authority_at[0], b.authority_at[1], b.authority_time_s, b.accel_authority_rad_s2
    )?;
    writeln!(
        o,
        "disturbance (62) up to {:.3} rad/s^2 -> net {:.3} rad/s^2",
        b.disturbance_bound_rad_s2, b.net_accel_authority_rad_s2
    )?;
    writeln!(
        o,
        "command filter 1: rate limit {:.3} rad/s, demand ~ R w_B = {:.1} rad/s^2 (peak 2 xi w_B R = {:.1})",
        b.command_rate_limit_rad_s, b.command_accel_estimate_rad_s2, b.command_accel_peak_rad_s2
    )?;
    writeln!(
        o,
        "followable command rate inside C_i1 = {} rad: min(C-bar_i2 = {:.3}, sqrt(2 a C_i1)) = {:.3} rad/s",
        b.attitude_margin_rad, b.rate_constraint_rad_s, b.followable_rate_rad_s
    )?;
    Ok(())
}
