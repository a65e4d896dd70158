//! The position broadcast every quadrotor receives (ours, docs/deviations.md D25): what the
//! separation layer of each controller knows of the others. Each quadrotor broadcasts its
//! position, velocity and whether its controller flies it; the report of step k that reaches
//! quadrotor i holds the nearest [`MAX_TRAFFIC`] others within the sensing range R_S as they were
//! at the last broadcast step at or before k - d_B (d_B = tau_B / dt, the broadcast delay; every
//! quadrotor broadcasts every P steps, P = `broadcast_period_s` / dt; step 0's before that).
//!
//! The nearest are found with a uniform grid of cells R_S wide, hashed into a table of 2N
//! buckets and filled by a counting sort: the cost of a step grows with N and with the pairs
//! within R_S of each other, not with N². Every buffer is sized at construction: no allocation
//! per step. Ties in distance go to the lower agent index, so the report does not depend on the
//! order the grid is walked in.

use formation_config::protocol::wire::{Traffic, TrafficEntry, MAX_TRAFFIC, TRAFFIC_UNCOOPERATIVE};

/// One quadrotor's broadcast at one step.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Beacon {
    /// Position, m.
    pub position: [f64; 3],
    /// Velocity, m/s.
    pub velocity: [f64; 3],
    /// Its onboard failsafe flew it over the step that led here (its controller was down).
    pub uncooperative: bool,
}

/// The broadcast of a run: the recent beacons of every quadrotor and the reports built from them.
#[derive(Debug, Clone)]
pub struct Broadcast {
    n: usize,
    range: f64,
    delay_steps: u64,
    /// Steps between two broadcasts P (the beacons of steps 0, P, 2P, ... go out).
    period_steps: u64,
    /// The measurement step of the current reports.
    measured: u64,
    /// How many times the reports were built: a new count means new reports.
    builds: u64,
    /// Ring of `delay_steps + period_steps` snapshots of N beacons, by step.
    ring: Vec<Beacon>,
    /// The reports of the current step, one per quadrotor.
    reports: Vec<Traffic>,
    /// Grid scratch: each quadrotor's bucket, the quadrotors sorted by bucket, bucket starts.
    bucket_of: Vec<u32>,
    order: Vec<u32>,
    starts: Vec<u32>,
}

/// Up to this many quadrotors the reports are built pair by pair: the grid only pays for itself
/// in larger formations. Both give the same reports (nearest first, ties to the lower index).
const BRUTE_FORCE_UP_TO: usize = 16;

/// Squared distance between `a` and `b`, m².
fn dist2(a: [f64; 3], b: [f64; 3]) -> f64 {
    let (dx, dy, dz) = (a[0] - b[0], a[1] - b[1], a[2] - b[2]);
    dx * dx + dy * dy + dz * dz
}

/// Integer cell coordinates of `p` in cells `w` wide.
fn cell(p: [f64; 3], w: f64) -> [i64; 3] {
    p.map(|x| (x / w).floor() as i64)
}

/// The bucket of a cell in a table of `mask + 1` buckets (a power of two).
fn bucket(c: [i64; 3], mask: usize) -> usize {
    let h = (c[0].wrapping_mul(73_856_093))
        ^ (c[1].wrapping_mul(19_349_663))
        ^ (c[2].wrapping_mul(83_492_791));
    (h as u64 as usize) & mask
}

impl Broadcast {
    /// The broadcast of `initial` beacons (step 0) with sensing range `range_m` (m) and a delay
    /// of `delay_steps` steps, broadcast every `period_steps` steps (at least 1).
    pub fn new(initial: &[Beacon], range_m: f64, delay_steps: u64, period_steps: u64) -> Broadcast {
        let n = initial.len();
        let period_steps = period_steps.max(1);
        let depth = (delay_steps + period_steps) as usize;
        let mut ring = vec![Beacon::default(); n * depth];
        for slot in 0..depth {
            ring[slot * n..(slot + 1) * n].copy_from_slice(initial);
        }
        let buckets = (2 * n).next_power_of_two().max(1);
        let mut b = Broadcast {
            n,
            range: range_m,
            delay_steps,
            period_steps,
            measured: 0,
            builds: 0,
            ring,
            reports: vec![Traffic::default(); n],
            bucket_of: vec![0; n],
            order: vec![0; n],
            starts: vec![0; buckets + 1],
        };
        b.build_reports(0);
        b
    }

    /// How many times the reports were built so far: the reports of two steps with the same
    /// count are the same, bit for bit.
    pub fn builds(&self) -> u64 {
        self.builds
    }

    /// The report quadrotor `i` receives at the current step.
    pub fn report(&self, i: usize) -> Traffic {
        self.reports[i]
    }

