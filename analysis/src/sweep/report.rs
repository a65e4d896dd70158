//! What a sweep writes: `sweep.csv` (one row per sample) and `sweep.json` (the summary), and the
//! progress display (a bar on a terminal, plain lines when piped).

use super::spec::Sample;
use formation_runtime::record::Summary;
use serde::Serialize;
use std::io::{IsTerminal, Write};
use std::path::Path;
use std::time::Instant;

/// The figures of one sample that the sweep keeps.
#[derive(Debug, Clone, PartialEq)]
pub struct Metrics {
    /// Largest per-agent RMS formation error in the cover window, m.
    pub rms_cover_m: Option<f64>,
    /// Same, enclose window, m.
    pub rms_enclose_m: Option<f64>,
    /// Attitude plus rate constraint violations (steps, summed over agents).
    pub violations: u64,
    /// Closest approach of two quadrotors over the run, m.
    pub min_separation_m: Option<f64>,
    /// Steps below the safety distance.
    pub steps_below_safety: u64,
    /// Mean covered share of the target disk over the cover window.
    pub coverage: Option<f64>,
    /// The run diverged.
    pub diverged: bool,
    /// The measured events of the run (`summary.json` `events`), summed up.
    pub events: EventMetrics,
}

/// The event figures of one sample (`summary.json` `events[]`, docs/failures.md): worst peak,
/// slowest recovery, summed violations, closest approach. All `None` for a run without events.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct EventMetrics {
    /// Worst `peak_error_m` of the events, m.
    pub peak_error_m: Option<f64>,
    /// Slowest `recovered_after_s`, s (infinite: an event did not recover in its window).
    pub recovered_after_s: Option<f64>,
    /// Sum of `violations_during`.
    pub violations_during: Option<u64>,
    /// Smallest `min_separation_during_m`, m.
    pub min_separation_during_m: Option<f64>,
    /// Sum of `steps_below_safety_during`.
    pub steps_below_safety_during: Option<u64>,
    /// Sum of `violations_once_back`.
    pub violations_once_back: Option<u64>,
}

impl EventMetrics {
    /// The figures of a run's measured events.
    pub fn of(events: &[formation_runtime::record::recovery::EventSummary]) -> EventMetrics {
        if events.is_empty() {
            return EventMetrics::default();
        }
        let sum =
            |f: &dyn Fn(&formation_runtime::record::recovery::EventSummary) -> Option<u64>| {
                events.iter().filter_map(f).reduce(|a, b| a + b)
            };
        EventMetrics {
            peak_error_m: events.iter().map(|e| e.peak_error_m).reduce(f64::max),
            recovered_after_s: events
                .iter()
                .map(|e| e.recovered_after_s.unwrap_or(f64::INFINITY))
                .reduce(f64::max),
            violations_during: sum(&|e| Some(e.violations_during)),
            min_separation_during_m: events
                .iter()
                .filter_map(|e| e.min_separation_during_m)
                .reduce(f64::min),
            steps_below_safety_during: sum(&|e| e.steps_below_safety_during),
            violations_once_back: sum(&|e| e.violations_once_back),
        }
    }
}

impl Metrics {
    /// The kept figures of a run summary.
    pub fn of(s: &Summary) -> Metrics {
        let worst =
            |f: &dyn Fn(&formation_runtime::record::summary::AgentSummary) -> Option<f64>| {
                s.agents.iter().filter_map(f).reduce(f64::max)
            };
        Metrics {
            rms_cover_m: worst(&|a| a.rms_formation_error_m.cover),
            rms_enclose_m: worst(&|a| a.rms_formation_error_m.enclose),
            violations: s
                .agents
                .iter()
                .map(|a| a.attitude_constraint_violations + a.rate_constraint_violations)
                .sum(),
            min_separation_m: s.separation.min_distance.whole.map(|a| a.distance_m),
            steps_below_safety: s.separation.steps_below_safety,
            coverage: s.coverage_fraction,
            diverged: s.diverged,
            events: EventMetrics::of(&s.events),
        }
    }
}

