//! The split lockstep step set against the bare Zenoh fan-out of the same placement
//! (`formation bench --transports zenoh`): the ratio of the two median steps taken within each
//! round, then the median over the rounds, with the split run's real-time factor.

use super::lockstep::{across_rounds, median, Comparison};
use super::row::Row;
use serde::Serialize;

/// Transport of the Zenoh rows.
pub const ZENOH: &str = "zenoh";

/// The split row's `wait` is this followed by the placement (`split 4,5@b`).
pub const SPLIT_WAIT: &str = "split ";

/// What a split run on one machine measures (in the JSON next to the figures).
pub const MEASURES: &str = "one machine: the second host is a formation host daemon in its own \
     mount namespace (its own /dev/shm, no shared memory crosses), linked over Zenoh on \
     loopback (TCP, TLS or QUIC, `--zenoh-link`); both share one kernel and its CPUs, and the link adds no latency of its own";

/// `zenoh_split_vs_fan_out` of the JSON report.
#[derive(Debug, Clone, Serialize)]
pub struct SplitComparison {
    /// The lockstep rows' figures against the fan-out's (`lockstep_*`: the split run).
    #[serde(flatten)]
    pub steps: Comparison,
    /// Agents on the second host (`formation run --place`).
    pub placement: String,
    /// Simulated time over wall time of the median split step (1 ms steps), median over rounds.
    pub realtime_factor: f64,
    /// The same for the mean split step.
    pub realtime_factor_mean: f64,
    /// What the figures measure on one machine.
    pub measures: &'static str,
}

/// Real-time factor of a lockstep step of `step_us` at the paper's time step.
pub fn realtime_factor(step_us: f64) -> f64 {
    1e6 * formation_config::Scenario::paper().simulation.dt_s / step_us
}

/// Whether a row belongs to the split comparison (the Zenoh lockstep and fan-out rows; not the
/// ping-pong).
pub fn is_split_row(r: &Row) -> bool {
    r.transport == ZENOH && (r.pattern == "lockstep" || r.pattern == "fan-out")
}

/// The rounds without the Zenoh rows (what the iceoryx2 comparisons are made of).
pub fn without_zenoh(rounds: &[Vec<Row>]) -> Vec<Vec<Row>> {
    rounds
        .iter()
        .map(|r| r.iter().filter(|r| r.transport != ZENOH).cloned().collect())
        .collect()
}

/// The split lockstep against the bare Zenoh fan-out over the rounds that have both; `None`
/// when no round has both.
pub fn split_vs_fan_out(rounds: &[Vec<Row>]) -> Option<SplitComparison> {
    let split: Vec<Vec<Row>> = rounds
        .iter()
        .map(|r| r.iter().filter(|r| is_split_row(r)).cloned().collect())
        .collect();
    let steps = across_rounds(&split).into_iter().next()?;
    let placement = split
        .iter()
        .flatten()
        .find(|r| r.pattern == "lockstep")
        .map(|r| r.wait.trim_start_matches(SPLIT_WAIT).to_string())
        .unwrap_or_default();
    let per_round = |f: fn(&Row) -> f64| {
        let v: Vec<f64> = split
            .iter()
            .flatten()
            .filter(|r| r.pattern == "lockstep")
            .map(|r| realtime_factor(f(r)))
            .collect();
        median(&v)
    };
    Some(SplitComparison {
        realtime_factor: round2(per_round(|r| r.p50_us)),
        realtime_factor_mean: round2(per_round(|r| r.mean_us)),
        placement,
        measures: MEASURES,
        steps,
    })
}

fn round2(x: f64) -> f64 {
    (x * 100.0).round() / 100.0
}

/// The comparison's lines of the text report.
pub fn text(c: &SplitComparison) -> String {
    format!(
        "n={} split {} (Zenoh over loopback, `--zenoh-link`): lockstep step / bare Zenoh fan-out of the same \
         placement, over {} round(s): median steps {:.1} / {:.1} µs; ratio of the medians within \
         a round: {:.2}x (median; range {:.2}-{:.2}x), of the means: {:.2}x; real time {:.2}x \
         (median step), {:.2}x (mean step)\n  ({MEASURES})\n",
        c.steps.n,
        c.placement,
        c.steps.rounds,
        c.steps.lockstep_p50_us,
        c.steps.fan_out_p50_us,
        c.steps.ratio_p50,
        c.steps.ratio_min,
        c.steps.ratio_max,
        c.steps.ratio_mean,
        c.realtime_factor,
        c.realtime_factor_mean
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(transport: &str, pattern: &str, wait: &str, n: usize, p50: f64) -> Row {
        Row {
            transport: transport.into(),
            pattern: pattern.into(),
            wait: wait.into(),
            n,
            payload_bytes: 16,
            payload_up_bytes: 16,
            p50_us: p50,
            mean_us: p50 * 1.1,
            p99_us: p50 * 2.0,
            p999_us: p50 * 3.0,
            max_us: p50 * 4.0,
            samples: 100,
        }
    }

    #[test]
    fn the_split_step_is_set_against_the_zenoh_fan_out_round_by_round_and_not_the_iceoryx2_ones() {
        let round = |fan: f64, split: f64| {
            vec![
                row("iox2-event", "fan-out", "block", 5, 40.0),
                row("iox2-event", "lockstep", "block/pinned/batch", 5, 80.0),
                row("zenoh", "ping-pong", "block", 1, 90.0),
                row("zenoh", "fan-out", "block", 5, fan),
                row("zenoh", "lockstep", "split 4,5@b", 5, split),
            ]
        };
        let rounds = vec![
            round(200.0, 500.0),
            round(400.0, 800.0),
            round(250.0, 500.0),
        ];
        let c = split_vs_fan_out(&rounds).unwrap();
        assert_eq!(c.steps.ratios, vec![2.5, 2.0, 2.0]);
        assert_eq!((c.steps.ratio, c.steps.rounds), (2.0, 3));
        assert_eq!(
            (c.steps.lockstep_p50_us, c.steps.fan_out_p50_us),
            (500.0, 250.0)
        );
        // 1 ms steps: a 500 µs step runs at twice real time.
        assert_eq!(c.realtime_factor, 2.0);
        assert_eq!(c.placement, "4,5@b");
        let rest = without_zenoh(&rounds);
        assert!(rest.iter().flatten().all(|r| r.transport == "iox2-event"));
        assert!(split_vs_fan_out(&rest).is_none());
        let json = serde_json::to_value(&c).unwrap();
        for key in [
            "lockstep_p50_us",
            "fan_out_p50_us",
            "ratio",
            "realtime_factor",
            "placement",
        ] {
            assert!(!json[key].is_null(), "{key} in {json}");
        }
    }
}
