//! Fig. 5: 3D trajectories, and the top view with the target disk and the sensor footprints.

use super::data::AgentTrace;
use super::style::{
    agent_color, clip_runs, draw_xy_mesh, emptiest_corner, fit_range, format_tick, stroke_pixels,
    thin, titled, Area, Backend, DrawResult, FONT, REFERENCE,
};
use super::Figure;
use formation_runtime::record::csv::Column;
use plotters::prelude::*;

/// Colour of the target disk (outline; the fill is a light tint). Distinct from every agent colour.
const DISK: RGBColor = RGBColor(20, 20, 20);
/// Length of the trail drawn before a snapshot, s.
const TRAIL_S: f64 = 5.0;

/// Fig. 5 (left): trajectories of all agents and the target's path in 3D.
pub fn trajectory_3d<DB: Backend>(fig: &Figure, root: &Area<DB>) -> DrawResult {
    let area = titled(
        root,
        &format!(
            "Fig. 5 — trajectories of the quadrotors and the target ({})",
            fig.run.title()
        ),
    )?;
    let run = fig.run;

    let xs = run
        .agents
        .iter()
        .flat_map(|a| a.col(Column::Px).iter().chain(a.col(Column::Tx)));
    let ys = run
        .agents
        .iter()
        .flat_map(|a| a.col(Column::Py).iter().chain(a.col(Column::Ty)));
    let (x0, x1) = fit_range(xs.copied(), 0.05);
    let (y0, y1) = fit_range(ys.copied(), 0.05);
    // Equal horizontal scales: both horizontal axes get the larger span.
    let half = (x1 - x0).max(y1 - y0) / 2.0;
    let (cx, cy) = ((x0 + x1) / 2.0, (y0 + y1) / 2.0);
    let (z0, z1) = fit_range(
        run.agents
            .iter()
            .flat_map(|a| a.col(Column::Pz).iter().copied()),
        0.05,
    );
    let (z0, z1) = (z0.min(0.0), z1.max(1.0));

    // plotters' 3D y axis is the vertical one: chart (x, y, z) = world (px, pz, py).
    let mut chart = ChartBuilder::on(&area).margin(30).build_cartesian_3d(
        cx - half..cx + half,
        z0..z1,
        cy - half..cy + half,
    )?;
    chart.with_projection(|mut pb| {
        pb.yaw = 0.6;
        pb.pitch = 0.35;
        pb.scale = 0.85;
        pb.into_matrix()
    });
    chart
        .configure_axes()
        .label_style((FONT, 14))
        .light_grid_style(RGBColor(230, 230, 230))
        .bold_grid_style(RGBColor(200, 200, 200))
        .max_light_lines(2)
        .x_formatter(&|v| format_tick(*v))
        .y_formatter(&|v| format_tick(*v))
        .z_formatter(&|v| format_tick(*v))
        .draw()?;

    // Paths are stroked segment by segment in pixels (no mitre spurs on the thick target path);
    // the legend entries come from empty series.
    let target = &run.agents[0];
    let target_pts: Vec<(f64, f64, f64)> = thin3(target, Column::Tx, Column::Ty, None);
    let pixels: Vec<(i32, i32)> = target_pts
        .iter()
        .map(|p| chart.as_coord_spec().translate(p))
        .collect();
    stroke_pixels(root, &pixels, REFERENCE.stroke_width(3))?;
    chart
        .draw_series(LineSeries::new(
            Vec::<(f64, f64, f64)>::new(),
            REFERENCE.stroke_width(3),
        ))?
        .label("target path T_g")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], REFERENCE.stroke_width(3)));
    for a in &run.agents {
        let color = agent_color(a.id);
        let pts = thin3(a, Column::Px, Column::Py, Some(Column::Pz));
        let pixels: Vec<(i32, i32)> = pts
            .iter()
            .map(|p| chart.as_coord_spec().translate(p))
            .collect();
        stroke_pixels(root, &pixels, color.stroke_width(2))?;
        if let Some(&start) = pts.first() {
            chart.draw_series(std::iter::once(Circle::new(start, 5, color.filled())))?;
        }
        if let Some(&end) = pts.last() {
            chart.draw_series(std::iter::once(TriangleMarker::new(end, 7, color.filled())))?;
        }
        chart
            .draw_series(LineSeries::new(
                Vec::<(f64, f64, f64)>::new(),
                color.stroke_width(2),
            ))?
            .label(format!("quadrotor {}", a.id))
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 24, y)], color.stroke_width(2))
            });
    }
    let px = |x: f64, h: f64, y: f64| chart.as_coord_spec().translate(&(x, h, y));
    draw_3d_axis_names(root, px, (cx, cy, half), (z0, z1))?;
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .label_font((FONT, 16))
        .background_style(WHITE.mix(0.85))
        .border_style(RGBColor(160, 160, 160))
        .draw()?;
    area.draw_text(
        "● start   ▲ end",
        &(FONT, 16).into_font().color(&RGBColor(80, 80, 80)),
        (20, root.dim_in_pixel().1 as i32 - 90),
    )?;
    Ok(())
}