    /// Records the beacons of step `step` (the step just reached) and builds that step's reports.
    pub fn record(&mut self, step: u64, beacons: impl Iterator<Item = Beacon>) {
        let depth = self.depth();
        let slot = (step % depth) as usize * self.n;
        for (i, b) in beacons.enumerate().take(self.n) {
            self.ring[slot + i] = b;
        }
        self.build_reports(step);
    }

    /// The snapshot the reports of step `k` are built from: step k - d_B (0 before it).
    fn measured_step(&self, k: u64) -> u64 {
        let m = k.saturating_sub(self.delay_steps);
        m - m % self.period_steps
    }

    /// Snapshots the ring holds.
    fn depth(&self) -> u64 {
        self.delay_steps + self.period_steps
    }

    fn build_reports(&mut self, k: u64) {
        let m = self.measured_step(k);
        if m == self.measured && k > 0 {
            return; // the same broadcast as the last step's
        }
        self.measured = m;
        self.builds += 1;
        if self.n <= BRUTE_FORCE_UP_TO {
            self.pairwise(m);
        } else {
            self.grid(m);
        }
    }

    /// The reports from the snapshot of step `m`, pair by pair.
    fn pairwise(&mut self, m: u64) {
        let base = (m % self.depth()) as usize * self.n;
        {
            let snap = &self.ring[base..base + self.n];
            let r2 = self.range * self.range;
            for (i, report) in self.reports.iter_mut().enumerate() {
                clear(report);
                let mut dist = [f64::INFINITY; MAX_TRAFFIC];
                let pi = snap[i].position;
                for (j, b) in snap.iter().enumerate() {
                    let d2 = dist2(b.position, pi);
                    if j != i && d2 <= r2 {
                        insert(report, &mut dist, d2, m, j, b);
                    }
                }
            }
        }
    }

    /// The reports from the snapshot of step `m`, through the grid.
    fn grid(&mut self, m: u64) {
        let base = (m % self.depth()) as usize * self.n;
        let snap = &self.ring[base..base + self.n];
        let mask = self.starts.len() - 2;
        // Counting sort of the quadrotors by bucket.
        self.starts.iter_mut().for_each(|s| *s = 0);
        for (i, b) in snap.iter().enumerate() {
            let k = bucket(cell(b.position, self.range), mask);
            self.bucket_of[i] = k as u32;
            self.starts[k + 1] += 1;
        }
        for k in 1..self.starts.len() {
            self.starts[k] += self.starts[k - 1];
        }
        for i in 0..self.n {
            let k = self.bucket_of[i] as usize;
            // starts[k] is advanced while filling and restored below.
            let at = self.starts[k] as usize;
            self.order[at] = i as u32;
            self.starts[k] += 1;
        }
        // Restore the starts (each was advanced by its bucket's size).
        for k in (1..self.starts.len()).rev() {
            self.starts[k] = self.starts[k - 1];
        }
        self.starts[0] = 0;
        for i in 0..self.n {
            self.reports[i] = self.nearest(i, m, snap, mask);
        }
    }

    /// The report of quadrotor `i` from the snapshot `snap` of step `m`.
    fn nearest(&self, i: usize, m: u64, snap: &[Beacon], mask: usize) -> Traffic {
        let mut t = self.reports[i];
        clear(&mut t);
        let mut dist = [f64::INFINITY; MAX_TRAFFIC];
        let pi = snap[i].position;
        let c = cell(pi, self.range);
        let r2 = self.range * self.range;
        let mut visited = [usize::MAX; 27];
        let mut nv = 0;
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    let k = bucket([c[0] + dx, c[1] + dy, c[2] + dz], mask);
                    // Distinct cells may share a bucket: walk each bucket once.
                    if visited[..nv].contains(&k) {
                        continue;
                    }
                    visited[nv] = k;
                    nv += 1;
                    for &j in &self.order[self.starts[k] as usize..self.starts[k + 1] as usize] {
                        let j = j as usize;
                        if j == i {
                            continue;
                        }
                        let d2 = dist2(snap[j].position, pi);
                        if d2 <= r2 {
                            insert(&mut t, &mut dist, d2, m, j, &snap[j]);
                        }
                    }
                }
            }
        }
        t
    }
}

/// Empties a report: its used entries back to zero (the rest already are), its count to 0.
fn clear(t: &mut Traffic) {
    let used = (t.count as usize).min(MAX_TRAFFIC);
    t.entries[..used].fill(TrafficEntry::default());
    t.count = 0;
    t.step = 0;
}

