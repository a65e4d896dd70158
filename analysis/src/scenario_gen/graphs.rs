//! Communication graphs of generated scenarios: ring, path, k-nearest, complete, random-connected;
//! leader weights b; edge weights normalised by the largest degree.

use super::GenError;
use formation_config::scenario::Edge;
use formation_runtime::rng::SplitMix64;

/// The graph families of `formation scenario --graph`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GraphKind {
    /// 1-2-...-N-1.
    Ring,
    /// 1-2-...-N (the paper's Fig. 4 for N = 5).
    Path,
    /// Every agent linked to the k agents whose formation slots are nearest (symmetrised).
    KNearest,
    /// Every pair.
    Complete,
    /// A random spanning tree plus ceil(N/2) random extra edges (deterministic for a seed).
    RandomConnected,
}

impl GraphKind {
    /// Parses `ring | path | k-nearest | complete | random-connected`.
    pub fn parse(s: &str) -> Result<GraphKind, GenError> {
        Ok(match s {
            "ring" => GraphKind::Ring,
            "path" => GraphKind::Path,
            "k-nearest" => GraphKind::KNearest,
            "complete" => GraphKind::Complete,
            "random-connected" => GraphKind::RandomConnected,
            other => return Err(GenError::Graph(other.to_string())),
        })
    }

    /// The name as given on the command line.
    pub fn name(self) -> &'static str {
        match self {
            GraphKind::Ring => "ring",
            GraphKind::Path => "path",
            GraphKind::KNearest => "k-nearest",
            GraphKind::Complete => "complete",
            GraphKind::RandomConnected => "random-connected",
        }
    }
}

/// Edge list (0-based, a < b, each undirected edge once) of the graph on `n` agents whose formation
/// slots sit on a ring in index order. `k` is used by k-nearest, `seed` by random-connected.
pub fn edges(kind: GraphKind, n: usize, k: usize, seed: u64) -> Vec<(usize, usize)> {
    let mut out: Vec<(usize, usize)> = Vec::new();
    let add = |a: usize, b: usize, out: &mut Vec<(usize, usize)>| {
        let e = (a.min(b), a.max(b));
        if a != b && !out.contains(&e) {
            out.push(e);
        }
    };
    match kind {
        GraphKind::Path => (1..n).for_each(|i| add(i - 1, i, &mut out)),
        GraphKind::Ring => {
            (1..n).for_each(|i| add(i - 1, i, &mut out));
            if n > 2 {
                add(n - 1, 0, &mut out);
            }
        }
        GraphKind::Complete => {
            for a in 0..n {
                for b in a + 1..n {
                    add(a, b, &mut out);
                }
            }
        }
        GraphKind::KNearest => {
            // Slot distance on the ring is monotone in the index distance min(|i-j|, n-|i-j|);
            // ties are broken towards the next agent in index order (+1 before -1).
            for i in 0..n {
                let mut others: Vec<usize> = (0..n).filter(|&j| j != i).collect();
                others.sort_by_key(|&j| {
                    let fwd = (j + n - i) % n;
                    let back = (i + n - j) % n;
                    (fwd.min(back), usize::from(back < fwd))
                });
                for &j in others.iter().take(k) {
                    add(i, j, &mut out);
                }
            }
        }
        GraphKind::RandomConnected => {
            let mut rng = SplitMix64::new(seed);
            let mut order: Vec<usize> = (0..n).collect();
            for i in (1..n).rev() {
                order.swap(i, rng.below(i + 1));
            }
            for i in 1..n {
                let j = order[rng.below(i)];
                add(order[i], j, &mut out);
            }
            let max_edges = n * (n - 1) / 2;
            let extra = n.div_ceil(2).min(max_edges - out.len());
            let target = out.len() + extra;
            while out.len() < target {
                let (a, b) = (rng.below(n), rng.below(n));
                add(a, b, &mut out);
            }
        }
    }
    out.sort_unstable();
    out
}

/// Largest row sum of L + B that generated graphs allow, measured (docs/scaling.md): with unit
/// weights, agents pinned between two neighbours have a row sum of 3 and the 50-agent path falls
/// into a saturated limit cycle (worst cover RMS 1.47 m); scaled to the paper's 2, the 20-ring
/// tracks its enclosing spin worse (0.41 m against 0.33 m); 2.7 gives 0.21 / 0.28 m on the 50-path
/// and 0.15 / 0.35 m on the 20-ring. The paper's path (row sums <= 2) is left as it is.
pub const MAX_ROW_SUM: f64 = 2.7;