/// Axis names of the 3D chart beside the middle of the tick-labelled edges: the bottom edges that
/// meet at the corner nearest the viewer (lowest on screen), and the vertical edge at the leftmost
/// corner. `px` projects (x, height, y) to pixels; the box is `cx ± half`, `cy ± half`, `z0..z1`.
fn draw_3d_axis_names<DB: Backend>(
    root: &Area<DB>,
    px: impl Fn(f64, f64, f64) -> (i32, i32),
    (cx, cy, half): (f64, f64, f64),
    (z0, z1): (f64, f64),
) -> DrawResult {
    let (xr, yr) = ((cx - half, cx + half), (cy - half, cy + half));
    let corners = [(xr.0, yr.0), (xr.0, yr.1), (xr.1, yr.0), (xr.1, yr.1)];
    let front = corners
        .iter()
        .copied()
        .max_by_key(|c| px(c.0, z0, c.1).1)
        .unwrap_or(corners[0]);
    let left = corners
        .iter()
        .copied()
        .min_by_key(|c| px(c.0, z0, c.1).0)
        .unwrap_or(corners[0]);
    let other = |v: f64, r: (f64, f64)| if v == r.0 { r.1 } else { r.0 };
    let mid = px(cx, (z0 + z1) / 2.0, cy);
    let outward = |p: (i32, i32), d: f64| {
        let (dx, dy) = ((p.0 - mid.0) as f64, (p.1 - mid.1) as f64);
        let n = dx.hypot(dy).max(1.0);
        (p.0 + (dx / n * d) as i32, p.1 + (dy / n * d) as i32)
    };
    let label = (FONT, 20).into_font().color(&BLACK);
    let x_mid = px((front.0 + other(front.0, xr)) / 2.0, z0, front.1);
    let y_mid = px(front.0, z0, (front.1 + other(front.1, yr)) / 2.0);
    let z_top = px(left.0, z1, left.1);
    root.draw_text("x (m)", &label, outward(x_mid, 70.0))?;
    root.draw_text("y (m)", &label, outward(y_mid, 70.0))?;
    root.draw_text("z (m)", &label, (z_top.0 - 20, z_top.1 - 40))?;
    Ok(())
}

/// (x, height, y) points of one agent for the 3D chart, thinned; `z = None` draws at ground level.
fn thin3(a: &AgentTrace, x: Column, y: Column, z: Option<Column>) -> Vec<(f64, f64, f64)> {
    let xs = a.col(x);
    let ys = a.col(y);
    let zs = z.map(|z| a.col(z));
    let step = xs.len().div_ceil(4000).max(1);
    (0..xs.len())
        .step_by(step)
        .map(|k| (xs[k], zs.map_or(0.0, |z| z[k]), ys[k]))
        .filter(|p| p.0.is_finite() && p.1.is_finite() && p.2.is_finite())
        .collect()
}

/// Index of the sample closest to time `t`.
fn index_at(a: &AgentTrace, t: f64) -> Option<usize> {
    a.t()
        .iter()
        .enumerate()
        .filter(|(_, v)| v.is_finite())
        .min_by(|x, y| (x.1 - t).abs().total_cmp(&(y.1 - t).abs()))
        .map(|(k, _)| k)
}

/// One snapshot: where everything was at time `t`.
struct Snapshot {
    t: f64,
    target: (f64, f64),
    /// (agent id, x, y, footprint radius)
    agents: Vec<(u32, f64, f64, f64)>,
}

