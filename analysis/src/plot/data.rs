//! Loading a run directory: `trajectory.csv` (columns read by name) and the optional `summary.json`.

use super::PlotError;
use formation_runtime::record::csv::Column;
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// Columns every figure family together needs (docs/formats.md).
pub const REQUIRED_COLUMNS: &[Column] = &[
    Column::T,
    Column::Agent,
    Column::Px,
    Column::Py,
    Column::Pz,
    Column::Phi,
    Column::Theta,
    Column::Ex,
    Column::Ey,
    Column::Ez,
    Column::Tx,
    Column::Ty,
    Column::Thrust,
    Column::PhiC,
    Column::ThetaC,
    Column::AttNorm,
    Column::AttCmdNorm,
    Column::C1Bar,
    Column::RateNorm,
    Column::AlphaNorm,
    Column::C2Bar,
    Column::UAX,
    Column::UAY,
    Column::UAZ,
    Column::GammaX,
    Column::GammaY,
    Column::GammaZ,
    Column::GammaHatX,
    Column::GammaHatY,
    Column::GammaHatZ,
    Column::DeltaX,
    Column::DeltaY,
    Column::DeltaZ,
    Column::DeltaHatX,
    Column::DeltaHatY,
    Column::DeltaHatZ,
    Column::DNorm,
    Column::DHat,
    Column::FX,
    Column::FY,
    Column::FZ,
    Column::FHatX,
    Column::FHatY,
    Column::FHatZ,
    Column::SepUx,
    Column::SepUy,
    Column::SepUz,
];

/// The time series of one agent: one vector per column of [`REQUIRED_COLUMNS`].
#[derive(Debug, Clone)]
pub struct AgentTrace {
    /// Agent index as written in the CSV (1-based).
    pub id: u32,
    columns: Vec<Vec<f64>>,
}

/// One run directory, loaded.
#[derive(Debug, Clone)]
pub struct Run {
    /// The directory it was read from.
    pub dir: PathBuf,
    /// `scenario` from `summary.json`, if present.
    pub scenario: Option<String>,
    /// `variant` from `summary.json`, if present.
    pub variant: Option<String>,
    /// Agents in ascending index order.
    pub agents: Vec<AgentTrace>,
    /// The events of `summary.json` (time, label), for the events figure.
    pub events: Vec<(f64, String)>,
}

fn column_index(c: Column) -> usize {
    REQUIRED_COLUMNS
        .iter()
        .position(|r| *r == c)
        .unwrap_or_else(|| panic!("internal: column '{}' is not in REQUIRED_COLUMNS", c.name()))
}

impl AgentTrace {
    /// The values of a required column (panics only on a programming error: a column missing from
    /// [`REQUIRED_COLUMNS`], never on user input, which is validated at load time).
    pub fn col(&self, c: Column) -> &[f64] {
        &self.columns[column_index(c)]
    }

    /// Time stamps, s.
    pub fn t(&self) -> &[f64] {
        self.col(Column::T)
    }

    /// (t, column) pairs.
    pub fn series(&self, c: Column) -> Vec<(f64, f64)> {
        self.t()
            .iter()
            .copied()
            .zip(self.col(c).iter().copied())
            .collect()
    }

    /// (t, f(row)) pairs for a function of several columns.
    pub fn derived(&self, columns: &[Column], f: impl Fn(&[f64]) -> f64) -> Vec<(f64, f64)> {
        let cols: Vec<&[f64]> = columns.iter().map(|c| self.col(*c)).collect();
        let mut row = vec![0.0; cols.len()];
        (0..self.t().len())
            .map(|k| {
                for (r, c) in row.iter_mut().zip(&cols) {
                    *r = c[k];
                }
                (self.t()[k], f(&row))
            })
            .collect()
    }
}