/// Weights of generated graphs: each edge (x, y) a_xy = min(1, 2 / max(d_x, d_y)) (d the degrees:
/// the paper's path has 2, so its edges keep weight 1), leaders b = 1, then all scaled by
/// min(1, [`MAX_ROW_SUM`] / the largest row sum of L + B). Every row of L has a sum of at most 2
/// before the scaling (each of the d_i edges of agent i weighs at most 2 / d_i), so dense graphs keep
/// the paper's bound on the spectrum of L + B (Gershgorin), while an edge between two agents of low
/// degree is not weakened by a hub elsewhere in the graph: with one weight 2 / d_max for every edge,
/// a random-connected graph of 50 agents with one hub of degree 9 coupled most agents at 0.22 and
/// flew 0.39 / 0.39 m worst RMS, 0.48 m apart at its closest (docs/scaling.md).
/// Returns the edge weights (in the order of `edges`) and b.
pub fn weights(n: usize, edges: &[(usize, usize)], leaders: &[usize]) -> (Vec<f64>, f64) {
    let mut deg = vec![0usize; n];
    for &(a, b) in edges {
        deg[a] += 1;
        deg[b] += 1;
    }
    let mut a: Vec<f64> = edges
        .iter()
        .map(|&(x, y)| (2.0 / deg[x].max(deg[y]).max(1) as f64).min(1.0))
        .collect();
    let mut row = vec![0.0; n];
    for (&(x, y), w) in edges.iter().zip(&a) {
        row[x] += w;
        row[y] += w;
    }
    for &l in leaders {
        if (1..=n).contains(&l) {
            row[l - 1] += 1.0;
        }
    }
    let row_max = row.iter().copied().fold(0.0, f64::max);
    let c = if row_max > MAX_ROW_SUM {
        MAX_ROW_SUM / row_max
    } else {
        1.0
    };
    for w in &mut a {
        *w *= c;
    }
    (a, c)
}

/// The scenario edges (1-based) with weights `a` (one per edge).
pub fn to_scenario_edges(edges: &[(usize, usize)], a: &[f64]) -> Vec<Edge> {
    edges
        .iter()
        .zip(a)
        .map(|(&(x, y), &w)| Edge {
            a: x + 1,
            b: y + 1,
            weight: w,
        })
        .collect()
}

/// Share of agents that receive the leader in the paper (b_1 = b_5 = 1: 2 of 5).
pub const PAPER_PINNED_SHARE: f64 = 2.0 / 5.0;

/// Default leader agents (1-based): m = max(1, round(N 2/5)) agents, the paper's share, spread
/// evenly: on a path from end to end (ids round(1 + k (N - 1)/(m - 1)), so N = 5 gives 1 and 5 as in
/// Fig. 4), on every other graph around the ring of slots (ids 1 + floor(k N / m)). The share is
/// kept because the RBFNN learns from the consensus error e_iP, which carries the formation's
/// common-mode error to agent i only through the b_j of the agents near it: with two pinned agents
/// out of 20 on a ring the common mode is left to the leader-relative terms alone, and the measured
/// worst cover RMS is 0.52 m against 0.13 m with 8 of 20 (docs/scaling.md).
pub fn default_leader_agents(kind: GraphKind, n: usize) -> Vec<usize> {
    let m = ((n as f64 * PAPER_PINNED_SHARE).round() as usize).clamp(1, n);
    if kind == GraphKind::Path && m > 1 {
        (0..m)
            .map(|k| (1.0 + k as f64 * (n - 1) as f64 / (m - 1) as f64).round() as usize)
            .collect()
    } else {
        (0..m).map(|k| 1 + k * n / m).collect()
    }
}

/// Default leader agents of a graph whose degrees differ from agent to agent (random-connected):
/// the paper's share m = max(1, round(N 2/5)), the agents of the lowest degree first (ties in id
/// order), returned in id order. The paper pins the two ends of its path, its two agents of degree
/// 1; on a random graph its leaves hang on a hub whose edges the weights share out
/// ([`weights`]), and unpinned they were the worst of the formation (N = 50: worst cover RMS
/// 0.31 m, all of the six worst were unpinned leaves, against 0.03 m for pinned ones;
/// docs/scaling.md).
pub fn least_coupled_leader_agents(n: usize, edges: &[(usize, usize)]) -> Vec<usize> {
    let m = ((n as f64 * PAPER_PINNED_SHARE).round() as usize).clamp(1, n);
    let mut deg = vec![0usize; n];
    for &(a, b) in edges {
        deg[a] += 1;
        deg[b] += 1;
    }
    let mut ids: Vec<usize> = (0..n).collect();
    ids.sort_by_key(|&i| deg[i]); // stable: ties stay in id order
    let mut out: Vec<usize> = ids[..m].iter().map(|&i| i + 1).collect();
    out.sort_unstable();
    out
}

