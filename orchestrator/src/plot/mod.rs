//! `formation plot`: the paper's Figs. 5-14 and the separation figure as PNG files, from one run directory (or two, to compare
//! variants in Fig. 6 and Fig. 9).
//!
//! Text is rendered by plotters' ab_glyph backend from a font embedded in the binary, so figures
//! render identically on machines without any system font (no fontconfig, no font-kit).

use std::path::{Path, PathBuf};
use std::process::ExitCode;

mod attitude;
mod data;
mod errors;
mod estimates;
mod geometry;
mod inputs;
mod separation;
mod style;
#[cfg(test)]
mod tests;
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
    /// Directory to write the PNG files into (created if missing). Default: the run directory.
    #[arg(long, value_name = "OUTDIR")]
    pub out: Option<PathBuf>,
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

/// One PNG written: its path and pixel size.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Rendered {
    /// Path of the file.
    pub path: PathBuf,
    /// Width, px.
    pub width: u32,
    /// Height, px.
    pub height: u32,
}

/// Entry point of `formation plot`.
pub fn main(args: PlotArgs) -> ExitCode {
    match run(&args) {
        Ok(files) => {
            println!("wrote {} figures:", files.len());
            for f in &files {
                println!("  {}", f.path.display());
            }
            ExitCode::SUCCESS
        }
        Err(e @ PlotError::Input(_)) => {
            eprintln!("error: {e}");
            ExitCode::from(crate::cli::EXIT_INVALID)
        }
        Err(e @ PlotError::Render(_)) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
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
    let geometry = Geometry::for_run(&main_run);
    render_all(&main_run, compare.as_ref(), &geometry, &out)
}

/// A figure renderer: draws into the file at the given path with the given size.
type Renderer = fn(&Figure, &Path, (u32, u32)) -> style::DrawResult;

/// What every figure renderer receives.
pub struct Figure<'a> {
    /// The run to draw.
    pub run: &'a Run,
    /// The run to compare with (Figs. 6 and 9), if any.
    pub compare: Option<&'a Run>,
    /// Coverage geometry and phase times.
    pub geometry: &'a Geometry,
}

/// Renders Figs. 5-14 of `run` and the separation figure into `out`.
pub fn render_all(
    run: &Run,
    compare: Option<&Run>,
    geometry: &Geometry,
    out: &Path,
) -> Result<Vec<Rendered>, PlotError> {
    style::register_fonts().map_err(PlotError::Render)?;
    let fig = Figure {
        run,
        compare,
        geometry,
    };
    let n = run.agents.len() as u32;
    let cols = if compare.is_some() { 2 } else { 1 };
    let list: Vec<(&str, (u32, u32), Renderer)> = vec![
        (
            "fig05_trajectory_3d.png",
            (1400, 1100),
            trajectory::trajectory_3d,
        ),
        ("fig05_top_view.png", (1950, 720), trajectory::top_view),
        (
            "fig06_position_errors.png",
            (900 * cols + 100, 1100),
            errors::position_errors,
        ),
        ("fig07_rbfnn_error.png", (1400, 1100), errors::rbfnn_error),
        (
            "fig08_attitude.png",
            (1600, 90 + 260 * n),
            attitude::attitude,
        ),
        (
            "fig09_attitude_constraint.png",
            (1400, 90 + 250 * n),
            attitude::attitude_constraint,
        ),
        (
            "fig10_rate_constraint.png",
            (1400, 90 + 250 * n),
            attitude::rate_constraint,
        ),
        ("fig11_inputs.png", (1400, 1400), inputs::inputs),
        (
            "fig12_disturbance_estimate.png",
            (1400, 700),
            estimates::disturbance,
        ),
        ("fig13_gamma.png", (1400, 1100), estimates::gamma),
        ("fig14_delta.png", (1400, 1100), estimates::delta),
        ("separation.png", (1400, 700), separation::separation),
    ];
    let mut written = Vec::with_capacity(list.len());
    for (name, size, render) in list {
        let path = out.join(name);
        render(&fig, &path, size)
            .map_err(|e| PlotError::Render(format!("{}: {e}", path.display())))?;
        written.push(Rendered {
            path,
            width: size.0,
            height: size.1,
        });
    }
    Ok(written)
}
