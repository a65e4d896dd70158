//! Latency histograms of a realtime run (and the step-time histogram of a lockstep run). Each role process records into fixed-size HDR histograms
//! (no allocation per sample) and, at the end, writes them as one small JSON file into
//! `<run dir>/timing/`; the orchestrator merges the files into `summary.json`.

use super::error::NodeError;
use hdrhistogram::Histogram;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Largest value a histogram holds, ns (larger samples are clamped to it): 60 s.
const HIGHEST_NS: u64 = 60_000_000_000;

/// An HDR histogram of durations in ns, 3 significant digits, allocated once.
#[derive(Debug, Clone)]
pub struct NsHistogram {
    h: Histogram<u64>,
}

impl Default for NsHistogram {
    fn default() -> Self {
        NsHistogram::new()
    }
}

impl NsHistogram {
    /// An empty histogram covering 1 ns .. 60 s.
    pub fn new() -> NsHistogram {
        // Constant, valid bounds: this cannot fail whatever the input.
        let h = Histogram::new_with_bounds(1, HIGHEST_NS, 3).expect("valid histogram bounds");
        NsHistogram { h }
    }

    /// Records one duration (clamped to the covered range).
    pub fn record(&mut self, ns: u64) {
        self.h.saturating_record(ns.min(HIGHEST_NS));
    }

    /// Records `count` samples of one duration (clamped to the covered range).
    pub fn record_n(&mut self, ns: u64, count: u64) {
        self.h.saturating_record_n(ns.min(HIGHEST_NS), count);
    }

    /// Number of samples.
    pub fn len(&self) -> u64 {
        self.h.len()
    }

    /// True when no sample was recorded.
    pub fn is_empty(&self) -> bool {
        self.h.is_empty()
    }

    /// Adds every sample of `other`.
    pub fn merge(&mut self, other: &NsHistogram) {
        for v in other.h.iter_recorded() {
            self.h
                .saturating_record_n(v.value_iterated_to().min(HIGHEST_NS), v.count_at_value());
        }
    }

    /// The value at quantile `q` in [0, 1], ns.
    pub fn quantile(&self, q: f64) -> u64 {
        self.h.value_at_quantile(q)
    }

    /// The largest sample, ns.
    pub fn max(&self) -> u64 {
        self.h.max()
    }

    /// Non-empty buckets as (value, count) pairs: the file format.
    fn buckets(&self) -> Vec<(u64, u64)> {
        self.h
            .iter_recorded()
            .map(|v| (v.value_iterated_to(), v.count_at_value()))
            .collect()
    }

    fn from_buckets(b: &[(u64, u64)]) -> NsHistogram {
        let mut out = NsHistogram::new();
        for &(v, c) in b {
            out.h.saturating_record_n(v.min(HIGHEST_NS), c);
        }
        out
    }
}

/// What one process measured: named histograms and counters.
#[derive(Debug, Default, Clone)]
pub struct TimingReport {
    /// Histograms by name, e.g. `state_hop`.
    pub histograms: BTreeMap<String, NsHistogram>,
    /// Counters by name, e.g. `deadline_misses`.
    pub counters: BTreeMap<String, u64>,
}

/// The directory of the timing files of a run.
pub fn dir(run_dir: &Path) -> PathBuf {
    run_dir.join("timing")
}

impl TimingReport {
    /// Writes the report to `<run dir>/timing/<name>.json`.
    pub fn write(&self, run_dir: &Path, name: &str) -> Result<(), NodeError> {
        let d = dir(run_dir);
        super::files::ensure_private_dir(&d)
            .map_err(|e| file_error(&d, "cannot create", std::io::Error::from(e)))?;
        let hist: serde_json::Map<String, serde_json::Value> = self
            .histograms
            .iter()
            .map(|(k, h)| (k.clone(), serde_json::json!(h.buckets())))
            .collect();
        let v = serde_json::json!({ "histograms": hist, "counters": self.counters });
        let path = d.join(format!("{name}.json"));
        super::files::write_atomic(&path, v.to_string().as_bytes())
            .map_err(|e| file_error(&path, "cannot write", e))
    }

    /// Reads a report written by [`TimingReport::write`].
    pub fn read(path: &Path) -> Result<TimingReport, NodeError> {
        let text = std::fs::read_to_string(path).map_err(|e| file_error(path, "cannot read", e))?;
        let v: serde_json::Value =
            serde_json::from_str(&text).map_err(|e| file_error(path, "cannot parse", e))?;
        let mut out = TimingReport::default();
        if let Some(h) = v.get("histograms").and_then(|h| h.as_object()) {
            for (k, b) in h {
                let pairs: Vec<(u64, u64)> = serde_json::from_value(b.clone())
                    .map_err(|e| file_error(path, &format!("histogram {k}"), e))?;
                out.histograms
                    .insert(k.clone(), NsHistogram::from_buckets(&pairs));
            }
        }
        if let Some(c) = v.get("counters").and_then(|c| c.as_object()) {
            for (k, n) in c {
                out.counters.insert(k.clone(), n.as_u64().unwrap_or(0));
            }
        }
        Ok(out)
    }
}

fn file_error(path: &Path, what: &str, e: impl std::fmt::Display) -> NodeError {
    NodeError::File {
        path: path.to_path_buf(),
        detail: format!("{what}: {e}"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_report_survives_the_file_round_trip() {
        let dir = std::env::temp_dir().join(format!("fm-timing-test-{}", std::process::id()));
        let mut h = NsHistogram::new();
        for v in [1_000, 2_000, 3_000, 150_000] {
            h.record(v);
        }
        let mut r = TimingReport::default();
        r.histograms.insert("hop".into(), h.clone());
        r.counters.insert("misses".into(), 7);
        r.write(&dir, "plant").unwrap();
        let back = TimingReport::read(&dir.join("timing/plant.json")).unwrap();
        let b = &back.histograms["hop"];
        assert_eq!(b.len(), 4);
        assert_eq!(b.max(), h.max());
        assert_eq!(b.quantile(0.5), h.quantile(0.5));
        assert_eq!(back.counters["misses"], 7);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn merging_adds_the_samples() {
        let mut a = NsHistogram::new();
        let mut b = NsHistogram::new();
        a.record(10);
        b.record(1_000_000);
        a.merge(&b);
        assert_eq!(a.len(), 2);
        assert!(a.max() >= 999_000);
    }
}