/// Why a sample could not run: its scenario is invalid, or its folder cannot be written.
#[derive(Debug, Clone, thiserror::Error)]
pub enum SampleError {
    /// The sample's values do not make a valid scenario.
    #[error(transparent)]
    Apply(#[from] super::apply::ApplyError),
    /// The sample's folder (`scenario.toml`, `summary.json`) cannot be written.
    #[error("cannot write {}: {source}", dir.display())]
    Write {
        /// The sample's folder.
        dir: std::path::PathBuf,
        /// What the system said (shared: an outcome is cloned).
        source: std::sync::Arc<std::io::Error>,
    },
}

/// One sample's result.
#[derive(Debug, Clone)]
pub struct Outcome {
    /// The sample.
    pub sample: Sample,
    /// Its figures, or why it could not run (invalid scenario, output error).
    pub result: Result<Metrics, SampleError>,
    /// Wall time of the sample, s.
    pub wall_s: f64,
}

impl Outcome {
    /// From the runner's result.
    pub fn new(sample: Sample, run: Result<Summary, SampleError>, wall_s: f64) -> Outcome {
        Outcome {
            sample,
            result: run.map(|s| Metrics::of(&s)),
            wall_s,
        }
    }
}

fn opt(v: Option<f64>) -> String {
    v.map_or(String::new(), |x| format!("{x}"))
}

fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

/// Writes `sweep.csv`: `sample`, the parameters, the figures, `wall_s`, `error`.
pub fn write_csv(path: &Path, names: &[String], outcomes: &[Outcome]) -> std::io::Result<()> {
    let mut text = String::from("sample");
    for n in names {
        text.push(',');
        text.push_str(&csv_field(n));
    }
    text.push_str(",rms_cover_worst_m,rms_enclose_worst_m,violations,min_separation_m,steps_below_safety,coverage_fraction,diverged,peak_error_m,recovered_after_s,violations_during,min_separation_during_m,steps_below_safety_during,violations_once_back,wall_s,error\n");
    for o in outcomes {
        text.push_str(&o.sample.index.to_string());
        for (_, v) in &o.sample.values {
            text.push(',');
            text.push_str(&csv_field(&v.to_string()));
        }
        match &o.result {
            Ok(m) => {
                let e = &m.events;
                let count = |v: Option<u64>| v.map_or(String::new(), |x| x.to_string());
                text.push_str(&format!(
                    ",{},{},{},{},{},{},{},{},{},{},{},{},{},{:.3},\n",
                    opt(m.rms_cover_m),
                    opt(m.rms_enclose_m),
                    m.violations,
                    opt(m.min_separation_m),
                    m.steps_below_safety,
                    opt(m.coverage),
                    m.diverged,
                    opt(e.peak_error_m),
                    opt(e.recovered_after_s),
                    count(e.violations_during),
                    opt(e.min_separation_during_m),
                    count(e.steps_below_safety_during),
                    count(e.violations_once_back),
                    o.wall_s
                ))
            }
            Err(e) => text.push_str(&format!(
                ",,,,,,,,,,,,,,{:.3},{}\n",
                o.wall_s,
                csv_field(&e.to_string())
            )),
        }
    }
    formation_config::node::files::write_atomic(path, text.as_bytes())
}

/// Median, 95th percentile and worst of a figure over the samples that have it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Spread {
    /// Median (the lower middle one for an even count).
    pub median: Option<f64>,
    /// 95th percentile (nearest rank).
    pub p95: Option<f64>,
    /// Largest.
    pub worst: Option<f64>,
    /// Sample with the largest.
    pub worst_sample: Option<usize>,
}

/// Nearest-rank quantile q in (0, 1] of sorted values.
pub fn quantile(sorted: &[f64], q: f64) -> Option<f64> {
    if sorted.is_empty() {
        return None;
    }
    let rank = ((q * sorted.len() as f64).ceil() as usize).clamp(1, sorted.len());
    Some(sorted[rank - 1])
}

impl Spread {
    /// Over (sample, value) pairs; non-finite values are left out.
    pub fn of(values: impl Iterator<Item = (usize, f64)>) -> Spread {
        let mut v: Vec<(usize, f64)> = values.filter(|p| p.1.is_finite()).collect();
        v.sort_by(|a, b| a.1.total_cmp(&b.1));
        let sorted: Vec<f64> = v.iter().map(|p| p.1).collect();
        Spread {
            median: quantile(&sorted, 0.5),
            p95: quantile(&sorted, 0.95),
            worst: sorted.last().copied(),
            worst_sample: v.last().map(|p| p.0),
        }
    }
}

/// How the sweep was set up (copied into the summary).
#[derive(Debug, Clone, Serialize)]
pub struct Setup {
    /// `monte-carlo` or `grid`.
    pub mode: &'static str,
    /// Sampling seed.
    pub seed: u64,
    /// Threads.
    pub jobs: usize,
    /// The `--vary` options as given.
    pub vary: Vec<String>,
    /// Base scenario name.
    pub base: String,
    /// Controller variant.
    pub variant: String,
    /// Wall time of the whole sweep, s.
    pub wall_time_s: f64,
}

