//! Shared look of the figures: the embedded font, agent colours, and a time-series panel.

use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::FontStyle;
use std::sync::OnceLock;

/// DejaVu Sans, embedded so that figures render without any system font (licence beside the file).
pub(super) static FONT_TTF: &[u8] = include_bytes!("../../assets/DejaVuSans.ttf");

/// The font family every text of the figures uses.
pub const FONT: &str = "sans-serif";

/// The embedded font could not be parsed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("the embedded font DejaVuSans.ttf could not be parsed")]
pub struct FontError;

/// Registers the embedded font with plotters' ab_glyph text renderer (once per process).
/// Every family name plotters may ask for maps to the same face.
pub fn register_fonts() -> Result<(), FontError> {
    static DONE: OnceLock<Result<(), FontError>> = OnceLock::new();
    *DONE.get_or_init(|| {
        for family in ["sans-serif", "serif", "monospace"] {
            for style in [FontStyle::Normal, FontStyle::Bold] {
                plotters::style::register_font(family, style, FONT_TTF).map_err(|_| FontError)?;
            }
        }
        Ok(())
    })
}

/// Error type of the drawing code.
pub type DrawResult = Result<(), Box<dyn std::error::Error>>;

/// A backend a figure can be drawn on: the PNG bitmap (through [`super::text::GlyphText`]) or
/// SVG; its errors can be boxed.
pub trait Backend: DrawingBackend<ErrorType: 'static> {}

impl<T: DrawingBackend<ErrorType: 'static>> Backend for T {}

/// The drawing area type every figure draws on.
pub type Area<DB> = DrawingArea<DB, Shift>;

/// Colour of agent `id` (1-based): the palette every view of a run uses, cycled.
pub fn agent_color(id: u32) -> RGBColor {
    let [r, g, b] = formation_config::view::agent_rgb(id as usize);
    RGBColor(r, g, b)
}

/// Dark grey for reference signals (target, constraints).
pub const REFERENCE: RGBColor = RGBColor(30, 30, 30);

/// How a series is stroked.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stroke {
    /// Solid line.
    Solid,
    /// Dashed line.
    Dashed,
}

/// One line of a panel.
pub struct Line {
    /// Legend text (`None`: no legend entry).
    pub label: Option<String>,
    /// Colour.
    pub color: RGBColor,
    /// Stroke pattern.
    pub stroke: Stroke,
    /// Line width, px.
    pub width: u32,
    /// Points (non-finite points are dropped).
    pub points: Vec<(f64, f64)>,
}

impl Line {
    /// A solid 2-px line with a legend entry.
    pub fn new(label: impl Into<String>, color: RGBColor, points: Vec<(f64, f64)>) -> Line {
        Line {
            label: Some(label.into()),
            color,
            stroke: Stroke::Solid,
            width: 2,
            points,
        }
    }

    /// The same line, dashed.
    pub fn dashed(mut self) -> Line {
        self.stroke = Stroke::Dashed;
        self
    }

    /// The same line without a legend entry.
    pub fn unlabelled(mut self) -> Line {
        self.label = None;
        self
    }

    /// The same line with another width.
    pub fn width(mut self, w: u32) -> Line {
        self.width = w;
        self
    }
}

/// Where the legend of a panel goes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Legend {
    /// No legend and no space reserved for one.
    None,
    /// A legend column at the right of the plot (never over the data).
    Side,
    /// The space of a legend column, left blank (aligns the panel with panels that have one).
    Blank,
}

/// Width of the legend column, px.
pub const LEGEND_WIDTH: u32 = 170;

/// A time-series panel: title, axis descriptions, lines, optional vertical markers.
pub struct Panel<'a> {
    /// Panel caption.
    pub title: String,
    /// x-axis description (with unit).
    pub x_desc: &'a str,
    /// y-axis description (with unit).
    pub y_desc: String,
    /// Lines to draw.
    pub lines: Vec<Line>,
    /// Vertical dotted markers (x, text), e.g. the phase changes T1, T2, T3.
    pub markers: &'a [(f64, String)],
    /// Legend placement.
    pub legend: Legend,
    /// Fixed y range; `None` fits the data.
    pub y_range: Option<(f64, f64)>,
    /// Fixed x range; `None` fits the data.
    pub x_range: Option<(f64, f64)>,
}

