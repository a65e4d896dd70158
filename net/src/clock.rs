//! Clocks of the hosts of a run, and the one-way delay of every cross-host link.
//!
//! Realtime messages are stamped with the sender's `CLOCK_MONOTONIC` (`sent_ns`). Each machine
//! has its own monotonic clock (its own origin: the boot), so a stamp from another host means
//! nothing until it is translated. Before a run the orchestrator estimates the offset of every
//! daemon's monotonic clock from its own, NTP style: it sends [`PROBES`] requests on
//! [`crate::proto::clock_key`], each answered at once (in Zenoh's receiving thread) with the daemon's
//! clock, and keeps the probe of the shortest round trip, whose midpoint is the least uncertain
//! ([`estimate`]). The offsets travel with the run request; each bridge translates the stamp of
//! every forwarded message into its own clock ([`shift_ns`]) before it publishes it, and measures
//! the one-way delay of the link (its clock now minus the translated stamp) per (sending host,
//! receiving host) pair.
//!
//! On one machine (the namespaces of the tests) every offset is about 0; nothing here assumes it.

use formation_config::node::timing::NsHistogram;

/// Probes per host at the handshake.
pub const PROBES: usize = 16;

/// One request/response of the clock probe: the orchestrator's clock when it asked (`t0`) and
/// when the answer came (`t3`), and the daemon's clock when it answered (`remote`); ns.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Probe {
    /// Local clock at the request, ns.
    pub t0: u64,
    /// Remote clock when it answered, ns.
    pub remote: u64,
    /// Local clock at the answer, ns.
    pub t3: u64,
}

/// A host's clock relative to the orchestrator's.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Offset {
    /// Remote clock minus local clock, ns.
    pub offset_ns: i64,
    /// Round trip of the probe used, ns.
    pub rtt_ns: u64,
    /// Bound on the error of `offset_ns`: half that round trip, ns (the true offset lies within
    /// `offset_ns ± uncertainty_ns` whatever the asymmetry of the two directions).
    pub uncertainty_ns: u64,
}

/// The offset from the probe of the shortest round trip: remote − (t0 + t3) / 2. `None` without a
/// valid probe (t3 < t0).
pub fn estimate(probes: &[Probe]) -> Option<Offset> {
    let best = probes
        .iter()
        .filter(|p| p.t3 >= p.t0)
        .min_by_key(|p| p.t3 - p.t0)?;
    let rtt = best.t3 - best.t0;
    let mid = best.t0 as i128 + rtt as i128 / 2;
    Some(Offset {
        offset_ns: (best.remote as i128 - mid) as i64,
        rtt_ns: rtt,
        uncertainty_ns: rtt / 2,
    })
}

/// What to add to a stamp of host `from` to read it on host `to`'s clock, given each host's
/// offset from the launcher's clock (`clock_h − clock_launcher`).
pub fn shift_ns(offset_from: i64, offset_to: i64) -> i64 {
    offset_to - offset_from
}

/// A stamp of another host on this host's clock (0 stays 0: lockstep messages carry no stamp).
pub fn translate(sent_ns: u64, shift: i64) -> u64 {
    if sent_ns == 0 {
        0
    } else {
        (sent_ns as i128 + shift as i128).max(1) as u64
    }
}

/// Name of the link from host `from` to host `to` in reports: `local->b`.
pub fn link_name(from: &str, to: &str) -> String {
    format!("{from}->{to}")
}

/// The one-way delays of one link.
#[derive(Debug, Clone, Default)]
pub struct LinkDelays {
    /// Delays ≥ 0, ns.
    pub delays: NsHistogram,
    /// Messages that seemed to arrive before they were sent (a negative delay: the clock offset
    /// was off by more than the delay); counted, not in `delays`.
    pub negative: u64,
}

impl LinkDelays {
    /// Records the delay of one message: `now` and the translated send stamp, on this host's
    /// clock. A message without a stamp (0) is not a measurement.
    pub fn record(&mut self, sent_here_ns: u64, now_ns: u64) {
        if sent_here_ns == 0 {
            return;
        }
        if now_ns >= sent_here_ns {
            self.delays.record(now_ns - sent_here_ns);
        } else {
            self.negative += 1;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_offset_comes_from_the_probe_of_the_shortest_round_trip() {
        // Remote clock = local + 5 ms. Probe 1: slow request (queueing) → a biased midpoint;
        // probe 2: 100 µs symmetric round trip → exact.
        let off = 5_000_000i64;
        let probes = [
            Probe {
                t0: 1_000_000,
                remote: (1_000_000 + 900_000 + off) as u64,
                t3: 2_000_000,
            },
            Probe {
                t0: 3_000_000,
                remote: (3_000_050 + off) as u64,
                t3: 3_000_100,
            },
        ];
        let e = estimate(&probes).unwrap();
        assert_eq!(e.offset_ns, off);
        assert_eq!(e.rtt_ns, 100);
        assert_eq!(e.uncertainty_ns, 50);
    }

    #[test]
    fn an_asymmetric_probe_errs_by_at_most_half_its_round_trip_and_a_remote_behind_is_negative() {
        // Remote 3 s behind; the request takes 80 µs, the answer 20 µs.
        let off = -3_000_000_000i64;
        let t0 = 10_000_000_000u64;
        let p = Probe {
            t0,
            remote: (t0 as i64 + 80_000 + off) as u64,
            t3: t0 + 100_000,
        };
        let e = estimate(&[p]).unwrap();
        assert!((e.offset_ns - off).unsigned_abs() <= e.uncertainty_ns);
        assert_eq!(e.offset_ns, off + 30_000);
        assert!(estimate(&[]).is_none());
        assert!(estimate(&[Probe {
            t0: 5,
            remote: 1,
            t3: 4
        }])
        .is_none());
    }

    #[test]
    fn a_stamp_translated_between_two_remote_hosts_reads_on_the_receivers_clock() {
        // b = launcher + 2 ms, c = launcher − 1 ms: a stamp of b reads 3 ms less on c.
        let (ob, oc) = (2_000_000i64, -1_000_000i64);
        let s = shift_ns(ob, oc);
        assert_eq!(translate(10_000_000, s), 7_000_000);
        assert_eq!(translate(0, s), 0, "lockstep messages carry no stamp");
        assert_eq!(
            translate(translate(10_000_000, s), shift_ns(oc, ob)),
            10_000_000
        );
        assert_eq!(link_name("local", "b"), "local->b");
    }

    #[test]
    fn link_delays_count_a_negative_delay_apart_and_ignore_unstamped_messages() {
        let mut l = LinkDelays::default();
        l.record(1_000, 151_000);
        l.record(1_000, 351_000);
        l.record(500_000, 400_000);
        l.record(0, 400_000);
        assert_eq!(l.delays.len(), 2);
        assert_eq!(l.negative, 1);
        assert!(l.delays.quantile(0.5) <= l.delays.max());
        assert!((349_000..=351_000).contains(&l.delays.max()));
    }
}
