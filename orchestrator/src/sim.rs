//! `formation sim` (in progress).

use std::process::ExitCode;

/// Arguments of `formation sim`.
#[derive(clap::Args, Debug, Default)]
pub struct SimArgs {}

/// Entry point of `formation sim`.
pub fn main(_args: SimArgs) -> ExitCode {
    ExitCode::from(1)
}
