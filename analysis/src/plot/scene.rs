//! The `scene` figure (feature `foxglove`): the live view's 3D scene at chosen times, seen from
//! above. The run's rows (`trajectory.csv`, `scenario.toml`, the injections of `events.jsonl`)
//! are fed to the same [`SceneBuilder`] as the live view and `run.mcap`, scene frame after scene
//! frame, and the SceneUpdate messages of the chosen frames are drawn as they are
//! (`formation_viz::topview`): what the figure shows is what Foxglove's 3D panel gets.

use super::style::{draw_xy_mesh, titled, Area, Backend, DrawResult, FONT};
use super::PlotError;
use formation_config::protocol::wire::ReferenceFrame;
use formation_config::Scenario;
use formation_runtime::record::csv::Column;
use formation_viz::topview::{shapes, Shape};
use formation_viz::{AgentSample, Frame, Scene, SceneBuilder};
use plotters::prelude::*;
use std::collections::BTreeMap;
use std::path::Path;

/// Default times of the figure, s: covering (t = 30 s) and enclosing (t = 55 s) of the paper run.
pub const DEFAULT_TIMES_S: [f64; 2] = [30.0, 55.0];

/// The scenes of a run at the chosen times.
pub struct Scenes {
    /// (time asked for, the scene of the first scene frame at or after it).
    pub at: Vec<(f64, Scene)>,
}

/// The `trajectory.csv` columns a scene is built from.
const SCENE_COLUMNS: &[Column] = &[
    Column::Step,
    Column::T,
    Column::Agent,
    Column::Px,
    Column::Py,
    Column::Pz,
    Column::Phi,
    Column::Theta,
    Column::Psi,
    Column::Pdx,
    Column::Pdy,
    Column::Pdz,
    Column::ENorm,
    Column::Tx,
    Column::Ty,
    Column::AttNorm,
    Column::C1Bar,
    Column::RateNorm,
    Column::C2Bar,
    Column::GammaX,
    Column::GammaY,
    Column::GammaZ,
    Column::GammaHatX,
    Column::GammaHatY,
    Column::GammaHatZ,
    Column::DeltaX,
    Column::DeltaY,
    Column::DeltaZ,
    Column::DeltaHatX,
    Column::DeltaHatY,
    Column::DeltaHatZ,
    Column::Tau,
];

fn columns(header: &str) -> BTreeMap<&str, usize> {
    header.split(',').enumerate().map(|(i, c)| (c, i)).collect()
}

/// The scenes of the run in `dir` at `times` (each moved inside the run; scene frames only).
pub fn load(dir: &Path, times: &[f64]) -> Result<Scenes, PlotError> {
    let input = |what: &str, e: &dyn std::fmt::Display| {
        PlotError::Input(format!("{}: {what}: {e}", dir.display()))
    };
    let s = Scenario::load(&dir.join("scenario.toml").to_string_lossy())
        .map_err(|e| input("scenario.toml", &e))?;
    let text = std::fs::read_to_string(dir.join("trajectory.csv"))
        .map_err(|e| input("trajectory.csv", &e))?;
    let mut lines = text.lines();
    let col = columns(lines.next().unwrap_or_default());
    if let Some(missing) = SCENE_COLUMNS.iter().find(|c| !col.contains_key(c.name())) {
        let missing = missing.name();
        return Err(input("trajectory.csv", &format!("no column '{missing}'")));
    }
    let mut builder = SceneBuilder::for_scenario(&s);
    if let Ok(events) = std::fs::read_to_string(dir.join("events.jsonl")) {
        for line in events.lines() {
            let v: serde_json::Value = serde_json::from_str(line).unwrap_or_default();
            if let Some(e) = formation_runtime::record::live::scenario_event(&v) {
                builder.add_event(&e);
            }
        }
    }
    let mission = formation_leader::Mission::from_scenario(&s);
    let n = s.n_agents();
    let dt = s.simulation.dt_s;
    let mut wanted: Vec<(f64, u64)> = times
        .iter()
        .map(|&t| (t, (t / dt).round().max(0.0) as u64))
        .collect();
    let last_step = s.n_steps().saturating_sub(1);
    for w in &mut wanted {
        w.1 = w.1.min(last_step - last_step % builder.config().decimation);
    }
    let mut out: Vec<(f64, Scene)> = Vec::new();
    let mut last: Option<Scene> = None;
    let mut rows: Vec<Vec<f64>> = Vec::with_capacity(n);
    let mut reference = ReferenceFrame::default();
    for line in lines {
        let row: Vec<f64> = line
            .split(',')
            .map(|v| v.parse().unwrap_or(f64::NAN))
            .collect();
        let step = row[col[Column::Step.name()]] as u64;
        if !builder.is_frame(step) {
            continue;
        }
        rows.push(row);
        if rows.len() < n {
            continue;
        }
        let get = |r: &Vec<f64>, c: Column| r[col[c.name()]];
        let v3 = |r: &Vec<f64>, a: Column, b: Column, c: Column| [get(r, a), get(r, b), get(r, c)];
        let t = get(&rows[0], Column::T);
        mission.reference(step, step as f64 * dt, &mut reference);
        let frame = Frame {
            step,
            t,
            p_d: reference.p_d,
            target: [get(&rows[0], Column::Tx), get(&rows[0], Column::Ty), 0.0],
            slots: rows
                .iter()
                .map(|r| v3(r, Column::Pdx, Column::Pdy, Column::Pdz))
                .collect(),
            agents: rows
                .iter()
                .map(|r| AgentSample {
                    position: v3(r, Column::Px, Column::Py, Column::Pz),
                    attitude: v3(r, Column::Phi, Column::Theta, Column::Psi),
                    formation_error_m: get(r, Column::ENorm),
                    gamma_hat: v3(r, Column::GammaHatX, Column::GammaHatY, Column::GammaHatZ),
                    delta_hat: v3(r, Column::DeltaHatX, Column::DeltaHatY, Column::DeltaHatZ),
                    gamma: v3(r, Column::GammaX, Column::GammaY, Column::GammaZ),
                    delta: v3(r, Column::DeltaX, Column::DeltaY, Column::DeltaZ),
                    attitude_margin_rad: get(r, Column::C1Bar) - get(r, Column::AttNorm),
                    rate_margin_rad_s: get(r, Column::C2Bar) - get(r, Column::RateNorm),
                    tau_s: get(r, Column::Tau),
                })
                .collect(),
        };
        rows.clear();
        let scene = builder.build(&frame);
        for &(t_asked, k) in &wanted {
            if k <= step && !out.iter().any(|(ta, _)| *ta == t_asked) {
                out.push((t_asked, scene.clone()));
            }
        }
        if out.len() == wanted.len() {
            break;
        }
        last = Some(scene);
    }
    // A run that ended early (diverged, interrupted): its last scene frame stands for the times
    // it did not reach.
    for &(t_asked, _) in &wanted {
        if !out.iter().any(|(ta, _)| *ta == t_asked) {
            if let Some(scene) = &last {
                out.push((t_asked, scene.clone()));
            }
        }
    }
    if out.is_empty() {
        return Err(input("trajectory.csv", &"no scene frame in the file"));
    }
    Ok(Scenes { at: out })
}