impl Run {
    /// Loads `DIR/trajectory.csv` and, if present, `DIR/summary.json`.
    pub fn load(dir: &Path) -> Result<Run, PlotError> {
        if !dir.is_dir() {
            return Err(PlotError::Input(format!(
                "run directory '{}' does not exist or is not a directory",
                dir.display()
            )));
        }
        let csv = dir.join("trajectory.csv");
        let text = std::fs::read_to_string(&csv)
            .map_err(|e| PlotError::Input(format!("cannot read '{}': {e}", csv.display())))?;
        let agents =
            parse_csv(&text).map_err(|e| PlotError::Input(format!("{}: {e}", csv.display())))?;
        let (scenario, variant) = read_summary(&dir.join("summary.json"));
        Ok(Run {
            dir: dir.to_path_buf(),
            scenario,
            variant,
            agents,
            events: read_events(&dir.join("summary.json")),
        })
    }

    /// A short name for titles and legends: the variant, else the scenario, else the directory name.
    pub fn label(&self) -> String {
        self.variant
            .clone()
            .or_else(|| self.scenario.clone())
            .or_else(|| {
                self.dir
                    .file_name()
                    .map(|n| n.to_string_lossy().into_owned())
            })
            .unwrap_or_else(|| "run".to_string())
    }

    /// "scenario / variant" for figure titles (whatever is known).
    pub fn title(&self) -> String {
        match (&self.scenario, &self.variant) {
            (Some(s), Some(v)) => format!("scenario {s}, variant {v}"),
            (Some(s), None) => format!("scenario {s}"),
            (None, Some(v)) => format!("variant {v}"),
            (None, None) => self.label(),
        }
    }

    /// First and last time stamp over all agents.
    pub fn time_span(&self) -> (f64, f64) {
        let mut lo = f64::INFINITY;
        let mut hi = f64::NEG_INFINITY;
        for a in &self.agents {
            for &t in a.t() {
                if t.is_finite() {
                    lo = lo.min(t);
                    hi = hi.max(t);
                }
            }
        }
        if lo <= hi {
            (lo, hi)
        } else {
            (0.0, 1.0)
        }
    }
}

/// Why a `trajectory.csv` does not parse: the line and column, and what failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CsvError {
    /// No header.
    #[error("the file is empty (no header)")]
    Empty,
    /// Columns the figures need are absent.
    #[error("missing column(s): {}", .0.join(", "))]
    Missing(Vec<&'static str>),
    /// A row with another number of fields than the header.
    #[error("line {line}: {fields} fields, the header has {header}")]
    Fields {
        /// The line (1-based).
        line: usize,
        /// Its fields.
        fields: usize,
        /// The header's fields.
        header: usize,
    },
    /// A cell that is not a number.
    #[error("line {line}: column '{column}': not a number: '{cell}'")]
    Number {
        /// The line (1-based).
        line: usize,
        /// The column.
        column: &'static str,
        /// The cell.
        cell: String,
    },
    /// An agent index that is not a positive integer.
    #[error("line {line}: agent index must be a positive integer, got {got}")]
    Agent {
        /// The line (1-based).
        line: usize,
        /// The value.
        got: f64,
    },
    /// A header and no row.
    #[error("no data rows after the header")]
    NoRows,
}

