//! Shared command-line plumbing: loading and validating scenarios with exit code 2 on bad input.

use formation_config::validate::validate;
use formation_config::Scenario;
use std::process::ExitCode;

/// Exit code for invalid input (bad scenario, bad arguments).
pub const EXIT_INVALID: u8 = 2;

/// Loads (`paper`, `paper-exact` or a path) and validates a scenario; prints the errors and returns
/// exit code 2 on failure.
pub fn load_scenario(name: Option<&str>) -> Result<Scenario, ExitCode> {
    let name = name.unwrap_or("paper");
    let s = match Scenario::load(name) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("error: {e}");
            return Err(ExitCode::from(EXIT_INVALID));
        }
    };
    if let Err(errs) = validate(&s) {
        eprintln!("error: scenario '{name}' is invalid:");
        for e in &errs.0 {
            eprintln!("  {e}");
        }
        return Err(ExitCode::from(EXIT_INVALID));
    }
    Ok(s)
}