impl Snapshot {
    fn at(fig: &Figure, t: f64) -> Option<Snapshot> {
        let first = fig.run.agents.first()?;
        let k = index_at(first, t)?;
        let target = (first.col(Column::Tx)[k], first.col(Column::Ty)[k]);
        let agents = fig
            .run
            .agents
            .iter()
            .filter_map(|a| {
                let k = index_at(a, t)?;
                let r = fig.geometry.footprint_radius(a.col(Column::Pz)[k]);
                Some((a.id, a.col(Column::Px)[k], a.col(Column::Py)[k], r))
            })
            .collect();
        Some(Snapshot {
            t: first.t()[k],
            target,
            agents,
        })
    }

    /// Fraction of the target disk inside at least one footprint (grid sampling).
    fn coverage(&self, disk_radius: f64) -> f64 {
        let n = 80;
        let (mut inside, mut covered) = (0usize, 0usize);
        for i in 0..n {
            for j in 0..n {
                let dx = disk_radius * (2.0 * (i as f64 + 0.5) / n as f64 - 1.0);
                let dy = disk_radius * (2.0 * (j as f64 + 0.5) / n as f64 - 1.0);
                if dx * dx + dy * dy > disk_radius * disk_radius {
                    continue;
                }
                inside += 1;
                let (x, y) = (self.target.0 + dx, self.target.1 + dy);
                if self
                    .agents
                    .iter()
                    .any(|&(_, ax, ay, r)| (x - ax).powi(2) + (y - ay).powi(2) <= r * r)
                {
                    covered += 1;
                }
            }
        }
        if inside == 0 {
            0.0
        } else {
            covered as f64 / inside as f64
        }
    }
}

/// Snapshot times: 10 s before T1 (covering) and 10 s after T3 (enclosing), moved inside the run.
fn snapshot_times(fig: &Figure) -> [f64; 2] {
    let (t0, t1) = fig.run.time_span();
    let phase = |name: &str| {
        fig.geometry
            .phases
            .iter()
            .find(|p| p.1 == name)
            .map(|p| p.0)
    };
    let cover = phase("T1").map(|t| t - 10.0).filter(|t| *t > t0 && *t < t1);
    let enclose = phase("T3")
        .map(|t| t + 10.0)
        .filter(|t| *t > t0 && *t <= t1);
    [
        cover.unwrap_or(t0 + 0.4 * (t1 - t0)),
        enclose.unwrap_or(t0 + 0.95 * (t1 - t0)),
    ]
}

fn circle(c: (f64, f64), r: f64) -> Vec<(f64, f64)> {
    (0..=96)
        .map(|k| {
            let a = k as f64 / 96.0 * std::f64::consts::TAU;
            (c.0 + r * a.cos(), c.1 + r * a.sin())
        })
        .collect()
}

/// Fig. 5 (right): top view; an overview and two zoomed snapshots with the disk and the footprints.
pub fn top_view<DB: Backend>(fig: &Figure, root: &Area<DB>) -> DrawResult {
    let area = titled(
        root,
        &format!(
            "Fig. 5 — top view: target disk (r = {} m) and sensor footprints ({})",
            fig.geometry.target_radius_m,
            fig.run.title()
        ),
    )?;
    let panels = area.split_evenly((1, 3));
    let snaps: Vec<Snapshot> = snapshot_times(fig)
        .iter()
        .filter_map(|&t| Snapshot::at(fig, t))
        .collect();

    // Overview: everything.
    let run = fig.run;
    // The range covers the trajectories, the target path, the disks (and their labels) and
    // the footprints of the snapshots.
    let rd = fig.geometry.target_radius_m;
    let mut extent: Vec<(f64, f64, f64)> = Vec::new();
    for s in &snaps {
        extent.push((s.target.0, s.target.1, 1.6 * rd));
        extent.extend(s.agents.iter().map(|&(_, x, y, r)| (x, y, r)));
    }
    let xs = run
        .agents
        .iter()
        .flat_map(|a| a.col(Column::Px).iter().chain(a.col(Column::Tx)).copied());
    let ys = run
        .agents
        .iter()
        .flat_map(|a| a.col(Column::Py).iter().chain(a.col(Column::Ty)).copied());
    let xs = xs.chain(extent.iter().flat_map(|e| [e.0 - e.2, e.0 + e.2]));
    let ys = ys.chain(extent.iter().flat_map(|e| [e.1 - e.2, e.1 + e.2]));
    let (x0, x1) = fit_range(xs, 0.03);
    let (y0, y1) = fit_range(ys, 0.03);
    let half = (x1 - x0).max(y1 - y0) / 2.0;
    let centre = ((x0 + x1) / 2.0, (y0 + y1) / 2.0);
    top_panel(
        fig,
        &panels[0],
        TopView {
            title: "whole run",
            centre,
            half,
            snaps: &snaps,
            trail_until: None,
            legend: true,
        },
    )?;

    for (k, s) in snaps.iter().enumerate() {
        let reach = s
            .agents
            .iter()
            .map(|&(_, x, y, r)| (x - s.target.0).hypot(y - s.target.1) + r)
            .fold(fig.geometry.target_radius_m, f64::max);
        let half = (reach * 1.15).min(4.0 * fig.geometry.target_radius_m.max(1.0));
        let cov = s.coverage(fig.geometry.target_radius_m) * 100.0;
        let title = format!("t = {:.1} s — disk covered {:.0} %", s.t, cov);
        top_panel(
            fig,
            &panels[k + 1],
            TopView {
                title: &title,
                centre: s.target,
                half,
                snaps: std::slice::from_ref(s),
                trail_until: Some(s.t),
                legend: false,
            },
        )?;
    }
    Ok(())
}

