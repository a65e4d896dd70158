//! Bounded logs for what arrives from the network: a flood of hostile or malformed messages must
//! not become a flood of log lines. [`LogLimit`] prints at most one line per second per source
//! and reason, and says how many like it it held back.

use std::collections::HashMap;
use std::time::{Duration, Instant};

/// At most one line per this period per (source, reason).
pub const PERIOD: Duration = Duration::from_secs(1);

/// Distinct (source, reason) pairs remembered; beyond it every new pair counts as one source
/// (`other`), so the table stays bounded whatever the senders call themselves.
pub const MAX_KEYS: usize = 64;

#[derive(Debug)]
struct Entry {
    last: Instant,
    held: u64,
}

/// A rate limiter of log lines (see the module documentation). Pure: the caller prints.
#[derive(Debug, Default)]
pub struct LogLimit {
    entries: HashMap<(String, &'static str), Entry>,
}

impl LogLimit {
    /// The line to print for a message from `source` refused for `reason` at `now`, if one is due:
    /// `line()` with, when lines were held back since the last one, how many.
    pub fn line(
        &mut self,
        now: Instant,
        source: &str,
        reason: &'static str,
        line: impl FnOnce() -> String,
    ) -> Option<String> {
        let source = if self.entries.len() >= MAX_KEYS
            && !self.entries.contains_key(&(source.to_string(), reason))
        {
            "other"
        } else {
            source
        };
        match self.entries.get_mut(&(source.to_string(), reason)) {
            Some(e) if now.duration_since(e.last) < PERIOD => {
                e.held += 1;
                None
            }
            Some(e) => {
                let held = std::mem::take(&mut e.held);
                e.last = now;
                Some(with_held(line(), held))
            }
            None => {
                self.entries
                    .insert((source.to_string(), reason), Entry { last: now, held: 0 });
                Some(line())
            }
        }
    }

    /// Prints [`LogLimit::line`] as a warning (`tracing`), if one is due.
    pub fn warn(&mut self, source: &str, reason: &'static str, line: impl FnOnce() -> String) {
        if let Some(l) = self.line(Instant::now(), source, reason, line) {
            tracing::warn!("{l}");
        }
    }

    /// Prints [`LogLimit::line`] on standard error (the daemon's log), if one is due.
    pub fn eprint(&mut self, source: &str, reason: &'static str, line: impl FnOnce() -> String) {
        if let Some(l) = self.line(Instant::now(), source, reason, line) {
            eprintln!("{l}");
        }
    }
}

fn with_held(line: String, held: u64) -> String {
    if held == 0 {
        line
    } else {
        format!("{line} (and {held} more like it held back)")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_flood_gives_one_line_per_second_per_source_and_reason_with_a_count() {
        let mut l = LogLimit::default();
        let t0 = Instant::now();
        let mut lines = Vec::new();
        // 1000 refusals over 2.5 s from one source for one reason.
        for k in 0..1000u64 {
            let t = t0 + Duration::from_micros(k * 2500);
            if let Some(s) = l.line(t, "x", "bad tag", || "refused".into()) {
                lines.push(s);
            }
        }
        assert_eq!(lines.len(), 3, "{lines:?}");
        assert_eq!(lines[0], "refused");
        assert!(lines[1].contains("held back"), "{lines:?}");
        // Another reason or source has its own line.
        assert!(l.line(t0, "x", "malformed", || "m".into()).is_some());
        assert!(l.line(t0, "y", "bad tag", || "y".into()).is_some());
    }

    #[test]
    fn the_table_stays_bounded_whatever_the_sources_are_called() {
        let mut l = LogLimit::default();
        let t0 = Instant::now();
        let printed = (0..10_000)
            .filter(|k| l.line(t0, &format!("s{k}"), "r", || "x".into()).is_some())
            .count();
        assert!(l.entries.len() <= MAX_KEYS + 1);
        assert_eq!(
            printed,
            MAX_KEYS + 1,
            "the sources beyond the table share one line"
        );
    }
}
