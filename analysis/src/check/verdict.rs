//! Verdicts: one OK / WARN / FAIL line per check, with a short reason.

use serde::Serialize;

/// How a check came out.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum Level {
    /// The condition holds with margin.
    #[serde(rename = "OK")]
    Ok,
    /// A sufficient condition of the paper's proof is not met: information, not a prediction
    /// that the design will not fly (sufficient conditions are conservative).
    #[serde(rename = "INFO")]
    Info,
    /// A rule of thumb is broken: the gains may still work, but expect trouble.
    #[serde(rename = "WARN")]
    Warn,
    /// The analysis predicts that the design will not fly: no stabilising feedback on the graph
    /// (Lemma 1), no leader-information window, or a loop of the flown gain set with no time-scale
    /// separation or phase margin.
    #[serde(rename = "FAIL")]
    Fail,
}

impl Level {
    /// The label printed in the text report.
    pub fn label(self) -> &'static str {
        match self {
            Level::Ok => "OK",
            Level::Info => "INFO",
            Level::Warn => "WARN",
            Level::Fail => "FAIL",
        }
    }
}

/// One verdict line.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Verdict {
    /// Stable name of the check, e.g. `theorem1.m_positive_definite`.
    pub check: String,
    /// The outcome.
    pub level: Level,
    /// Why, with the deciding numbers.
    pub why: String,
}

impl Verdict {
    /// Builds a verdict.
    pub fn new(check: &str, level: Level, why: impl Into<String>) -> Verdict {
        Verdict {
            check: check.to_string(),
            level,
            why: why.into(),
        }
    }
}

/// Time-scale separation of a cascade: OK when `ratio >= good`, WARN when `1 <= ratio < good`,
/// FAIL when the inner loop is slower than the loop around it (`ratio < 1`, or not a number).
pub fn separation_level(ratio: f64, good: f64) -> Level {
    if ratio >= good {
        Level::Ok
    } else if ratio >= 1.0 {
        Level::Warn
    } else {
        Level::Fail
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn separation_levels_split_at_one_and_good() {
        assert_eq!(separation_level(5.0, 3.0), Level::Ok);
        assert_eq!(separation_level(2.0, 3.0), Level::Warn);
        assert_eq!(separation_level(0.5, 3.0), Level::Fail);
        assert_eq!(separation_level(f64::NAN, 3.0), Level::Fail);
    }

    #[test]
    fn information_ranks_above_ok_and_below_a_warning() {
        let worst = |l: &[Level]| l.iter().copied().max_by_key(|l| *l as u8).unwrap();
        assert_eq!(worst(&[Level::Ok, Level::Info]), Level::Info);
        assert_eq!(worst(&[Level::Info, Level::Warn]), Level::Warn);
        assert_eq!(serde_json::to_string(&Level::Info).unwrap(), "\"INFO\"");
    }

    #[test]
    fn levels_serialise_as_upper_case_labels() {
        assert_eq!(serde_json::to_string(&Level::Warn).unwrap(), "\"WARN\"");
        assert_eq!(Level::Fail.label(), "FAIL");
    }
}