/// Parses the long-format CSV into per-agent column vectors. Errors name the line and column.
fn parse_csv(text: &str) -> Result<Vec<AgentTrace>, CsvError> {
    let mut lines = text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty());
    let (_, header) = lines.next().ok_or(CsvError::Empty)?;
    let names: Vec<&str> = header.split(',').map(str::trim).collect();
    let index: HashMap<&str, usize> = names.iter().enumerate().map(|(i, n)| (*n, i)).collect();
    let missing: Vec<&'static str> = REQUIRED_COLUMNS
        .iter()
        .map(|c| c.name())
        .filter(|c| !index.contains_key(c))
        .collect();
    if !missing.is_empty() {
        return Err(CsvError::Missing(missing));
    }
    let wanted: Vec<usize> = REQUIRED_COLUMNS.iter().map(|c| index[c.name()]).collect();
    let agent_col = column_index(Column::Agent);

    let mut by_agent: Vec<AgentTrace> = Vec::new();
    let mut values = vec![0.0; REQUIRED_COLUMNS.len()];
    for (lineno, line) in lines {
        let cells: Vec<&str> = line.split(',').map(str::trim).collect();
        if cells.len() != names.len() {
            return Err(CsvError::Fields {
                line: lineno + 1,
                fields: cells.len(),
                header: names.len(),
            });
        }
        for (v, (&src, name)) in values.iter_mut().zip(wanted.iter().zip(REQUIRED_COLUMNS)) {
            *v = parse_number(cells[src]).ok_or_else(|| CsvError::Number {
                line: lineno + 1,
                column: name.name(),
                cell: cells[src].to_string(),
            })?;
        }
        let a = values[agent_col];
        if !(a >= 1.0 && a.fract() == 0.0 && a < u32::MAX as f64) {
            return Err(CsvError::Agent {
                line: lineno + 1,
                got: a,
            });
        }
        let id = a as u32;
        let trace = match by_agent.iter_mut().position(|t| t.id == id) {
            Some(p) => &mut by_agent[p],
            None => {
                by_agent.push(AgentTrace {
                    id,
                    columns: vec![Vec::new(); REQUIRED_COLUMNS.len()],
                });
                let last = by_agent.len() - 1;
                &mut by_agent[last]
            }
        };
        for (c, v) in trace.columns.iter_mut().zip(&values) {
            c.push(*v);
        }
    }
    if by_agent.is_empty() {
        return Err(CsvError::NoRows);
    }
    by_agent.sort_by_key(|t| t.id);
    Ok(by_agent)
}

/// A number, accepting the usual spellings of non-finite values (which are then skipped when drawn).
fn parse_number(s: &str) -> Option<f64> {
    match s.to_ascii_lowercase().as_str() {
        "" | "nan" | "-nan" => Some(f64::NAN),
        _ => s.parse().ok(),
    }
}

/// `scenario` and `variant` of `summary.json`; absent or unreadable files give `None`s.
fn read_summary(path: &Path) -> (Option<String>, Option<String>) {
    let Ok(text) = std::fs::read_to_string(path) else {
        return (None, None);
    };
    let Ok(v) = serde_json::from_str::<serde_json::Value>(&text) else {
        eprintln!(
            "warning: '{}' is not valid JSON; ignoring it",
            path.display()
        );
        return (None, None);
    };
    let field = |k: &str| match v.get(k) {
        Some(serde_json::Value::String(s)) => Some(s.clone()),
        Some(serde_json::Value::Object(o)) => {
            o.get("name").and_then(|n| n.as_str()).map(str::to_string)
        }
        _ => None,
    };
    (field("scenario"), field("variant"))
}

/// The events of a `summary.json` as (at_s, label) pairs: `crash 3`, `link_down 2-3`.
fn read_events(path: &Path) -> Vec<(f64, String)> {
    let v: serde_json::Value = std::fs::read_to_string(path)
        .ok()
        .and_then(|t| serde_json::from_str(&t).ok())
        .unwrap_or_default();
    let Some(list) = v.get("events").and_then(|e| e.as_array()) else {
        return Vec::new();
    };
    list.iter()
        .filter_map(|e| {
            let t = e.get("at_s")?.as_f64()?;
            let kind = e.get("kind")?.as_str()?;
            let who = match (e.get("agents").and_then(|a| a.as_array()), e.get("agent")) {
                (Some(a), _) if a.len() == 2 => format!(" {}-{}", a[0], a[1]),
                (_, Some(a)) if a.is_u64() => format!(" {a}"),
                _ => String::new(),
            };
            Some((t, format!("{kind}{who}")))
        })
        .collect()
}