fn rgba(c: &formation_viz::topview::Rgba) -> RGBAColor {
    let u = |v: f64| (v.clamp(0.0, 1.0) * 255.0).round() as u8;
    RGBAColor(u(c.r), u(c.g), u(c.b), c.a.clamp(0.0, 1.0))
}

/// The square region a panel shows: the quadrotors, their slots and footprints, the target's
/// disk, with a margin.
fn extent(all: &[Shape]) -> ((f64, f64), f64) {
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for s in all {
        if let Shape::Polygon { points, .. } = s {
            for p in points {
                x0 = x0.min(p[0]);
                x1 = x1.max(p[0]);
                y0 = y0.min(p[1]);
                y1 = y1.max(p[1]);
            }
        }
    }
    let half = 0.55 * (x1 - x0).max(y1 - y0).max(1.0);
    (((x0 + x1) / 2.0, (y0 + y1) / 2.0), half)
}

/// Draws the figure: one top-view panel per chosen time, and the key.
pub fn draw<DB: Backend>(scenes: &Scenes, title: &str, root: &Area<DB>) -> DrawResult {
    let area = titled(
        root,
        &format!("Scene of the live view seen from above — the 3D panel's messages ({title})"),
    )?;
    let (_, h) = area.dim_in_pixel();
    let (body, key) = area.split_vertically(h.saturating_sub(70));
    let panels = body.split_evenly((1, scenes.at.len().max(1)));
    for ((t_asked, scene), panel) in scenes.at.iter().zip(&panels) {
        let all = shapes(scene);
        let (c, half) = extent(&all);
        let t = scene.plots.first().map_or(*t_asked, |p| p.t);
        let panel = panel.titled(&format!("t = {t:.2} s (step {})", scene.step), (FONT, 20))?;
        let mut chart = ChartBuilder::on(&panel)
            .margin(12)
            .x_label_area_size(44)
            .y_label_area_size(60)
            .build_cartesian_2d(c.0 - half..c.0 + half, c.1 - half..c.1 + half)?;
        draw_xy_mesh(&mut chart)?;
        let plot_w = chart.plotting_area().dim_in_pixel().0 as f64;
        let px_per_m = plot_w / (2.0 * half);
        for s in &all {
            match s {
                Shape::Polygon { points, color } => {
                    let pts: Vec<(f64, f64)> = points.iter().map(|p| (p[0], p[1])).collect();
                    chart.draw_series(std::iter::once(Polygon::new(pts, rgba(color).filled())))?;
                }
                Shape::Polyline {
                    points,
                    color,
                    width_m,
                } => {
                    let pts: Vec<(f64, f64)> = points.iter().map(|p| (p[0], p[1])).collect();
                    let width = (width_m * px_per_m).round().clamp(1.0, 6.0) as u32;
                    chart.draw_series(std::iter::once(PathElement::new(
                        pts,
                        rgba(color).stroke_width(width),
                    )))?;
                }
                Shape::Text {
                    at,
                    text,
                    color,
                    size_m,
                } => {
                    let size = (size_m * px_per_m).clamp(12.0, 22.0);
                    let style = (FONT, size).into_font().color(&rgba(color));
                    chart.draw_series(std::iter::once(Text::new(
                        text.clone(),
                        (at[0], at[1]),
                        style,
                    )))?;
                }
            }
        }
    }
    key.draw_text(
        "quadrotors: arms, rotors and heading arrow from /tf; trail: last 3 s; thin line: to its slot (faint dot); \
         faint disks: camera footprints; grey disk: target area; black dot: virtual leader P_d",
        &(FONT, 16).into_font().color(&RGBColor(60, 60, 60)),
        (20, 8),
    )?;
    key.draw_text(
        "graph links: green up, amber stale (an end down or messages lost), red down; grey: leader links; \
         red halo and label: an event of the last 4 s; grey quadrotor: its process is down",
        &(FONT, 16).into_font().color(&RGBColor(60, 60, 60)),
        (20, 34),
    )?;
    Ok(())
}

/// Whether `dir` holds what the figure needs (`scenario.toml` and `trajectory.csv`).
pub fn available(dir: &Path) -> bool {
    dir.join("scenario.toml").is_file() && dir.join("trajectory.csv").is_file()
}
