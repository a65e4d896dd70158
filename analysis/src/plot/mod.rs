//! `formation plot`: the paper's Figs. 5-14 and the separation figure as PNG or SVG files, from
//! one run directory (or two, to compare variants in Fig. 6 and Fig. 9).
//!
//! PNG text is rasterised by [`text::GlyphText`] from a font embedded in the binary, so figures
//! render identically on machines without any system font (no fontconfig, no font-kit). SVG text
//! stays text (`<text>` elements in the `sans-serif` family), laid out with the same metrics.

use plotters::prelude::IntoDrawingArea;
use std::path::{Path, PathBuf};

mod attitude;
mod data;
mod errors;
mod estimates;
mod geometry;
mod inputs;
#[cfg(feature = "foxglove")]
pub mod scene;
mod separation;
mod style;
#[cfg(test)]
mod tests;
pub mod text;
mod trajectory;

pub use data::Run;
pub use geometry::Geometry;

/// Arguments of `formation plot`.
#[derive(clap::Args, Debug, Default)]
pub struct PlotArgs {
    /// Run directory holding `trajectory.csv` (and optionally `summary.json`).
    pub dir: PathBuf,
    /// Second run directory (e.g. a `no-rbfnn` or `unconstrained` run) compared in Figs. 6 and 9.
    #[arg(long, value_name = "DIR2")]
    pub compare: Option<PathBuf>,
    /// Runs of the same timeline flown another way (e.g. `runtime.fallback`), repeatable: adds
    /// `events_compare`, the worst agent's formation error of DIR and of each around the first
    /// event, each line named by its directory.
    #[arg(long = "events-compare", value_name = "DIR")]
    pub events_compare: Vec<PathBuf>,
    /// Directory to write the figures into (created if missing). Default: the run directory.
    #[arg(long, value_name = "OUTDIR")]
    pub out: Option<PathBuf>,
    /// File format of the figures: `png` (bitmap) or `svg` (vector, text as text).
    #[arg(long, value_enum, default_value_t = Format::Png)]
    pub format: Format,
    /// Times of the `scene` figure, s (default 30,55: covering and enclosing of the paper run;
    /// moved inside the run). The figure needs DIR/scenario.toml (written by sim and run).
    #[arg(long, value_name = "T1,T2", value_delimiter = ',')]
    pub scene_at: Vec<f64>,
}

/// File format of the figures.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum Format {
    /// PNG bitmap.
    #[default]
    Png,
    /// SVG vector graphics; text is text.
    Svg,
}

impl Format {
    /// The file extension.
    pub fn extension(self) -> &'static str {
        match self {
            Format::Png => "png",
            Format::Svg => "svg",
        }
    }
}

/// Why plotting failed.
#[derive(Debug)]
pub enum PlotError {
    /// Bad input: missing directory, file or column, malformed CSV (exit code 2).
    Input(String),
    /// A figure could not be drawn or written (exit code 1).
    Render(String),
}

impl std::fmt::Display for PlotError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            PlotError::Input(m) | PlotError::Render(m) => f.write_str(m),
        }
    }
}

impl std::error::Error for PlotError {}

/// One figure written: its path and size, px.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Rendered {
    /// Path of the file.
    pub path: PathBuf,
    /// Width, px.
    pub width: u32,
    /// Height, px.
    pub height: u32,
}

/// Entry point of `formation plot`: renders every figure and lists the files written.
pub fn main(args: PlotArgs) -> Result<(), PlotError> {
    let files = run(&args)?;
    println!("wrote {} figures:", files.len());
    for f in &files {
        println!("  {}", f.path.display());
    }
    Ok(())
}

/// Loads the run(s) and renders every figure; returns the files written.
pub fn run(args: &PlotArgs) -> Result<Vec<Rendered>, PlotError> {
    let main_run = Run::load(&args.dir)?;
    let compare = args.compare.as_deref().map(Run::load).transpose()?;
    let out = args.out.clone().unwrap_or_else(|| args.dir.clone());
    std::fs::create_dir_all(&out).map_err(|e| {
        PlotError::Input(format!(
            "cannot create output directory '{}': {e}",
            out.display()
        ))
    })?;
    let others = args
        .events_compare
        .iter()
        .map(|d| Run::load(d))
        .collect::<Result<Vec<_>, _>>()?;
    let geometry = Geometry::for_run(&main_run);
    let mut files = render_all(&main_run, compare.as_ref(), &geometry, &out, args.format)?;
    if !others.is_empty() {
        let path = out.join(format!("events_compare.{}", args.format.extension()));
        let size = (1400, 700);
        let fig = Figure {
            run: &main_run,
            compare: None,
            geometry: &geometry,
            others: &others,
        };
        draw_file(Kind::EventsCompare, &fig, &path, size, args.format)
            .map_err(|e| PlotError::Render(format!("{}: {e}", path.display())))?;
        files.push(Rendered {
            path,
            width: size.0,
            height: size.1,
        });
    }
    #[cfg(feature = "foxglove")]
    if scene::available(&args.dir) {
        files.push(render_scene(args, &main_run, &out)?);
    }
    Ok(files)
}