/// Inserts quadrotor `j` at squared distance `d2` into the report `t` kept nearest first (ties:
/// lower index first), dropping the farthest beyond [`MAX_TRAFFIC`].
fn insert(t: &mut Traffic, dist: &mut [f64; MAX_TRAFFIC], d2: f64, m: u64, j: usize, b: &Beacon) {
    let used = t.count as usize;
    let before = |l: usize| d2 < dist[l] || (d2 == dist[l] && (j as u32) < t.entries[l].agent);
    let mut at = used;
    while at > 0 && before(at - 1) {
        at -= 1;
    }
    if at >= MAX_TRAFFIC {
        return;
    }
    let last = used.min(MAX_TRAFFIC - 1);
    for l in (at..last).rev() {
        t.entries[l + 1] = t.entries[l];
        dist[l + 1] = dist[l];
    }
    t.step = m;
    t.entries[at] = TrafficEntry {
        agent: j as u32,
        flags: if b.uncooperative {
            TRAFFIC_UNCOOPERATIVE
        } else {
            0
        },
        position: b.position.map(|x| x as f32),
        velocity: b.velocity.map(|x| x as f32),
    };
    dist[at] = d2;
    t.count = (used + 1).min(MAX_TRAFFIC) as u32;
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(x: f64, y: f64) -> Beacon {
        Beacon {
            position: [x, y, 5.0],
            ..Beacon::default()
        }
    }

    /// The grid's answer equals the brute-force one: every other quadrotor within the range,
    /// nearest first, at most MAX_TRAFFIC, for a crowd spread over many cells.
    #[test]
    fn the_grid_reports_the_nearest_within_range_as_brute_force_does() {
        let n = 60;
        let beacons: Vec<Beacon> = (0..n)
            .map(|i| {
                let a = i as f64 * 2.399_963;
                let r = 0.4 * (i as f64).sqrt();
                at(r * a.cos(), r * a.sin())
            })
            .collect();
        let b = Broadcast::new(&beacons, 1.0, 0, 1);
        // The pairwise path gives the same reports.
        let mut pairs = b.clone();
        pairs.pairwise(0);
        for i in 0..n {
            assert_eq!(pairs.report(i), b.report(i), "agent {i}");
        }
        for i in 0..n {
            let mut want: Vec<(f64, usize)> = (0..n)
                .filter(|&j| j != i)
                .map(|j| {
                    let d: f64 = (0..3)
                        .map(|a| (beacons[j].position[a] - beacons[i].position[a]).powi(2))
                        .sum();
                    (d, j)
                })
                .filter(|(d, _)| *d <= 1.0)
                .collect();
            want.sort_by(|a, b| a.partial_cmp(b).unwrap());
            want.truncate(MAX_TRAFFIC);
            let got: Vec<usize> = b
                .report(i)
                .used()
                .iter()
                .map(|e| e.agent as usize)
                .collect();
            assert_eq!(
                got,
                want.iter().map(|w| w.1).collect::<Vec<_>>(),
                "agent {i}"
            );
        }
    }

    /// The report of step k holds the beacons of step k - d_B (of step 0 before that), stamped
    /// with their step, and says who is flown by its failsafe.
    #[test]
    fn reports_are_the_broadcast_delay_old_and_flag_a_quadrotor_down() {
        let mut b = Broadcast::new(&[at(0.0, 0.0), at(1.0, 0.0)], 3.0, 2, 1);
        assert_eq!(b.report(0).step, 0);
        for k in 1..=4u64 {
            let x = 1.0 + k as f64;
            let down = k == 3;
            b.record(
                k,
                [
                    at(0.0, 0.0),
                    Beacon {
                        uncooperative: down,
                        ..at(x, 0.0)
                    },
                ]
                .into_iter(),
            );
            let e = b.report(0).used()[0];
            let m = k.saturating_sub(2);
            assert_eq!(b.report(0).step, m);
            assert_eq!(e.p()[0], 1.0 + m as f64);
            assert_eq!(e.flags == TRAFFIC_UNCOOPERATIVE, m == 3);
        }
        // Out of range (4 m > 3 m) at the step measured at k = 6.
        b.record(5, [at(0.0, 0.0), at(4.0, 0.0)].into_iter());
        b.record(6, [at(0.0, 0.0), at(4.0, 0.0)].into_iter());
        b.record(7, [at(0.0, 0.0), at(4.0, 0.0)].into_iter());
        assert_eq!(b.report(0).count, 0);
    }

    /// Broadcast every 3 steps with a delay of 2: the report of step k holds the beacons of the
    /// last broadcast step at or before k - 2, and is rebuilt only when that changes.
    #[test]
    fn reports_hold_the_last_broadcast_between_two() {
        let mut b = Broadcast::new(&[at(0.0, 0.0), at(1.0, 0.0)], 5.0, 2, 3);
        for k in 1..=12u64 {
            b.record(k, [at(0.0, 0.0), at(1.0 + k as f64 * 0.1, 0.0)].into_iter());
            let m = k.saturating_sub(2) / 3 * 3;
            assert_eq!(b.report(0).step, m, "step {k}");
            let x = b.report(0).used()[0].p()[0];
            assert!((x - (1.0 + m as f64 * 0.1)).abs() < 1e-6, "step {k}: {x}");
        }
    }
}
