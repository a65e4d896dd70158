//! Separation: the closest approach of any two quadrotors per metric window and over the whole run,
//! and the number of steps at which it is below the scenario's safety distance.
//!
//! On true positions, per step: up to [`ALL_PAIRS_MAX`] quadrotors, one pass over every pair gives
//! both the closest pair and each one's nearest other; beyond, a sweep along x (sort by x, then only
//! the pairs closer in x than the closest distance so far), O(N log N) for a spread-out swarm
//! instead of the N (N - 1) / 2 distances of every pair. Both give bit for bit the answer of the
//! all-pairs definition ([`closest_pair`]), tie-break included (unit tests).

use serde::Serialize;

/// Up to this many quadrotors a step's separation is computed over every pair (cheaper than
/// sorting for a small fleet); beyond, by the sweep along x.
pub const ALL_PAIRS_MAX: usize = 16;

/// The closest approach of two quadrotors.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Approach {
    /// Distance between the two, m.
    pub distance_m: f64,
    /// Time of the (first) step at which it occurred, s.
    pub time_s: f64,
    /// The two agents (1-based, smaller id first).
    pub agents: [usize; 2],
}

impl Approach {
    fn keep_min(slot: &mut Option<Approach>, a: Approach) {
        if slot.is_none_or(|s| a.distance_m < s.distance_m) {
            *slot = Some(a);
        }
    }
}

/// Closest approach of the positions of one step: the distance and the pair (0-based, i < j), or
/// `None` for fewer than two positions. The first pair in (i, j) order wins a tie.
pub fn closest_pair(p: &[[f64; 3]]) -> Option<(f64, usize, usize)> {
    all_pairs(p, &mut [])
}

/// [`closest_pair`] over every pair and, when `out_sq` holds one value per position, each
/// quadrotor's squared distance to its nearest other (infinite for a lone one; the same bits as
/// [`nearest_each`]; an empty `out_sq` asks only for the pair).
pub fn all_pairs(p: &[[f64; 3]], out_sq: &mut [f64]) -> Option<(f64, usize, usize)> {
    out_sq.iter_mut().for_each(|d| *d = f64::INFINITY);
    let each = out_sq.len() == p.len();
    let mut best = (f64::INFINITY, 0, 0);
    for (i, a) in p.iter().enumerate() {
        for (j, b) in p.iter().enumerate().skip(i + 1) {
            let (dx, dy, dz) = (a[0] - b[0], a[1] - b[1], a[2] - b[2]);
            let d2 = dx * dx + dy * dy + dz * dz;
            if d2 < best.0 {
                best = (d2, i, j);
            }
            if each {
                out_sq[i] = out_sq[i].min(d2);
                out_sq[j] = out_sq[j].min(d2);
            }
        }
    }
    (p.len() >= 2).then(|| (best.0.sqrt(), best.1, best.2))
}

/// [`closest_pair`] by a sweep along x: the same distance (same bits: the same operations on the
/// same pair) and the same pair, the first one in (i, j) order among equal distances. `order` is
/// scratch space (its content is replaced).
///
/// Why it is exact: for positions sorted by x, once (x_b - x_a)² exceeds the best squared distance
/// so far, every later b is at least as far in x, and a squared distance is never below its x term
/// (rounding is monotonic), so no later pair can be closer or tie; every pair that can is computed
/// as in [`closest_pair`] and kept under the same tie rule.
pub fn closest_pair_sweep(p: &[[f64; 3]], order: &mut Vec<usize>) -> Option<(f64, usize, usize)> {
    order.clear();
    order.extend(0..p.len());
    order.sort_unstable_by(|&a, &b| p[a][0].total_cmp(&p[b][0]).then(a.cmp(&b)));
    let mut best = (f64::INFINITY, 0, 0);
    for (ia, &a) in order.iter().enumerate() {
        for &b in &order[ia + 1..] {
            let dx = p[b][0] - p[a][0];
            if dx * dx > best.0 {
                break;
            }
            let (i, j) = if a < b { (a, b) } else { (b, a) };
            let (u, v) = (&p[i], &p[j]);
            let (dx, dy, dz) = (u[0] - v[0], u[1] - v[1], u[2] - v[2]);
            let d2 = dx * dx + dy * dy + dz * dz;
            if d2 < best.0 || (d2 == best.0 && (i, j) < (best.1, best.2)) {
                best = (d2, i, j);
            }
        }
    }
    (p.len() >= 2).then(|| (best.0.sqrt(), best.1, best.2))
}