/// The `scene` figure: the live view's scene at the `--scene-at` times, from above.
#[cfg(feature = "foxglove")]
fn render_scene(args: &PlotArgs, run: &Run, out: &Path) -> Result<Rendered, PlotError> {
    let times = if args.scene_at.is_empty() {
        scene::DEFAULT_TIMES_S.to_vec()
    } else {
        args.scene_at.clone()
    };
    let scenes = scene::load(&args.dir, &times)?;
    let size = (900 * scenes.at.len() as u32 + 100, 1010);
    let path = out.join(format!("scene.{}", args.format.extension()));
    let title = run.title();
    let drawn: style::DrawResult = (|| {
        match args.format {
            Format::Png => {
                let backend = plotters::backend::BitMapBackend::new(&path, size);
                let root = text::GlyphText::new(backend).into_drawing_area();
                scene::draw(&scenes, &title, &root)?;
                root.present()?;
            }
            Format::Svg => {
                let backend = plotters::backend::SVGBackend::new(&path, size);
                let root = text::GlyphText::vector(backend).into_drawing_area();
                scene::draw(&scenes, &title, &root)?;
                root.present()?;
            }
        }
        Ok(())
    })();
    drawn.map_err(|e| PlotError::Render(format!("{}: {e}", path.display())))?;
    Ok(Rendered {
        path,
        width: size.0,
        height: size.1,
    })
}

/// The figures.
#[derive(Debug, Clone, Copy)]
enum Kind {
    Trajectory3d,
    TopView,
    PositionErrors,
    RbfnnError,
    Attitude,
    AttitudeConstraint,
    RateConstraint,
    Inputs,
    Disturbance,
    Gamma,
    Delta,
    Separation,
    Events,
    EventsCompare,
}

/// Draws figure `kind` on `root`.
fn draw<DB: style::Backend>(kind: Kind, fig: &Figure, root: &style::Area<DB>) -> style::DrawResult {
    match kind {
        Kind::Trajectory3d => trajectory::trajectory_3d(fig, root),
        Kind::TopView => trajectory::top_view(fig, root),
        Kind::PositionErrors => errors::position_errors(fig, root),
        Kind::RbfnnError => errors::rbfnn_error(fig, root),
        Kind::Attitude => attitude::attitude(fig, root),
        Kind::AttitudeConstraint => attitude::attitude_constraint(fig, root),
        Kind::RateConstraint => attitude::rate_constraint(fig, root),
        Kind::Inputs => inputs::inputs(fig, root),
        Kind::Disturbance => estimates::disturbance(fig, root),
        Kind::Gamma => estimates::gamma(fig, root),
        Kind::Delta => estimates::delta(fig, root),
        Kind::Separation => separation::separation(fig, root),
        Kind::Events => errors::events(fig, root),
        Kind::EventsCompare => errors::events_compare(fig, root),
    }
}

/// Draws figure `kind` into the file `path` of `format`, `size` px.
fn draw_file(
    kind: Kind,
    fig: &Figure,
    path: &Path,
    size: (u32, u32),
    format: Format,
) -> style::DrawResult {
    match format {
        Format::Png => {
            let backend = plotters::backend::BitMapBackend::new(path, size);
            let root = text::GlyphText::new(backend).into_drawing_area();
            draw(kind, fig, &root)?;
            root.present()?;
        }
        Format::Svg => {
            let backend = plotters::backend::SVGBackend::new(path, size);
            let root = text::GlyphText::vector(backend).into_drawing_area();
            draw(kind, fig, &root)?;
            root.present()?;
        }
    }
    Ok(())
}

/// What every figure renderer receives.
pub struct Figure<'a> {
    /// The run to draw.
    pub run: &'a Run,
    /// The run to compare with (Figs. 6 and 9), if any.
    pub compare: Option<&'a Run>,
    /// Coverage geometry and phase times.
    pub geometry: &'a Geometry,
    /// Runs of the same timeline flown another way (`--events-compare`).
    pub others: &'a [Run],
}

/// Renders Figs. 5-14 of `run` and the separation figure into `out`, as `format` files.
pub fn render_all(
    run: &Run,
    compare: Option<&Run>,
    geometry: &Geometry,
    out: &Path,
    format: Format,
) -> Result<Vec<Rendered>, PlotError> {
    style::register_fonts().map_err(|e| PlotError::Render(e.to_string()))?;
    let fig = Figure {
        run,
        compare,
        geometry,
        others: &[],
    };
    let n = run.agents.len() as u32;
    let cols = if compare.is_some() { 2 } else { 1 };
    let list: Vec<(&str, (u32, u32), Kind)> = vec![
        ("fig05_trajectory_3d", (1400, 1100), Kind::Trajectory3d),
        ("fig05_top_view", (1950, 720), Kind::TopView),
        (
            "fig06_position_errors",
            (900 * cols + 100, 1100),
            Kind::PositionErrors,
        ),
        ("fig07_rbfnn_error", (1400, 1100), Kind::RbfnnError),
        ("fig08_attitude", (1600, 90 + 260 * n), Kind::Attitude),
        (
            "fig09_attitude_constraint",
            (1400, 90 + 250 * n),
            Kind::AttitudeConstraint,
        ),
        (
            "fig10_rate_constraint",
            (1400, 90 + 250 * n),
            Kind::RateConstraint,
        ),
        ("fig11_inputs", (1400, 1400), Kind::Inputs),
        ("fig12_disturbance_estimate", (1400, 700), Kind::Disturbance),
        ("fig13_gamma", (1400, 1100), Kind::Gamma),
        ("fig14_delta", (1400, 1100), Kind::Delta),
        ("separation", (1400, 700), Kind::Separation),
    ];
    let mut list = list;
    if !run.events.is_empty() {
        list.push(("events", (1400, 700), Kind::Events));
    }
    let mut written = Vec::with_capacity(list.len());
    for (stem, size, kind) in list {
        let path = out.join(format!("{stem}.{}", format.extension()));
        draw_file(kind, &fig, &path, size, format)
            .map_err(|e| PlotError::Render(format!("{}: {e}", path.display())))?;
        written.push(Rendered {
            path,
            width: size.0,
            height: size.1,
        });
    }
    Ok(written)
}
