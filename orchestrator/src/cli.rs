//! Shared command-line plumbing: loading and validating scenarios with exit code 2 on bad input.

use formation_config::scenario::validate::validate;
use formation_config::Scenario;
use std::process::ExitCode;

/// Exit code for invalid input (bad scenario, bad arguments).
pub const EXIT_INVALID: u8 = 2;

/// Applies `--set path=value` overrides (TOML paths such as `controller.position.k_p` or
/// `agents[2].delay.base_s`; values in TOML syntax) to a scenario.
pub fn apply_overrides(s: Scenario, sets: &[String]) -> Result<Scenario, String> {
    if sets.is_empty() {
        return Ok(s);
    }
    let mut root = toml::Value::try_from(&s).map_err(|e| e.to_string())?;
    for set in sets {
        let (path, value) = set
            .split_once('=')
            .ok_or_else(|| format!("--set '{set}': expected path=value"))?;
        let parsed: toml::Table = toml::from_str(&format!("v = {}", value.trim()))
            .map_err(|e| format!("--set '{set}': bad value: {e}"))?;
        let new_value = parsed["v"].clone();
        let mut node = &mut root;
        for part in path.trim().split('.') {
            let (key, index) = match part.split_once('[') {
                Some((k, rest)) => {
                    let idx: usize = rest
                        .trim_end_matches(']')
                        .parse()
                        .map_err(|_| format!("--set '{set}': bad index in '{part}'"))?;
                    (k, Some(idx))
                }
                None => (part, None),
            };
            node = node
                .get_mut(key)
                .ok_or_else(|| format!("--set '{set}': no field '{key}'"))?;
            if let Some(idx) = index {
                node = node
                    .get_mut(idx)
                    .ok_or_else(|| format!("--set '{set}': index {idx} out of range"))?;
            }
        }
        *node = new_value;
    }
    root.try_into()
        .map_err(|e: toml::de::Error| format!("--set: {e}"))
}

/// Loads a scenario, applies the overrides, validates; exit code 2 with clear errors on failure.
pub fn load_with_overrides(name: Option<&str>, sets: &[String]) -> Result<Scenario, ExitCode> {
    let name = name.unwrap_or("paper");
    let s = match Scenario::load(name) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("error: {e}");
            return Err(ExitCode::from(EXIT_INVALID));
        }
    };
    let s = match apply_overrides(s, sets) {
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

/// Parses a variant name, exit code 2 on an unknown one.
pub fn parse_variant(name: &str) -> Result<formation_config::Variant, ExitCode> {
    formation_config::Variant::parse(name).ok_or_else(|| {
        eprintln!("error: unknown variant '{name}' (expected proposed, no-rbfnn or unconstrained)");
        ExitCode::from(EXIT_INVALID)
    })
}

/// What every runner (`sim`, `run`) takes: scenario, variant, output directory and overrides.
#[derive(clap::Args, Debug, Default, Clone)]
pub struct RunnerArgs {
    /// Scenario: `paper` (default), `paper-exact`, or a TOML file.
    pub scenario: Option<String>,
    /// Controller variant: proposed, no-rbfnn, unconstrained.
    #[arg(long, default_value = "proposed")]
    pub variant: String,
    /// Output directory (default: out/<scenario>-<variant>[-<mode>]).
    #[arg(long)]
    pub out: Option<std::path::PathBuf>,
    /// Override a scenario parameter, e.g. `--set controller.position.k_p=1.5` (repeatable).
    #[arg(long = "set", value_name = "PATH=VALUE")]
    pub sets: Vec<String>,
}

impl RunnerArgs {
    /// The validated scenario (after the overrides) and the variant; exit code 2 with clear errors.
    pub fn load(&self) -> Result<(Scenario, formation_config::Variant), ExitCode> {
        let scenario = load_with_overrides(self.scenario.as_deref(), &self.sets)?;
        let name = if self.variant.is_empty() {
            "proposed"
        } else {
            &self.variant
        };
        Ok((scenario, parse_variant(name)?))
    }
}
