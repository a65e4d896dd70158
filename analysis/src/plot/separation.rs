//! Separation figure: the distance between the closest two quadrotors over time, against the
//! scenario's safety distance, with the pair and time of the closest approach, and when the
//! separation layer acted (D25; the CSV's output rate; `summary.json` has the per-step minimum).

use super::style::{draw_panel, titled, Area, Backend, DrawResult, Legend, Line, Panel};
use super::{Figure, Run};
use formation_runtime::record::csv::Column;
use formation_runtime::record::separation::closest_pair;
use plotters::prelude::*;

/// (t, closest distance, pair (0-based)) at every output instant the agents share.
pub fn closest_series(run: &Run) -> Vec<(f64, f64, usize, usize)> {
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
            closest_pair(&pos).map(|(d, i, j)| (first.t()[k], d, i, j))
        })
        .collect()
}

/// The output instants at which some agent's separation layer changed its virtual control, as
/// intervals [start, end] (s) of consecutive instants.
pub fn layer_intervals(run: &Run) -> Vec<(f64, f64)> {
    let Some(first) = run.agents.first() else {
        return Vec::new();
    };
    let len = run.agents.iter().map(|a| a.t().len()).min().unwrap_or(0);
    let acting = |k: usize| {
        run.agents.iter().any(|a| {
            [Column::SepUx, Column::SepUy, Column::SepUz]
                .iter()
                .any(|c| a.col(*c)[k] != 0.0)
        })
    };
    let mut out: Vec<(f64, f64)> = Vec::new();
    let mut open: Option<f64> = None;
    for k in 0..len {
        let t = first.t()[k];
        match (acting(k), open) {
            (true, None) => open = Some(t),
            (false, Some(s)) => {
                out.push((s, first.t()[k - 1]));
                open = None;
            }
            _ => {}
        }
    }
    if let Some(s) = open {
        out.push((s, first.t()[len - 1]));
    }
    out
}

/// Distance between the closest two quadrotors with the safety distance (dashed).
pub fn separation<DB: Backend>(fig: &Figure, root: &Area<DB>) -> DrawResult {
    let closest = closest_series(fig.run);
    let series: Vec<(f64, f64)> = closest.iter().map(|c| (c.0, c.1)).collect();
    let (t0, t1) = fig.run.time_span();
    let safety = fig.geometry.safety_distance_m;
    let top = series.iter().map(|p| p.1).fold(safety, f64::max) * 1.1;
    let closest_at = match closest.iter().min_by(|a, b| a.1.total_cmp(&b.1)) {
        Some(&(t, d, i, j)) => format!(
            ": min {d:.3} m, agents {} and {} at {t:.1} s",
            fig.run.agents[i].id, fig.run.agents[j].id
        ),
        None => String::new(),
    };
    let area = titled(
        root,
        &format!(
            "Separation — the closest two quadrotors{closest_at} ({})",
            fig.run.title()
        ),
    )?;
    let mut lines = vec![
        Line::new("closest pair", BLUE, series),
        Line::new(
            format!("safety {safety} m"),
            RED,
            vec![(t0, safety), (t1, safety)],
        )
        .dashed(),
    ];
    // When the separation layer acts: a band along the bottom of the panel.
    let band = 0.04 * top;
    for (n, (a, b)) in layer_intervals(fig.run).into_iter().enumerate() {
        let line = Line::new(
            "layer acting",
            RGBColor(230, 120, 0),
            vec![(a, band), (b.max(a + 0.05), band)],
        )
        .width(6);
        lines.push(if n == 0 { line } else { line.unlabelled() });
    }
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
