//! `formation plot` (in progress).

use std::process::ExitCode;

/// Arguments of `formation plot`.
#[derive(clap::Args, Debug, Default)]
pub struct PlotArgs {}

/// Entry point of `formation plot`.
pub fn main(_args: PlotArgs) -> ExitCode {
    eprintln!("formation plot: not available yet");
    ExitCode::from(1)
}
