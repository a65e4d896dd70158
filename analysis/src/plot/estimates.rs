//! Figs. 12-14: adaptive estimates against the true values (disturbance bound, multiplicative and
//! additive actuator faults).

use super::style::{
    agent_color, draw_panel, titled, Area, Backend, DrawResult, Legend, Line, Panel,
};
use super::Figure;
use formation_runtime::record::csv::Column;
use plotters::prelude::*;

/// Fig. 12: D̂_iA against ‖D_iA‖ (solid: estimate, dashed: true), all agents.
pub fn disturbance<DB: Backend>(fig: &Figure, root: &Area<DB>) -> DrawResult {
    let area = titled(
        root,
        &format!(
            "Fig. 12 — disturbance bound estimate D_hat (solid) vs ‖D_iA‖ (dashed) ({})",
            fig.run.title()
        ),
    )?;
    let mut lines = Vec::new();
    for a in &fig.run.agents {
        let c = agent_color(a.id);
        lines.push(Line::new(
            format!("quadrotor {}", a.id),
            c,
            a.series(Column::DHat),
        ));
        lines.push(
            Line::new("", c, a.series(Column::DNorm))
                .dashed()
                .width(1)
                .unlabelled(),
        );
    }
    lines.push(true_value_key());
    draw_panel(
        &area,
        Panel {
            title: String::new(),
            x_desc: "t (s)",
            y_desc: "D_hat, ‖D_iA‖ (N m)".to_string(),
            lines,
            markers: &fig.geometry.phases,
            legend: Legend::Side,
            y_range: None,
            x_range: None,
        },
    )?;
    Ok(())
}

/// Fig. 13: Γ̂_i against Γ_i per channel.
pub fn gamma<DB: Backend>(fig: &Figure, root: &Area<DB>) -> DrawResult {
    per_channel(
        fig,
        root,
        "Fig. 13 — multiplicative fault Γ: estimate (solid) vs true (dashed)",
        [Column::GammaX, Column::GammaY, Column::GammaZ],
        [Column::GammaHatX, Column::GammaHatY, Column::GammaHatZ],
        "Γ",
        "",
    )
}

/// Fig. 14: δ̂_i against δ_i per channel.
pub fn delta<DB: Backend>(fig: &Figure, root: &Area<DB>) -> DrawResult {
    per_channel(
        fig,
        root,
        "Fig. 14 — additive fault δ: estimate (solid) vs true (dashed)",
        [Column::DeltaX, Column::DeltaY, Column::DeltaZ],
        [Column::DeltaHatX, Column::DeltaHatY, Column::DeltaHatZ],
        "δ",
        " (N m)",
    )
}

fn per_channel<DB: Backend>(
    fig: &Figure,
    root: &Area<DB>,
    title: &str,
    truth: [Column; 3],
    estimate: [Column; 3],
    sym: &str,
    unit: &str,
) -> DrawResult {
    let area = titled(root, &format!("{title} ({})", fig.run.title()))?;
    let cells = area.split_evenly((3, 1));
    for (row, (cell, axis)) in cells.iter().zip(["x", "y", "z"]).enumerate() {
        let mut lines = Vec::new();
        for a in &fig.run.agents {
            let c = agent_color(a.id);
            lines.push(Line::new(
                format!("quadrotor {}", a.id),
                c,
                a.series(estimate[row]),
            ));
            lines.push(
                Line::new("", c, a.series(truth[row]))
                    .dashed()
                    .width(1)
                    .unlabelled(),
            );
        }
        lines.push(true_value_key());
        draw_panel(
            cell,
            Panel {
                title: format!("channel {axis}"),
                x_desc: "t (s)",
                y_desc: format!("{sym}_{axis}{unit}"),
                lines,
                markers: &fig.geometry.phases,
                legend: if row == 0 {
                    Legend::Side
                } else {
                    Legend::Blank
                },
                y_range: None,
                x_range: None,
            },
        )?;
    }
    Ok(())
}

/// A legend-only entry explaining the dashed lines.
fn true_value_key() -> Line {
    Line::new("true (dashed)", RGBColor(90, 90, 90), Vec::new())
        .dashed()
        .width(2)
}
