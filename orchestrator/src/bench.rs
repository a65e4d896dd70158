//! `formation bench` (in progress).

use std::process::ExitCode;

/// Arguments of `formation bench`.
#[derive(clap::Args, Debug, Default)]
pub struct BenchArgs {}

/// Entry point of `formation bench`.
pub fn main(_args: BenchArgs) -> ExitCode {
    eprintln!("formation bench: not available yet");
    ExitCode::from(1)
}
