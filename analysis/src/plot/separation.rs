//! Separation figure: the distance between the closest two quadrotors over time, against the
//! scenario's safety distance (the CSV's output rate; `summary.json` has the per-step minimum).

use super::style::{draw_panel, titled, Area, Backend, DrawResult, Legend, Line, Panel};
use super::{Figure, Run};
use formation_runtime::record::csv::Column;
use formation_runtime::record::separation::closest_pair;
use plotters::prelude::*;

/// (t, closest distance) at every output instant the agents share.
pub fn min_distance_series(run: &Run) -> Vec<(f64, f64)> {
    let Some(first) = run.agents.first() else {
        return Vec::new();
    };
    let len = run.agents.iter().map(|a| a.t().len()).min().unwrap_or(0);
    let cols: Vec<[&[f64]; 3]> = run
        .agents
        .iter()
        .map(|a| [a.col(Column::Px), a.col(Column::Py), a.col(Column::Pz)])
        .collect();
    let mut pos = Vec::with_capacity(cols.len());
    (0..len)
        .filter_map(|k| {
            pos.clear();
            pos.extend(cols.iter().map(|c| [c[0][k], c[1][k], c[2][k]]));
            closest_pair(&pos).map(|(d, _, _)| (first.t()[k], d))
        })
        .collect()
}

/// Distance between the closest two quadrotors with the safety distance (dashed).
pub fn separation<DB: Backend>(fig: &Figure, root: &Area<DB>) -> DrawResult {
    let area = titled(
        root,
        &format!(
            "Separation — distance between the closest two quadrotors ({})",
            fig.run.title()
        ),
    )?;
    let series = min_distance_series(fig.run);
    let (t0, t1) = fig.run.time_span();
    let safety = fig.geometry.safety_distance_m;
    let top = series.iter().map(|p| p.1).fold(safety, f64::max) * 1.1;
    let lines = vec![
        Line::new("closest pair", BLUE, series),
        Line::new(
            format!("safety {safety} m"),
            RED,
            vec![(t0, safety), (t1, safety)],
        )
        .dashed(),
    ];
    draw_panel(
        &area,
        Panel {
            title: String::new(),
            x_desc: "t (s)",
            y_desc: "min_ij ‖P_i − P_j‖ (m)".to_string(),
            lines,
            markers: &fig.geometry.phases,
            legend: Legend::Side,
            y_range: Some((0.0, top)),
            x_range: None,
        },
    )?;
    Ok(())
}