/// Parses `--leader-agents 1,5` (1-based ids, each within 1..=n, no repeats).
pub fn parse_leader_agents(s: &str, n: usize) -> Result<Vec<usize>, GenError> {
    let mut out = Vec::new();
    let list = || s.to_string();
    for part in s.split(',') {
        let id: usize = part.trim().parse().map_err(|_| GenError::LeaderId {
            list: list(),
            part: part.to_string(),
        })?;
        if !(1..=n).contains(&id) {
            return Err(GenError::LeaderOutside {
                list: list(),
                id,
                n,
            });
        }
        if out.contains(&id) {
            return Err(GenError::LeaderTwice { list: list(), id });
        }
        out.push(id);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn connected(n: usize, e: &[(usize, usize)]) -> bool {
        let mut seen = vec![false; n];
        let mut stack = vec![0];
        seen[0] = true;
        while let Some(i) = stack.pop() {
            for &(a, b) in e {
                let j = if a == i {
                    b
                } else if b == i {
                    a
                } else {
                    continue;
                };
                if !seen[j] {
                    seen[j] = true;
                    stack.push(j);
                }
            }
        }
        seen.into_iter().all(|s| s)
    }

    #[test]
    fn graph_families_have_their_textbook_edge_counts() {
        assert_eq!(edges(GraphKind::Path, 7, 0, 0).len(), 6);
        assert_eq!(edges(GraphKind::Ring, 7, 0, 0).len(), 7);
        assert_eq!(edges(GraphKind::Ring, 2, 0, 0), vec![(0, 1)]);
        assert_eq!(edges(GraphKind::Complete, 7, 0, 0).len(), 21);
        // k = 2 nearest on a ring is the ring; k = 4 adds the second neighbours.
        assert_eq!(
            edges(GraphKind::KNearest, 9, 2, 0),
            edges(GraphKind::Ring, 9, 0, 0)
        );
        assert_eq!(edges(GraphKind::KNearest, 9, 4, 0).len(), 18);
    }

    #[test]
    fn random_connected_graphs_are_connected_and_reproducible_for_a_seed() {
        for n in [2, 3, 10, 50, 128] {
            for seed in 0..5 {
                let e = edges(GraphKind::RandomConnected, n, 0, seed);
                assert!(connected(n, &e), "n = {n}, seed = {seed}");
                assert_eq!(e, edges(GraphKind::RandomConnected, n, 0, seed));
                let tree = n - 1;
                assert_eq!(e.len(), (tree + n.div_ceil(2)).min(n * (n - 1) / 2));
            }
        }
        assert_ne!(
            edges(GraphKind::RandomConnected, 20, 0, 1),
            edges(GraphKind::RandomConnected, 20, 0, 2)
        );
    }

    #[test]
    fn weights_keep_the_papers_path_and_bound_every_row_sum_of_l_plus_b() {
        assert_eq!(
            weights(5, &edges(GraphKind::Path, 5, 0, 0), &[1, 5]),
            (vec![1.0; 4], 1.0)
        );
        for (kind, n) in [
            (GraphKind::Complete, 50),
            (GraphKind::Ring, 20),
            (GraphKind::Path, 50),
            (GraphKind::KNearest, 30),
            (GraphKind::RandomConnected, 50),
            (GraphKind::RandomConnected, 128),
        ] {
            let e = edges(kind, n, 6, 0);
            let leaders = default_leader_agents(kind, n);
            let (a, b) = weights(n, &e, &leaders);
            let mut row = vec![0.0; n];
            for (&(x, y), w) in e.iter().zip(&a) {
                assert!(*w > 0.0 && *w <= 1.0, "{kind:?} {n}: edge weight {w}");
                row[x] += w;
                row[y] += w;
            }
            for &l in &leaders {
                row[l - 1] += b;
            }
            let max = row.iter().copied().fold(0.0, f64::max);
            assert!(max <= MAX_ROW_SUM + 1e-12, "{kind:?} {n}: {max}");
        }
    }

    #[test]
    fn random_graphs_pin_their_leaves_first() {
        let e = edges(GraphKind::RandomConnected, 50, 0, 1);
        let leaders = least_coupled_leader_agents(50, &e);
        assert_eq!(leaders.len(), 20);
        let mut deg = [0usize; 50];
        for &(a, b) in &e {
            deg[a] += 1;
            deg[b] += 1;
        }
        let pinned_max = leaders.iter().map(|&l| deg[l - 1]).max().unwrap();
        let free_min = (1..=50)
            .filter(|i| !leaders.contains(i))
            .map(|i| deg[i - 1])
            .min()
            .unwrap();
        assert!(
            pinned_max <= free_min,
            "a pinned agent of degree {pinned_max}, a free one of {free_min}"
        );
        assert!(leaders.iter().any(|&l| deg[l - 1] == 1));
    }

    #[test]
    fn leader_agents_are_parsed_as_one_based_ids_and_bad_ids_are_refused() {
        assert_eq!(parse_leader_agents("1,5", 5).unwrap(), vec![1, 5]);
        assert!(parse_leader_agents("0", 5).is_err());
        assert!(parse_leader_agents("6", 5).is_err());
        assert!(parse_leader_agents("2,2", 5).is_err());
        assert!(parse_leader_agents("x", 5).is_err());
    }

    #[test]
    fn default_leader_agents_keep_the_papers_two_in_five_share_spread_evenly() {
        assert_eq!(default_leader_agents(GraphKind::Path, 5), vec![1, 5]);
        assert_eq!(default_leader_agents(GraphKind::Ring, 5), vec![1, 3]);
        assert_eq!(
            default_leader_agents(GraphKind::Ring, 20),
            vec![1, 3, 6, 8, 11, 13, 16, 18]
        );
        let p = default_leader_agents(GraphKind::Path, 50);
        assert_eq!((p.len(), p[0], p[19]), (20, 1, 50));
        assert_eq!(default_leader_agents(GraphKind::Complete, 2), vec![1]);
    }
}