/// Each quadrotor's squared distance to its nearest other at one step, into `out` (infinite for a
/// lone one), by the same sweep along x: quadrotor a's scan in each direction ends once
/// (x_b - x_a)² exceeds its best squared distance so far. `order` is scratch space.
pub fn nearest_each(p: &[[f64; 3]], order: &mut Vec<usize>, out: &mut [f64]) {
    order.clear();
    order.extend(0..p.len());
    order.sort_unstable_by(|&a, &b| p[a][0].total_cmp(&p[b][0]).then(a.cmp(&b)));
    out.iter_mut().for_each(|d| *d = f64::INFINITY);
    let d2 = |a: usize, b: usize| {
        let (u, v) = (&p[a], &p[b]);
        let (dx, dy, dz) = (u[0] - v[0], u[1] - v[1], u[2] - v[2]);
        dx * dx + dy * dy + dz * dz
    };
    for (ia, &a) in order.iter().enumerate() {
        let mut best = out[a];
        for &b in &order[ia + 1..] {
            let dx = p[b][0] - p[a][0];
            if dx * dx > best {
                break;
            }
            best = best.min(d2(a, b));
        }
        for &b in order[..ia].iter().rev() {
            let dx = p[a][0] - p[b][0];
            if dx * dx > best {
                break;
            }
            best = best.min(d2(a, b));
        }
        out[a] = best;
    }
}

/// Running separation statistics of a run.
#[derive(Debug, Clone)]
pub struct Separation {
    /// Safety distance, m.
    pub safety_distance_m: f64,
    /// Steps at which the closest two were nearer than the safety distance.
    pub steps_below_safety: u64,
    /// Closest approach in the cover window.
    pub cover: Option<Approach>,
    /// Closest approach in the enclose window.
    pub enclose: Option<Approach>,
    /// Closest approach over the whole run.
    pub whole: Option<Approach>,
    /// Closest distance of the latest step, m.
    pub last: Option<f64>,
    /// Per quadrotor: the smallest squared distance to any other over the run, m² (infinite: none
    /// yet); [`Separation::nearest_m`] in m.
    nearest_sq: Vec<f64>,
    /// Per quadrotor: its nearest other's squared distance at the latest step (scratch), m².
    now: Vec<f64>,
    /// Positions of the current step (allocated once).
    scratch: Vec<[f64; 3]>,
    /// The sweep's order of the current step (allocated once).
    order: Vec<usize>,
}

impl Separation {
    /// Empty statistics.
    pub fn new(safety_distance_m: f64) -> Separation {
        Separation {
            safety_distance_m,
            steps_below_safety: 0,
            cover: None,
            enclose: None,
            whole: None,
            last: None,
            nearest_sq: Vec::new(),
            now: Vec::new(),
            scratch: Vec::new(),
            order: Vec::new(),
        }
    }

    /// Empty statistics for `n` quadrotors (the per-step buffer is allocated here, not per step).
    pub fn with_capacity(safety_distance_m: f64, n: usize) -> Separation {
        let mut s = Separation::new(safety_distance_m);
        s.scratch.reserve(n);
        s.order.reserve(n);
        s.nearest_sq = vec![f64::INFINITY; n];
        s.now = vec![f64::INFINITY; n];
        s
    }

    /// Accumulates one step at time `t`.
    pub fn record(
        &mut self,
        t: f64,
        in_cover: bool,
        in_enclose: bool,
        positions: impl Iterator<Item = [f64; 3]>,
    ) {
        self.scratch.clear();
        self.scratch.extend(positions);
        let n = self.scratch.len();
        let tracked = self.nearest_sq.len() == n;
        let found = if n <= ALL_PAIRS_MAX && tracked {
            all_pairs(&self.scratch, &mut self.now)
        } else {
            closest_pair_sweep(&self.scratch, &mut self.order)
        };
        let Some((d, i, j)) = found else {
            return;
        };
        self.last = Some(d);
        if d < self.safety_distance_m {
            self.steps_below_safety += 1;
        }
        // Per quadrotor (min of squares: sqrt is monotonic, so the same bits as a min of
        // distances). Beyond ALL_PAIRS_MAX only where it can lower a minimum: the step's closest
        // distance is below some quadrotor's minimum so far.
        if tracked {
            if n > ALL_PAIRS_MAX {
                if !self.nearest_sq.iter().any(|&m| d < m.sqrt()) {
                    return self.keep(t, in_cover, in_enclose, (d, i, j));
                }
                nearest_each(&self.scratch, &mut self.order, &mut self.now);
            }
            for (m, now) in self.nearest_sq.iter_mut().zip(self.now.iter()) {
                *m = m.min(*now);
            }
        }
        self.keep(t, in_cover, in_enclose, (d, i, j));
    }

    /// Quadrotor `i`'s smallest distance to any other over the run, m (`None`: not tracked;
    /// infinite: no other yet).
    pub fn nearest_m(&self, i: usize) -> Option<f64> {
        self.nearest_sq.get(i).map(|d2| d2.sqrt())
    }