/// Largest number of points drawn per line; longer lines keep each bucket's min and max.
const MAX_POINTS: usize = 4000;

/// Drops non-finite points and reduces long lines to the min/max envelope of buckets.
pub fn thin(points: &[(f64, f64)]) -> Vec<(f64, f64)> {
    let finite: Vec<(f64, f64)> = points
        .iter()
        .copied()
        .filter(|(x, y)| x.is_finite() && y.is_finite())
        .collect();
    if finite.len() <= MAX_POINTS {
        return finite;
    }
    let bucket = finite.len().div_ceil(MAX_POINTS / 2);
    let mut out = Vec::with_capacity(MAX_POINTS + 2);
    for chunk in finite.chunks(bucket) {
        let (mut imin, mut imax) = (0, 0);
        for (i, p) in chunk.iter().enumerate() {
            if p.1 < chunk[imin].1 {
                imin = i;
            }
            if p.1 > chunk[imax].1 {
                imax = i;
            }
        }
        let (a, b) = (imin.min(imax), imin.max(imax));
        out.push(chunk[a]);
        if b != a {
            out.push(chunk[b]);
        }
    }
    out
}

/// A padded range covering the finite values, never empty.
pub fn fit_range(values: impl Iterator<Item = f64>, pad_fraction: f64) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in values.filter(|v| v.is_finite()) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if lo > hi {
        return (-1.0, 1.0);
    }
    let span = hi - lo;
    let pad = if span > 1e-12 {
        span * pad_fraction
    } else {
        (hi.abs() * 0.1).max(1e-3)
    };
    (lo - pad, hi + pad)
}

/// The y range of several panels together (to share a scale across a row).
pub fn lines_y_range(lines: &[&Line]) -> (f64, f64) {
    fit_range(
        lines.iter().flat_map(|l| l.points.iter().map(|p| p.1)),
        0.06,
    )
}

/// Draws a time-series panel into `area`.
pub fn draw_panel<DB: Backend>(area: &Area<DB>, panel: Panel) -> DrawResult {
    let lines: Vec<Line> = panel
        .lines
        .into_iter()
        .map(|mut l| {
            l.points = thin(&l.points);
            l
        })
        .collect();
    let x_range = panel
        .x_range
        .unwrap_or_else(|| fit_range(lines.iter().flat_map(|l| l.points.iter().map(|p| p.0)), 0.0));
    let y_range = panel
        .y_range
        .unwrap_or_else(|| lines_y_range(&lines.iter().collect::<Vec<_>>()));

    let (plot_area, side) = match panel.legend {
        Legend::None => (area.clone(), None),
        Legend::Side | Legend::Blank => {
            let w = area.dim_in_pixel().0;
            let (p, side) = area.split_horizontally(w.saturating_sub(LEGEND_WIDTH));
            (p, Some(side))
        }
    };
    let mut chart = ChartBuilder::on(&plot_area)
        .caption(&panel.title, (FONT, 20))
        .margin(8)
        .margin_right(16)
        .x_label_area_size(44)
        .y_label_area_size(72)
        .build_cartesian_2d(x_range.0..x_range.1, y_range.0..y_range.1)?;
    chart
        .configure_mesh()
        .x_desc(panel.x_desc)
        .y_desc(panel.y_desc.as_str())
        .label_style((FONT, 14))
        .axis_desc_style((FONT, 16))
        .light_line_style(RGBColor(235, 235, 235))
        .bold_line_style(RGBColor(215, 215, 215))
        .x_labels(10)
        .y_labels(6)
        .x_label_formatter(&|v| format_tick(*v))
        .y_label_formatter(&|v| format_tick(*v))
        .max_light_lines(2)
        .draw()?;

    for (x, text) in panel.markers {
        if *x < x_range.0 || *x > x_range.1 {
            continue;
        }
        let grey = RGBColor(120, 120, 120);
        chart.draw_series(DashedLineSeries::new(
            vec![(*x, y_range.0), (*x, y_range.1)],
            4,
            4,
            grey.stroke_width(1),
        ))?;
        // Labels at the bottom, where bounds and legends are least likely to be.
        let top = y_range.0 + (y_range.1 - y_range.0) * 0.09;
        chart.draw_series(std::iter::once(Text::new(
            text.clone(),
            (*x + (x_range.1 - x_range.0) * 0.004, top),
            (FONT, 13).into_font().color(&grey),
        )))?;
    }

    // Lines are stroked segment by segment in pixel space: plotters joins thick polylines with
    // mitres, which shoot far out of the panel where a noisy signal turns back sharply.
    let canvas = chart.plotting_area().strip_coord_spec();
    let base = canvas.get_base_pixel();
    for line in &lines {
        let style = line.color.stroke_width(line.width);
        let mut pixels: Vec<(i32, i32)> = line
            .points
            .iter()
            .map(|p| {
                let (x, y) = chart.backend_coord(p);
                (x - base.0, y - base.1)
            })
            .collect();
        match line.stroke {
            Stroke::Solid => stroke_pixels(&canvas, &pixels, style)?,
            Stroke::Dashed => {
                pixels.dedup();
                for (a, b) in dash(&pixels, 9.0, 5.0) {
                    canvas.draw(&PathElement::new(vec![a, b], style))?;
                }
            }
        }
    }

    if let (Legend::Side, Some(side)) = (panel.legend, side) {
        draw_side_legend(&side, &lines)?;
    }
    Ok(())
}

