//! Figs. 8-10: attitude tracking and the attitude / angular-rate constraints.

use super::style::{
    agent_color, draw_panel, titled, Area, Backend, DrawResult, Legend, Line, Panel, REFERENCE,
};
use super::Figure;
use formation_runtime::record::csv::Column;
use plotters::prelude::*;

/// Colour of constraint bounds (black: distinct from every agent colour).
const BOUND: RGBColor = RGBColor(0, 0, 0);
/// Colour of the commanded / virtual-control norms.
const COMMAND: RGBColor = RGBColor(110, 110, 110);
/// Colour of the compared run's trace.
const OTHER: RGBColor = RGBColor(150, 150, 150);

/// Fig. 8: roll and pitch of each agent against the filtered commands.
pub fn attitude<DB: Backend>(fig: &Figure, root: &Area<DB>) -> DrawResult {
    let area = titled(
        root,
        &format!(
            "Fig. 8 — attitude (solid) vs filtered command (dashed) ({})",
            fig.run.title()
        ),
    )?;
    let n = fig.run.agents.len();
    let cells = area.split_evenly((n, 2));
    for (i, a) in fig.run.agents.iter().enumerate() {
        let color = agent_color(a.id);
        for (c, (name, commanded, sym)) in [
            (Column::Phi, Column::PhiC, "φ"),
            (Column::Theta, Column::ThetaC, "θ"),
        ]
        .iter()
        .enumerate()
        {
            draw_panel(
                &cells[2 * i + c],
                Panel {
                    title: format!("quadrotor {} — {sym}", a.id),
                    x_desc: "t (s)",
                    y_desc: format!("{sym} (rad)"),
                    lines: vec![
                        Line::new(format!("{sym}_{}", a.id), color, a.series(*name)),
                        Line::new(format!("{sym}_{}C", a.id), REFERENCE, a.series(*commanded))
                            .dashed()
                            .width(1),
                    ],
                    markers: &fig.geometry.phases,
                    legend: Legend::Side,
                    y_range: None,
                    x_range: None,
                },
            )?;
        }
    }
    Ok(())
}

/// Fig. 9: ‖A_i‖ and ‖A_iC‖ against the constraint C̄_i1, one panel per agent; with `--compare`,
/// the compared run's ‖A_i‖ as well (the paper compares an unconstrained AFTAC).
pub fn attitude_constraint<DB: Backend>(fig: &Figure, root: &Area<DB>) -> DrawResult {
    constraint_figure(
        fig,
        root,
        Constraint {
            title: "Fig. 9 — attitude norm ‖A_i‖ and constraint C1_bar",
            state: (Column::AttNorm, "‖A_i‖"),
            command: (Column::AttCmdNorm, "‖A_iC‖"),
            bound: (Column::C1Bar, "C1_bar"),
            unit: "rad",
            with_compare: true,
        },
    )
}

/// Fig. 10: ‖Ω_i‖ and ‖α_i‖ against the constraint C̄_i2, one panel per agent.
pub fn rate_constraint<DB: Backend>(fig: &Figure, root: &Area<DB>) -> DrawResult {
    constraint_figure(
        fig,
        root,
        Constraint {
            title: "Fig. 10 — angular-rate norm ‖Ω_i‖, virtual control ‖α_i‖ and constraint C2_bar",
            state: (Column::RateNorm, "‖Ω_i‖"),
            command: (Column::AlphaNorm, "‖α_i‖"),
            bound: (Column::C2Bar, "C2_bar"),
            unit: "rad/s",
            with_compare: false,
        },
    )
}

/// What a constraint figure draws: each pair is (CSV column, legend label).
struct Constraint<'a> {
    /// The figure's title (the run's title follows it).
    title: &'a str,
    /// The constrained norm.
    state: (Column, &'a str),
    /// Its command (dashed).
    command: (Column, &'a str),
    /// The constraint.
    bound: (Column, &'a str),
    /// The unit of the norms.
    unit: &'a str,
    /// Whether the `--compare` run's norm is drawn as well.
    with_compare: bool,
}

fn constraint_figure<DB: Backend>(fig: &Figure, root: &Area<DB>, c: Constraint) -> DrawResult {
    let Constraint {
        title,
        state,
        command,
        bound,
        unit,
        with_compare,
    } = c;
    let area = titled(root, &format!("{title} ({})", fig.run.title()))?;
    let cells = area.split_evenly((fig.run.agents.len(), 1));
    for (cell, a) in cells.iter().zip(&fig.run.agents) {
        let mut lines = vec![
            Line::new(bound.1, BOUND, a.series(bound.0)).width(3),
            Line::new(command.1, COMMAND, a.series(command.0))
                .dashed()
                .width(2),
            Line::new(state.1, agent_color(a.id), a.series(state.0)),
        ];
        let compare = fig.compare.filter(|_| with_compare);
        if let Some(other) = compare.and_then(|r| r.agents.iter().find(|b| b.id == a.id)) {
            let label = format!(
                "{} ({})",
                state.1,
                compare.map(|r| r.label()).unwrap_or_default()
            );
            lines.insert(0, Line::new(label, OTHER, other.series(state.0)).width(1));
        }
        draw_panel(
            cell,
            Panel {
                title: format!("quadrotor {}", a.id),
                x_desc: "t (s)",
                y_desc: format!("norm ({unit})"),
                lines,
                markers: &fig.geometry.phases,
                legend: Legend::Side,
                y_range: None,
                x_range: None,
            },
        )?;
    }
    Ok(())
}