/// What one top-view panel shows.
struct TopView<'a> {
    /// The panel's title.
    title: &'a str,
    /// Centre of the view (x, y), m.
    centre: (f64, f64),
    /// Half-width of the view, m (the longer side is widened to keep x and y to scale).
    half: f64,
    /// The snapshots drawn (target disk, footprints).
    snaps: &'a [Snapshot],
    /// `None`: whole trajectories; `Some(t)`: the last [`TRAIL_S`] seconds before t.
    trail_until: Option<f64>,
    /// Whether the panel carries the legend (else a note on the circles).
    legend: bool,
}

/// The chart of a top view: x and y in m.
type XyChart<'a, DB> = ChartContext<
    'a,
    DB,
    Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>,
>;

/// One square top-view panel centred on `v.centre` with half-width `v.half`.
fn top_panel<DB: Backend>(fig: &Figure, area: &Area<DB>, v: TopView) -> DrawResult {
    let TopView {
        title,
        centre,
        half,
        snaps,
        trail_until,
        legend,
    } = v;
    let area = area.titled(title, (FONT, 19))?;
    let (w, h) = area.dim_in_pixel();
    let (margin, xlab, ylab) = (12i32, 44i32, 60i32);
    // Equal scales on x and y: the plotting rectangle's aspect sets the y span.
    let pw = (w as i32 - 2 * margin - ylab).max(1) as f64;
    let ph = (h as i32 - 2 * margin - xlab).max(1) as f64;
    let (hx, hy) = if pw >= ph {
        (half * pw / ph, half)
    } else {
        (half, half * ph / pw)
    };
    let mut chart = ChartBuilder::on(&area)
        .margin(margin)
        .x_label_area_size(xlab)
        .y_label_area_size(ylab)
        .build_cartesian_2d(centre.0 - hx..centre.0 + hx, centre.1 - hy..centre.1 + hy)?;
    draw_xy_mesh(&mut chart)?;

    let run = fig.run;
    let target = &run.agents[0];
    let window = (
        (centre.0 - hx, centre.0 + hx),
        (centre.1 - hy, centre.1 + hy),
    );
    let target_path: Vec<(f64, f64)> = target
        .col(Column::Tx)
        .iter()
        .copied()
        .zip(target.col(Column::Ty).iter().copied())
        .collect();
    for (k, part) in clip_runs(&thin(&target_path), window.0, window.1)
        .into_iter()
        .enumerate()
    {
        let s = chart.draw_series(DashedLineSeries::new(part, 8, 5, REFERENCE.stroke_width(2)))?;
        if k == 0 && legend {
            s.label("target path").legend(|(x, y)| {
                PathElement::new(vec![(x, y), (x + 24, y)], REFERENCE.stroke_width(2))
            });
        }
    }

    // Trajectories: the whole run (overview) or the last seconds before the snapshot.
    for a in &run.agents {
        let color = agent_color(a.id);
        let pts: Vec<(f64, f64)> = a
            .t()
            .iter()
            .zip(a.col(Column::Px).iter().zip(a.col(Column::Py)))
            .filter(|(t, _)| trail_until.is_none_or(|te| **t <= te && **t >= te - TRAIL_S))
            .map(|(_, (x, y))| (*x, *y))
            .collect();
        for (k, part) in clip_runs(&thin(&pts), window.0, window.1)
            .into_iter()
            .enumerate()
        {
            let s = chart.draw_series(LineSeries::new(part, color.mix(0.75).stroke_width(2)))?;
            if legend && k == 0 {
                s.label(format!("quadrotor {}", a.id))
                    .legend(move |(x, y)| {
                        PathElement::new(vec![(x, y), (x + 24, y)], color.stroke_width(3))
                    });
            }
        }
    }

    draw_snapshots(&mut chart, fig, snaps, trail_until.is_none(), legend)?;
    if legend {
        draw_top_legend(&mut chart, fig, &target_path, snaps, window)?;
    } else {
        let note = "circles: sensor footprints r = z tan(θs/2); ✕ target";
        area.draw_text(
            note,
            &(FONT, 13).into_font().color(&RGBColor(80, 80, 80)),
            (margin + ylab + 6, margin + 4),
        )?;
    }
    Ok(())
}

