//! Figs. 6 and 7: formation errors (optionally two variants side by side) and RBFNN approximation error.

use super::style::{
    agent_color, draw_panel, lines_y_range, titled, Area, Backend, DrawResult, Legend, Line, Panel,
};
use super::{Figure, Run};
use formation_runtime::record::csv::Column;

const AXES: [&str; 3] = ["x", "y", "z"];
/// The formation error e per axis of [`AXES`].
const ERRORS: [Column; 3] = [Column::Ex, Column::Ey, Column::Ez];
/// F per axis of [`AXES`].
const F: [Column; 3] = [Column::FX, Column::FY, Column::FZ];
/// F-hat per axis of [`AXES`].
const F_HAT: [Column; 3] = [Column::FHatX, Column::FHatY, Column::FHatZ];

/// Lines of one column of one run, one per agent.
fn per_agent(run: &Run, f: impl Fn(&super::data::AgentTrace) -> Vec<(f64, f64)>) -> Vec<Line> {
    run.agents
        .iter()
        .map(|a| Line::new(format!("quadrotor {}", a.id), agent_color(a.id), f(a)))
        .collect()
}

/// Fig. 6: formation error components per agent; with `--compare`, both variants side by side on
/// the same scales.
pub fn position_errors<DB: Backend>(fig: &Figure, root: &Area<DB>) -> DrawResult {
    let runs: Vec<&Run> = std::iter::once(fig.run).chain(fig.compare).collect();
    let title = if runs.len() == 2 {
        format!(
            "Fig. 6 — formation errors P_i − P_d − Δ_i0: {} (left) vs {} (right)",
            runs[0].label(),
            runs[1].label()
        )
    } else {
        format!(
            "Fig. 6 — formation errors P_i − P_d − Δ_i0 ({})",
            fig.run.title()
        )
    };
    let area = titled(root, &title)?;
    let cells = area.split_evenly((3, runs.len()));
    for (row, axis) in AXES.iter().enumerate() {
        let col = ERRORS[row];
        let lines: Vec<Vec<Line>> = runs
            .iter()
            .map(|r| per_agent(r, |a| a.series(col)))
            .collect();
        let y_range = lines_y_range(&lines.iter().flatten().collect::<Vec<_>>());
        for (c, (run, lines)) in runs.iter().zip(lines).enumerate() {
            draw_panel(
                &cells[row * runs.len() + c],
                Panel {
                    title: format!("e_{axis} — {}", run.label()),
                    x_desc: "t (s)",
                    y_desc: format!("e_{axis} (m)"),
                    lines,
                    markers: &fig.geometry.phases,
                    // Only the rightmost column carries the legend.
                    legend: if c + 1 < runs.len() {
                        Legend::None
                    } else if row == 0 {
                        Legend::Side
                    } else {
                        Legend::Blank
                    },
                    y_range: Some(y_range),
                    x_range: None,
                },
            )?;
        }
    }
    Ok(())
}

/// Fig. 7: RBFNN approximation error F_iP − F̂_iP on the three axes.
pub fn rbfnn_error<DB: Backend>(fig: &Figure, root: &Area<DB>) -> DrawResult {
    let area = titled(
        root,
        &format!(
            "Fig. 7 — RBFNN approximation error F − F_hat ({})",
            fig.run.title()
        ),
    )?;
    let cells = area.split_evenly((3, 1));
    for (row, axis) in AXES.iter().enumerate() {
        let lines = per_agent(fig.run, |a| {
            a.derived(&[F[row], F_HAT[row]], |r| r[0] - r[1])
        });
        draw_panel(
            &cells[row],
            Panel {
                title: format!("{axis} axis"),
                x_desc: "t (s)",
                y_desc: format!("F_{axis} − F_hat_{axis} (m/s²)"),
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

/// The formation error norm of every agent with the events of the timeline marked (crashes, hangs,
/// link faults, losses, detected deaths; docs/failures.md).
pub fn events<DB: Backend>(fig: &Figure, root: &Area<DB>) -> DrawResult {
    let area = titled(
        root,
        &format!(
            "Formation error ||P_i − P_d − Δ_i0|| with the events of the run ({})",
            fig.run.title()
        ),
    )?;
    draw_panel(
        &area,
        Panel {
            title: events_subtitle(fig.run),
            x_desc: "t (s)",
            y_desc: "||e_i|| (m)".to_string(),
            lines: per_agent(fig.run, error_norm),
            markers: &fig.run.events,
            legend: Legend::Side,
            y_range: None,
            x_range: None,
        },
    )
}

/// "dashed: crash 3 at 6.00 s, ...": the events of `run` that the dashed markers show.
fn events_subtitle(run: &Run) -> String {
    let events: Vec<String> = run
        .events
        .iter()
        .map(|(t, what)| format!("{what} at {t:.2} s"))
        .collect();
    format!("dashed: {}", events.join(", "))
}

/// The formation error norm ||e_i|| of one agent at each time row.
fn error_norm(a: &super::data::AgentTrace) -> Vec<(f64, f64)> {
    a.derived(&ERRORS, |r| {
        (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]).sqrt()
    })
}

/// Seconds shown before the first event in `events_compare`.
const COMPARE_BEFORE_S: f64 = 2.0;
/// Seconds shown after it.
const COMPARE_AFTER_S: f64 = 12.0;

/// The worst agent's formation error at each time row of `run`.
fn worst_error(run: &Run) -> Vec<(f64, f64)> {
    let per: Vec<Vec<(f64, f64)>> = run.agents.iter().map(error_norm).collect();
    let rows = per.iter().map(Vec::len).min().unwrap_or(0);
    (0..rows)
        .map(|k| (per[0][k].0, per.iter().map(|p| p[k].1).fold(0.0, f64::max)))
        .collect()
}

/// The worst agent's formation error of the run and of each `--events-compare` run, from 2 s
/// before the run's first event to 12 s after it; each line is named by its run's directory.
pub fn events_compare<DB: Backend>(fig: &Figure, root: &Area<DB>) -> DrawResult {
    let t0 = fig.run.events.first().map_or(0.0, |e| e.0);
    let window = (t0 - COMPARE_BEFORE_S, t0 + COMPARE_AFTER_S);
    let name = |r: &Run| {
        r.dir
            .file_name()
            .map_or_else(|| r.label(), |n| n.to_string_lossy().into_owned())
    };
    let lines = std::iter::once(fig.run)
        .chain(fig.others.iter())
        .enumerate()
        .map(|(k, r)| {
            let points = worst_error(r)
                .into_iter()
                .filter(|(t, _)| *t >= window.0 && *t <= window.1)
                .collect();
            Line::new(name(r), agent_color(k as u32 + 1), points)
        })
        .collect();
    let area = titled(
        root,
        &format!(
            "Worst formation error max_i ||P_i − P_d − Δ_i0|| around the first event ({})",
            fig.run.title()
        ),
    )?;
    draw_panel(
        &area,
        Panel {
            title: events_subtitle(fig.run),
            x_desc: "t (s)",
            y_desc: "max_i ||e_i|| (m)".to_string(),
            lines,
            markers: &fig.run.events,
            legend: Legend::Side,
            y_range: None,
            x_range: Some(window),
        },
    )
}