/// `sweep.json`.
#[derive(Debug, Clone, Serialize)]
pub struct SweepSummary {
    /// Setup.
    #[serde(flatten)]
    pub setup: Setup,
    /// Samples in the sweep.
    pub samples: usize,
    /// Samples that ran (valid scenario).
    pub ran: usize,
    /// Samples whose scenario was invalid or could not be written.
    pub invalid: usize,
    /// The first such error.
    pub first_error: Option<String>,
    /// Samples that diverged.
    pub divergences: usize,
    /// Their indices.
    pub diverged_samples: Vec<usize>,
    /// Worst RMS cover error per sample, over the samples that did not diverge, m.
    pub rms_cover_m: Spread,
    /// Worst RMS enclose error per sample, over the samples that did not diverge, m.
    pub rms_enclose_m: Spread,
    /// Constraint violations summed over all samples (steps).
    pub violations: u64,
    /// Samples with at least one violation.
    pub samples_with_violations: usize,
    /// Smallest closest approach over all samples, m.
    pub min_separation_m: Option<f64>,
    /// Its sample.
    pub min_separation_sample: Option<usize>,
    /// Samples with a step below the safety distance.
    pub samples_below_safety: usize,
    /// Samples run per second of wall time.
    pub samples_per_s: f64,
    /// Mean wall time of one sample, s.
    pub mean_sample_wall_s: f64,
}

impl SweepSummary {
    /// Summarises the outcomes.
    pub fn build(outcomes: &[Outcome], setup: Setup) -> SweepSummary {
        let ok: Vec<(usize, &Metrics)> = outcomes
            .iter()
            .filter_map(|o| o.result.as_ref().ok().map(|m| (o.sample.index, m)))
            .collect();
        let settled = || ok.iter().filter(|(_, m)| !m.diverged);
        let min_sep = ok
            .iter()
            .filter_map(|(k, m)| m.min_separation_m.map(|d| (*k, d)))
            .min_by(|a, b| a.1.total_cmp(&b.1));
        let wall = setup.wall_time_s;
        SweepSummary {
            samples: outcomes.len(),
            ran: ok.len(),
            invalid: outcomes.len() - ok.len(),
            first_error: outcomes
                .iter()
                .find_map(|o| o.result.as_ref().err().map(|e| e.to_string())),
            divergences: ok.iter().filter(|(_, m)| m.diverged).count(),
            diverged_samples: ok
                .iter()
                .filter(|(_, m)| m.diverged)
                .map(|(k, _)| *k)
                .collect(),
            rms_cover_m: Spread::of(settled().filter_map(|(k, m)| m.rms_cover_m.map(|v| (*k, v)))),
            rms_enclose_m: Spread::of(
                settled().filter_map(|(k, m)| m.rms_enclose_m.map(|v| (*k, v))),
            ),
            violations: ok.iter().map(|(_, m)| m.violations).sum(),
            samples_with_violations: ok.iter().filter(|(_, m)| m.violations > 0).count(),
            min_separation_m: min_sep.map(|p| p.1),
            min_separation_sample: min_sep.map(|p| p.0),
            samples_below_safety: ok.iter().filter(|(_, m)| m.steps_below_safety > 0).count(),
            samples_per_s: if wall > 0.0 {
                outcomes.len() as f64 / wall
            } else {
                0.0
            },
            mean_sample_wall_s: if outcomes.is_empty() {
                0.0
            } else {
                outcomes.iter().map(|o| o.wall_s).sum::<f64>() / outcomes.len() as f64
            },
            setup,
        }
    }

    /// Writes it as pretty JSON.
    pub fn write(&self, path: &Path) -> std::io::Result<()> {
        let text = serde_json::to_string_pretty(self).map_err(std::io::Error::other)?;
        formation_config::node::files::write_atomic(path, (text + "\n").as_bytes())
    }

    /// Prints the human-readable summary.
    pub fn print(&self) {
        let f = |v: Option<f64>| v.map_or("-".to_string(), |x| format!("{x:.3}"));
        println!(
            "{} samples ({} ran, {} invalid) in {:.1} s on {} jobs: {:.2} samples/s",
            self.samples,
            self.ran,
            self.invalid,
            self.setup.wall_time_s,
            self.setup.jobs,
            self.samples_per_s
        );
        for (name, s) in [
            ("cover", &self.rms_cover_m),
            ("enclose", &self.rms_enclose_m),
        ] {
            println!(
                "worst-agent RMS {name}: median {} m, p95 {} m, worst {} m (sample {})",
                f(s.median),
                f(s.p95),
                f(s.worst),
                s.worst_sample.map_or("-".into(), |k| k.to_string())
            );
        }
        println!(
            "divergences {}, violations {} (in {} samples), min separation {} m (sample {}), {} samples below the safety distance",
            self.divergences,
            self.violations,
            self.samples_with_violations,
            f(self.min_separation_m),
            self.min_separation_sample.map_or("-".into(), |k| k.to_string()),
            self.samples_below_safety
        );
        if let Some(e) = &self.first_error {
            println!("first invalid sample: {e}");
        }
    }
}

