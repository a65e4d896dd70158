//! `formation check` (in progress).

use std::process::ExitCode;

/// Arguments of `formation check`.
#[derive(clap::Args, Debug, Default)]
pub struct CheckArgs {}

/// Entry point of `formation check`.
pub fn main(_args: CheckArgs) -> ExitCode {
    eprintln!("formation check: not available yet");
    ExitCode::from(1)
}
