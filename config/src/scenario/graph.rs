//! Communication graph of Section 2.1: adjacency W = [a_ij], Laplacian L = D - W, leader weights B.

use crate::scenario::Scenario;
use nalgebra::DMatrix;

/// Neighbours of every agent with their weights, 0-based, plus the leader weight b_i.
#[derive(Debug, Clone, PartialEq)]
pub struct Topology {
    /// `neighbours[i]` lists (j, a_ij) for every j with a_ij > 0.
    pub neighbours: Vec<Vec<(usize, f64)>>,
    /// Leader weights b_i.
    pub leader_weights: Vec<f64>,
}

impl Topology {
    /// Builds the topology of a scenario (edges are 1-based in the file). Assumes a validated scenario.
    pub fn from_scenario(s: &Scenario) -> Topology {
        let n = s.n_agents();
        let mut neighbours = vec![Vec::new(); n];
        for e in &s.graph.edges {
            let (a, b) = (e.a - 1, e.b - 1);
            neighbours[a].push((b, e.weight));
            neighbours[b].push((a, e.weight));
        }
        for list in &mut neighbours {
            list.sort_by_key(|(j, _)| *j);
        }
        Topology {
            neighbours,
            leader_weights: s.graph.leader_weights.clone(),
        }
    }

    /// Number of agents.
    pub fn n(&self) -> usize {
        self.neighbours.len()
    }

    /// The matrix L + B of eq. (10).
    pub fn laplacian_plus_leader(&self) -> DMatrix<f64> {
        let n = self.n();
        let mut m = DMatrix::zeros(n, n);
        for (i, list) in self.neighbours.iter().enumerate() {
            for &(j, a) in list {
                m[(i, j)] -= a;
                m[(i, i)] += a;
            }
            m[(i, i)] += self.leader_weights[i];
        }
        m
    }

    /// Eigenvalues of the symmetric L + B, ascending.
    pub fn eigenvalues(&self) -> Vec<f64> {
        let e = self.laplacian_plus_leader().symmetric_eigen();
        let mut v: Vec<f64> = e.eigenvalues.iter().copied().collect();
        v.sort_by(|a, b| a.total_cmp(b));
        v
    }

    /// True when every agent is connected to one that hears the leader (Assumption 1).
    pub fn leader_reaches_all(&self) -> bool {
        let n = self.n();
        let mut seen = vec![false; n];
        let mut stack: Vec<usize> = (0..n).filter(|&i| self.leader_weights[i] > 0.0).collect();
        for &i in &stack {
            seen[i] = true;
        }
        while let Some(i) = stack.pop() {
            for &(j, _) in &self.neighbours[i] {
                if !seen[j] {
                    seen[j] = true;
                    stack.push(j);
                }
            }
        }
        seen.iter().all(|&s| s)
    }

    /// True when the follower graph is connected (Assumption 1).
    pub fn connected(&self) -> bool {
        let n = self.n();
        if n == 0 {
            return false;
        }
        let mut seen = vec![false; n];
        let mut stack = vec![0];
        seen[0] = true;
        while let Some(i) = stack.pop() {
            for &(j, _) in &self.neighbours[i] {
                if !seen[j] {
                    seen[j] = true;
                    stack.push(j);
                }
            }
        }
        seen.iter().all(|&s| s)
    }
}