/// Progress: a bar redrawn in place on a terminal, one plain line per finished sample (at most
/// one every 2 s, and the last) when stderr is not a terminal.
pub struct Progress {
    total: usize,
    done: usize,
    diverged: usize,
    invalid: usize,
    start: Instant,
    last: Option<Instant>,
    tty: bool,
}

impl Progress {
    /// For `total` samples.
    pub fn new(total: usize) -> Progress {
        Progress {
            total,
            done: 0,
            diverged: 0,
            invalid: 0,
            start: Instant::now(),
            last: None,
            tty: std::io::stderr().is_terminal(),
        }
    }

    fn line(&self) -> String {
        let wall = self.start.elapsed().as_secs_f64().max(1e-9);
        let rate = self.done as f64 / wall;
        let eta = if rate > 0.0 {
            (self.total - self.done) as f64 / rate
        } else {
            0.0
        };
        format!(
            "{}/{} samples  {rate:.2}/s  ETA {eta:.0} s  diverged {}  invalid {}",
            self.done, self.total, self.diverged, self.invalid
        )
    }

    /// One more sample finished.
    pub fn done(&mut self, o: &Outcome) {
        self.done += 1;
        match &o.result {
            Ok(m) if m.diverged => self.diverged += 1,
            Ok(_) => {}
            Err(_) => self.invalid += 1,
        }
        let due = self
            .last
            .is_none_or(|t| t.elapsed().as_millis() >= if self.tty { 200 } else { 2000 });
        if !due && self.done < self.total {
            return;
        }
        self.last = Some(Instant::now());
        let mut e = std::io::stderr();
        if self.tty {
            const WIDTH: usize = 30;
            let filled = WIDTH * self.done / self.total.max(1);
            let _ = write!(
                e,
                "\r[{}{}] {}\x1b[K",
                "#".repeat(filled),
                ".".repeat(WIDTH - filled),
                self.line()
            );
            let _ = e.flush();
        } else {
            let _ = writeln!(e, "{}", self.line());
        }
    }

    /// Ends the bar's line.
    pub fn finish(&self) {
        if self.tty {
            eprintln!();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sweep::spec::Value;

    fn outcome(k: usize, rms: f64, diverged: bool) -> Outcome {
        Outcome {
            sample: Sample {
                index: k,
                values: vec![("x".into(), Value::Num(k as f64))],
            },
            result: Ok(Metrics {
                rms_cover_m: Some(rms),
                rms_enclose_m: Some(rms / 2.0),
                violations: k as u64 % 2,
                min_separation_m: Some(1.0 + k as f64),
                steps_below_safety: 0,
                coverage: Some(1.0),
                diverged,
                events: EventMetrics::default(),
            }),
            wall_s: 1.0,
        }
    }

    #[test]
    fn nearest_rank_quantiles_of_one_to_twenty() {
        let v: Vec<f64> = (1..=20).map(f64::from).collect();
        assert_eq!(quantile(&v, 0.5), Some(10.0));
        assert_eq!(quantile(&v, 0.95), Some(19.0));
        assert_eq!(quantile(&v, 1.0), Some(20.0));
        assert_eq!(quantile(&[], 0.5), None);
    }

    #[test]
    fn summary_leaves_diverged_samples_out_of_the_rms_spread_and_counts_them() {
        let mut o: Vec<Outcome> = (0..10)
            .map(|k| outcome(k, 0.1 * (k + 1) as f64, false))
            .collect();
        o.push(outcome(10, 50.0, true));
        o.push(Outcome {
            result: Err(SampleError::Apply(super::super::apply::ApplyError::Set(
                formation_runtime::cli::OverrideError::NoEquals { set: "bad".into() },
            ))),
            ..outcome(11, 0.0, false)
        });
        let s = SweepSummary::build(
            &o,
            Setup {
                mode: "monte-carlo",
                seed: 1,
                jobs: 2,
                vary: vec![],
                base: "paper".into(),
                variant: "proposed".into(),
                wall_time_s: 6.0,
            },
        );
        assert_eq!((s.samples, s.ran, s.invalid, s.divergences), (12, 11, 1, 1));
        assert_eq!(s.diverged_samples, vec![10]);
        assert!((s.rms_cover_m.worst.unwrap() - 1.0).abs() < 1e-12);
        assert_eq!(s.rms_cover_m.worst_sample, Some(9));
        assert!((s.rms_cover_m.median.unwrap() - 0.5).abs() < 1e-12);
        assert_eq!(s.violations, 5);
        assert_eq!(
            (s.min_separation_m, s.min_separation_sample),
            (Some(1.0), Some(0))
        );
        assert_eq!(s.samples_per_s, 2.0);
        assert_eq!(
            s.first_error.as_deref(),
            Some("--set \"bad\": expected path=value")
        );
    }
}
