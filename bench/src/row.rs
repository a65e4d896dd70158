//! One measured case of `formation bench`, summarised: the row of the table and the JSON object.

use super::link::Sizes;
use super::plan::Case;
use hdrhistogram::Histogram;
use serde::Serialize;

/// One result row (also the JSON object of one case).
#[derive(Debug, Clone, Serialize)]
pub struct Row {
    /// Transport name.
    pub transport: String,
    /// `ping-pong` (full round trip per sample) or `fan-out` (one step per sample).
    pub pattern: String,
    /// Waiting strategy and CPU placement.
    pub wait: String,
    /// Agent processes.
    pub n: usize,
    /// Message size plant -> agent, bytes.
    pub payload_bytes: usize,
    /// Message size agent -> plant, bytes.
    pub payload_up_bytes: usize,
    /// Median, µs.
    pub p50_us: f64,
    /// Mean, µs (for lockstep: steady-state wall time per step).
    pub mean_us: f64,
    /// 99th percentile, µs.
    pub p99_us: f64,
    /// 99.9th percentile, µs.
    pub p999_us: f64,
    /// Largest sample, µs.
    pub max_us: f64,
    /// Samples recorded (after the warm-up).
    pub samples: u64,
}

fn us(ns: f64) -> f64 {
    (ns / 100.0).round() / 10.0
}

impl Row {
    /// Summarises the histogram (values in ns) of `case`.
    pub fn new(case: &Case, sizes: Sizes, h: &Histogram<u64>) -> Row {
        Row::of(
            (
                case.transport.name(),
                case.pattern.name(),
                &case.wait_label(),
            ),
            case.n,
            sizes,
            h,
        )
    }

    /// Summarises the histogram (values in ns) of a case named (transport, pattern, wait).
    pub fn of(
        (transport, pattern, wait): (&str, &str, &str),
        n: usize,
        sizes: Sizes,
        h: &Histogram<u64>,
    ) -> Row {
        Row {
            transport: transport.to_string(),
            pattern: pattern.to_string(),
            wait: wait.to_string(),
            n,
            payload_bytes: sizes.down,
            payload_up_bytes: sizes.up,
            p50_us: us(h.value_at_quantile(0.5) as f64),
            mean_us: us(h.mean()),
            p99_us: us(h.value_at_quantile(0.99) as f64),
            p999_us: us(h.value_at_quantile(0.999) as f64),
            max_us: us(h.max() as f64),
            samples: h.len(),
        }
    }
}