/// Strokes a polyline given in pixels of `area` segment by segment: plotters joins the segments of
/// a thick polyline with mitres, which shoot far out of the line (spurs) where it turns back
/// sharply, as a noisy signal or a densely sampled path does at every pixel step.
pub fn stroke_pixels<DB: Backend>(
    area: &Area<DB>,
    pixels: &[(i32, i32)],
    style: ShapeStyle,
) -> DrawResult {
    let mut pixels = pixels.to_vec();
    pixels.dedup();
    for w in pixels.windows(2) {
        area.draw(&PathElement::new(vec![w[0], w[1]], style))?;
    }
    Ok(())
}

/// The corner of the window `x` × `y` where a legend box `size` (fractions of the window's
/// width and height) covers the fewest of `points`: a legend inside the data goes where it hides
/// the least (the first of upper right, upper left, lower left, lower right on a tie).
pub fn emptiest_corner(
    points: impl Iterator<Item = (f64, f64)>,
    x: (f64, f64),
    y: (f64, f64),
    size: (f64, f64),
) -> SeriesLabelPosition {
    let (w, h) = ((x.1 - x.0) * size.0, (y.1 - y.0) * size.1);
    // (position, x range, y range) of each candidate box.
    let corners = [
        (
            SeriesLabelPosition::UpperRight,
            (x.1 - w, x.1),
            (y.1 - h, y.1),
        ),
        (
            SeriesLabelPosition::UpperLeft,
            (x.0, x.0 + w),
            (y.1 - h, y.1),
        ),
        (
            SeriesLabelPosition::LowerLeft,
            (x.0, x.0 + w),
            (y.0, y.0 + h),
        ),
        (
            SeriesLabelPosition::LowerRight,
            (x.1 - w, x.1),
            (y.0, y.0 + h),
        ),
    ];
    let mut counts = [0usize; 4];
    for p in points {
        for (k, (_, bx, by)) in corners.iter().enumerate() {
            if p.0 >= bx.0 && p.0 <= bx.1 && p.1 >= by.0 && p.1 <= by.1 {
                counts[k] += 1;
            }
        }
    }
    let best = (0..4).min_by_key(|&k| counts[k]).unwrap_or(0);
    corners[best].0.clone()
}

/// Cuts a pixel polyline into dashes of `on` px separated by gaps of `off` px; returns the
/// straight pieces to stroke.
fn dash(pixels: &[(i32, i32)], on: f64, off: f64) -> Vec<((i32, i32), (i32, i32))> {
    let mut out = Vec::new();
    let (mut drawing, mut left) = (true, on);
    for w in pixels.windows(2) {
        let (a, b) = (
            (w[0].0 as f64, w[0].1 as f64),
            (w[1].0 as f64, w[1].1 as f64),
        );
        let len = (b.0 - a.0).hypot(b.1 - a.1);
        let mut s = 0.0;
        while s < len {
            let step = left.min(len - s);
            if drawing {
                let p = |u: f64| {
                    let f = u / len;
                    (
                        (a.0 + (b.0 - a.0) * f).round() as i32,
                        (a.1 + (b.1 - a.1) * f).round() as i32,
                    )
                };
                out.push((p(s), p(s + step)));
            }
            s += step;
            left -= step;
            if left <= 1e-9 {
                drawing = !drawing;
                left = if drawing { on } else { off };
            }
        }
    }
    out
}