    /// Keeps the step's closest approach `(d, i, j)` at `t` as the window's and the run's.
    fn keep(&mut self, t: f64, in_cover: bool, in_enclose: bool, (d, i, j): (f64, usize, usize)) {
        let a = Approach {
            distance_m: d,
            time_s: t,
            agents: [i + 1, j + 1],
        };
        Approach::keep_min(&mut self.whole, a);
        if in_cover {
            Approach::keep_min(&mut self.cover, a);
        }
        if in_enclose {
            Approach::keep_min(&mut self.enclose, a);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn closest_pair_equals_the_hand_computed_distance() {
        // 1 at the origin, 2 at (3, 4, 0): 5 m; 3 at (3, 4, 1.2): 1.2 m from 2; 4 far away.
        let p = [
            [0.0, 0.0, 0.0],
            [3.0, 4.0, 0.0],
            [3.0, 4.0, 1.2],
            [10.0, 0.0, 0.0],
        ];
        let (d, i, j) = closest_pair(&p).unwrap();
        assert!((d - 1.2).abs() < 1e-12);
        assert_eq!((i, j), (1, 2));
        assert!(closest_pair(&[[1.0, 2.0, 3.0]]).is_none());
    }

    #[test]
    fn the_sweep_and_the_one_pass_give_the_all_pairs_answer_bit_for_bit_ties_and_non_finite_positions_included(
    ) {
        let mut rng = 0x2545_f491_4f6c_dd1du64;
        let mut next = move || {
            rng ^= rng << 13;
            rng ^= rng >> 7;
            rng ^= rng << 17;
            (rng >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut order = Vec::new();
        for n in [0, 1, 2, 3, 5, 20, 100, 128] {
            for round in 0..40 {
                let scale = [0.01, 1.0, 30.0][round % 3];
                let mut p: Vec<[f64; 3]> = (0..n)
                    .map(|_| [scale * next(), scale * next(), scale * next()])
                    .collect();
                if n >= 4 && round % 4 == 1 {
                    // Ties: a copy of a pair at the same offset, and equal x everywhere.
                    p[3] = [p[0][0] + 1.0, p[0][1], p[0][2]];
                    p[2] = [p[1][0] + 1.0, p[1][1], p[1][2]];
                }
                if n >= 4 && round % 4 == 2 {
                    for q in &mut p {
                        q[0] = 0.5;
                    }
                }
                if n >= 3 && round % 8 == 3 {
                    p[1] = [f64::NAN, 0.0, 0.0];
                    p[2] = [f64::INFINITY, 1.0, 1.0];
                }
                let want = closest_pair(&p);
                let got = closest_pair_sweep(&p, &mut order);
                let bits = |r: Option<(f64, usize, usize)>| r.map(|(d, i, j)| (d.to_bits(), i, j));
                assert_eq!(bits(got), bits(want), "n = {n}, round {round}");
                let (mut each, mut one_pass) = (vec![0.0; n], vec![0.0; n]);
                nearest_each(&p, &mut order, &mut each);
                let got = all_pairs(&p, &mut one_pass);
                assert_eq!(bits(got), bits(want), "all pairs, n = {n}, round {round}");
                if !p.iter().flatten().any(|x| !x.is_finite()) {
                    let bits = |v: &[f64]| v.iter().map(|d| d.to_bits()).collect::<Vec<_>>();
                    assert_eq!(
                        bits(&each),
                        bits(&one_pass),
                        "nearest, n = {n}, round {round}"
                    );
                }
            }
        }
        let all_nan = [[f64::NAN; 3]; 4];
        assert_eq!(
            closest_pair_sweep(&all_nan, &mut order).map(|(d, i, j)| (d.to_bits(), i, j)),
            closest_pair(&all_nan).map(|(d, i, j)| (d.to_bits(), i, j))
        );
    }

    #[test]
    fn separation_keeps_the_first_closest_step_per_window_and_counts_unsafe_steps() {
        let mut s = Separation::new(0.5);
        // t = 0: 2 m apart (whole only); t = 1 (cover): 0.4 m; t = 2 (cover): 0.4 m again (later,
        // not kept); t = 3 (enclose): 0.6 m between agents 2 and 3.
        let steps: [(f64, bool, bool, [[f64; 3]; 3]); 4] = [
            (
                0.0,
                false,
                false,
                [[0.0; 3], [2.0, 0.0, 0.0], [0.0, 5.0, 0.0]],
            ),
            (
                1.0,
                true,
                false,
                [[0.0; 3], [0.4, 0.0, 0.0], [0.0, 5.0, 0.0]],
            ),
            (
                2.0,
                true,
                false,
                [[0.0; 3], [0.0, 0.4, 0.0], [0.0, 5.0, 0.0]],
            ),
            (
                3.0,
                false,
                true,
                [[0.0; 3], [0.0, 4.4, 0.0], [0.0, 5.0, 0.0]],
            ),
        ];
        for (t, c, e, p) in steps {
            s.record(t, c, e, p.iter().copied());
        }
        assert_eq!(s.steps_below_safety, 2);
        let w = s.whole.unwrap();
        assert_eq!((w.time_s, w.agents), (1.0, [1, 2]));
        assert!((w.distance_m - 0.4).abs() < 1e-12);
        assert_eq!(s.cover.unwrap().time_s, 1.0);
        let e = s.enclose.unwrap();
        assert_eq!(e.agents, [2, 3]);
        assert!((e.distance_m - 0.6).abs() < 1e-12);
    }
}
