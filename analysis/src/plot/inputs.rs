//! Fig. 11: control inputs applied to the quadrotors (torques after faults and saturation, thrust).

use super::style::{
    agent_color, draw_panel, titled, Area, Backend, DrawResult, Legend, Line, Panel,
};
use super::Figure;
use formation_runtime::record::csv::Column;

/// Fig. 11: applied torques U_iA (x, y, z) and total thrust, all agents.
pub fn inputs<DB: Backend>(fig: &Figure, root: &Area<DB>) -> DrawResult {
    let area = titled(
        root,
        &format!(
            "Fig. 11 — applied inputs U_iA (after faults and saturation) and thrust ({})",
            fig.run.title()
        ),
    )?;
    let rows = [
        (Column::UAX, "roll torque U_A,x", "U_A,x (N m)"),
        (Column::UAY, "pitch torque U_A,y", "U_A,y (N m)"),
        (Column::UAZ, "yaw torque U_A,z", "U_A,z (N m)"),
        (Column::Thrust, "total thrust T", "T (N)"),
    ];
    let cells = area.split_evenly((rows.len(), 1));
    for (row, (cell, (col, title, y))) in cells.iter().zip(rows).enumerate() {
        let lines = fig
            .run
            .agents
            .iter()
            .map(|a| {
                Line::new(
                    format!("quadrotor {}", a.id),
                    agent_color(a.id),
                    a.series(col),
                )
                .width(1)
            })
            .collect();
        draw_panel(
            cell,
            Panel {
                title: title.to_string(),
                x_desc: "t (s)",
                y_desc: y.to_string(),
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