/// Draws the labelled lines' samples and names in a column, from the top.
fn draw_side_legend<DB: Backend>(side: &Area<DB>, lines: &[Line]) -> DrawResult {
    let font = (FONT, 15).into_font().color(&BLACK);
    let mut y = 48;
    for line in lines {
        let Some(label) = &line.label else { continue };
        let style = line.color.stroke_width(line.width.max(2));
        for (x0, x1) in legend_segments(line.stroke) {
            side.draw(&PathElement::new(vec![(6 + x0, y), (6 + x1, y)], style))?;
        }
        side.draw_text(label, &font, (38, y - 9))?;
        y += 24;
    }
    Ok(())
}

/// The legend sample of a line: four 24-px-wide segments (x0, x1) showing its stroke pattern.
fn legend_segments(stroke: Stroke) -> [(i32, i32); 4] {
    match stroke {
        Stroke::Solid => [(0, 6), (6, 12), (12, 18), (18, 24)],
        Stroke::Dashed => [(0, 9), (0, 9), (15, 24), (15, 24)],
    }
}

/// The mesh of a top view (x and y in m): light grid, tick labels from [`format_tick`].
pub fn draw_xy_mesh<DB: Backend>(
    chart: &mut ChartContext<
        '_,
        DB,
        Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>,
    >,
) -> DrawResult {
    chart
        .configure_mesh()
        .x_desc("x (m)")
        .y_desc("y (m)")
        .label_style((FONT, 14))
        .axis_desc_style((FONT, 16))
        .light_line_style(RGBColor(240, 240, 240))
        .bold_line_style(RGBColor(215, 215, 215))
        .x_label_formatter(&|v| format_tick(*v))
        .y_label_formatter(&|v| format_tick(*v))
        .draw()?;
    Ok(())
}

/// Tick labels: few significant digits, scientific notation for very small or large magnitudes.
pub fn format_tick(v: f64) -> String {
    let a = v.abs();
    if a < 1e-10 {
        // Also hides floating-point noise of tick positions (6.9e-18 for 0).
        "0".to_string()
    } else if !(1e-3..1e5).contains(&a) {
        format!("{v:.1e}")
    } else if a >= 100.0 {
        format!("{v:.0}")
    } else if a >= 1.0 {
        let s = format!("{v:.2}");
        trim_zeros(s)
    } else {
        trim_zeros(format!("{v:.4}"))
    }
}

fn trim_zeros(s: String) -> String {
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    }
}

/// Draws a figure title across the top of `root` and returns the area below it.
pub fn titled<DB: Backend>(
    root: &Area<DB>,
    title: &str,
) -> Result<Area<DB>, Box<dyn std::error::Error>> {
    root.fill(&WHITE)?;
    Ok(root.titled(title, (FONT, 26))?)
}

/// Splits a polyline into the runs of points inside a window (plotters clamps points outside the
/// plotting area onto its border instead of clipping them, which draws false lines along the edge).
pub fn clip_runs(points: &[(f64, f64)], x: (f64, f64), y: (f64, f64)) -> Vec<Vec<(f64, f64)>> {
    let inside = |p: &(f64, f64)| p.0 >= x.0 && p.0 <= x.1 && p.1 >= y.0 && p.1 <= y.1;
    let mut runs = Vec::new();
    let mut current: Vec<(f64, f64)> = Vec::new();
    for p in points.iter().filter(|p| p.0.is_finite() && p.1.is_finite()) {
        if inside(p) {
            current.push(*p);
        } else if !current.is_empty() {
            runs.push(std::mem::take(&mut current));
        }
    }
    if !current.is_empty() {
        runs.push(current);
    }
    runs.retain(|r| r.len() > 1);
    runs
}