/// The snapshots of a top view: the target disk, every quadrotor's footprint, and (`label_time`)
/// the time beside the target.
fn draw_snapshots<DB: Backend>(
    chart: &mut XyChart<'_, DB>,
    fig: &Figure,
    snaps: &[Snapshot],
    label_time: bool,
    legend: bool,
) -> DrawResult {
    for s in snaps {
        let disk = circle(s.target, fig.geometry.target_radius_m);
        chart.draw_series(std::iter::once(Polygon::new(
            disk.clone(),
            DISK.mix(0.10).filled(),
        )))?;
        let d = chart.draw_series(std::iter::once(PathElement::new(
            disk,
            DISK.stroke_width(3),
        )))?;
        if legend && std::ptr::eq(s, &snaps[0]) {
            d.label("target disk at snapshots").legend(|(x, y)| {
                Rectangle::new([(x, y - 6), (x + 24, y + 6)], DISK.mix(0.25).filled())
            });
        }
        for &(id, x, y, r) in &s.agents {
            let color = agent_color(id);
            let ring = circle((x, y), r);
            chart.draw_series(std::iter::once(Polygon::new(
                ring.clone(),
                color.mix(0.12).filled(),
            )))?;
            chart.draw_series(std::iter::once(PathElement::new(
                ring,
                color.stroke_width(2),
            )))?;
            chart.draw_series(std::iter::once(Circle::new((x, y), 5, color.filled())))?;
        }
        chart.draw_series(std::iter::once(Cross::new(
            s.target,
            7,
            DISK.stroke_width(3),
        )))?;
        if label_time {
            let r = fig.geometry.target_radius_m;
            let label_pos = (s.target.0 - 0.45 * r, s.target.1 + 1.5 * r);
            chart.draw_series(std::iter::once(Text::new(
                format!("t = {:.0} s", s.t),
                label_pos,
                (FONT, 15).into_font().color(&DISK),
            )))?;
        }
    }
    Ok(())
}

/// The legend of a top view, in the emptiest corner of its data (`window`: the x and y ranges).
fn draw_top_legend<'a, DB: Backend + 'a>(
    chart: &mut XyChart<'a, DB>,
    fig: &Figure,
    target_path: &[(f64, f64)],
    snaps: &[Snapshot],
    window: ((f64, f64), (f64, f64)),
) -> DrawResult {
    let run = fig.run;
    // Legend box: ~7 entries of 19 px and ~190 px wide, in the emptiest corner of the data
    // (trajectories, target path, the disks and footprints of the snapshots).
    let (pw, ph) = chart.plotting_area().dim_in_pixel();
    let size = (200.0 / pw.max(1) as f64, 150.0 / ph.max(1) as f64);
    let mut data: Vec<(f64, f64)> = target_path.to_vec();
    for a in &run.agents {
        data.extend(
            a.col(Column::Px)
                .iter()
                .copied()
                .zip(a.col(Column::Py).iter().copied()),
        );
    }
    for s in snaps {
        data.extend(circle(s.target, fig.geometry.target_radius_m));
        for &(_, x, y, r) in &s.agents {
            data.extend(circle((x, y), r));
        }
    }
    let corner = emptiest_corner(data.into_iter(), window.0, window.1, size);
    chart
        .configure_series_labels()
        .position(corner)
        .label_font((FONT, 14))
        .background_style(WHITE.mix(0.85))
        .border_style(RGBColor(160, 160, 160))
        .draw()?;
    Ok(())
}
