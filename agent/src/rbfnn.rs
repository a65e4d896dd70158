//! RBFNN of eq. (11) with the update law (15), one network per axis.
//!
//! Input of axis k: the delayed (P_ik, V_ik), normalised by the spans of the scenario. The l centres form
//! a grid of (l / n_v) positions x n_v velocities evenly spread over [-1, 1]² of the normalised input;
//! every Gaussian has the same spread (docs/deviations.md D6). With `position_norm_sq` c_P (D24) the position
//! factors of an axis are scaled so that their squared norm is c_P wherever the quadrotor is.

/// Largest number of neurons per axis.
pub const MAX_NEURONS: usize = 64;

/// D24: the factor that scales the position Gaussians `g` of one axis to the squared norm `c_p`
/// (1.0 where they all vanish: far outside the span nothing is rescaled from nothing).
pub fn position_factor_scale(g: &[f64], c_p: f64) -> f64 {
    let norm_sq: f64 = g.iter().map(|x| x * x).sum();
    if norm_sq > f64::MIN_POSITIVE {
        (c_p / norm_sq).sqrt()
    } else {
        1.0
    }
}

/// Three RBF networks (one per axis) with their weights W-hat_ik.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct Rbfnn {
    l: usize,
    #[serde(with = "crate::checkpoint::array")]
    centres: [f64; MAX_NEURONS],
    #[serde(with = "crate::checkpoint::array")]
    vel_centres: [f64; MAX_NEURONS],
    n_v: usize,
    inv_spread_sq: f64,
    inv_pos_span: f64,
    inv_vel_span: f64,
    /// c_P of D24: the squared norm the position factors of Psi_ik are scaled to (None: plain
    /// Gaussians).
    position_norm_sq: Option<f64>,
    /// W-hat_ik, axis-major.
    #[serde(with = "crate::checkpoint::rows")]
    weights: [[f64; MAX_NEURONS]; 3],
    /// Psi_ik of the last evaluation.
    #[serde(with = "crate::checkpoint::rows")]
    psi: [[f64; MAX_NEURONS]; 3],
}

impl Rbfnn {
    /// A network of `l` neurons per axis (`n_v` velocity values) with the given spans and spread;
    /// `initial` fills the weights. `position_norm_sq` c_P (D24) scales the position factors of
    /// Psi to the squared norm c_P at every position; `None` keeps the plain Gaussians.
    pub fn new(
        l: usize,
        n_v: usize,
        pos_span: f64,
        vel_span: f64,
        spread: f64,
        position_norm_sq: Option<f64>,
        initial: impl Fn(usize, usize) -> f64,
    ) -> Rbfnn {
        let l = l.clamp(1, MAX_NEURONS);
        let n_v = n_v.clamp(1, l);
        let n_v = if l.is_multiple_of(n_v) { n_v } else { 1 };
        let n_p = (l / n_v).max(1);
        let spaced = |j: usize, n: usize| {
            if n == 1 {
                0.0
            } else {
                -1.0 + 2.0 * j as f64 / (n - 1) as f64
            }
        };
        let mut centres = [0.0; MAX_NEURONS];
        let mut vel_centres = [0.0; MAX_NEURONS];
        for j in 0..l {
            centres[j] = spaced(j / n_v % n_p, n_p);
            vel_centres[j] = spaced(j % n_v, n_v);
        }
        let mut weights = [[0.0; MAX_NEURONS]; 3];
        for (k, row) in weights.iter_mut().enumerate() {
            for (j, w) in row.iter_mut().enumerate().take(l) {
                *w = initial(k, j);
            }
        }
        Rbfnn {
            l,
            centres,
            vel_centres,
            n_v,
            inv_spread_sq: 1.0 / (spread * spread),
            inv_pos_span: 1.0 / pos_span,
            inv_vel_span: 1.0 / vel_span,
            position_norm_sq,
            weights,
            psi: [[0.0; MAX_NEURONS]; 3],
        }
    }

    /// Evaluates Psi_i at the delayed (P, V) and returns F-hat_iP = W-hat^T Psi (eq. (11)).
    pub fn evaluate(&mut self, p: [f64; 3], v: [f64; 3]) -> [f64; 3] {
        let mut out = [0.0; 3];
        let (n_p, n_v, l) = (self.l / self.n_v, self.n_v, self.l);
        // The centres form a grid, so exp(-(dx² + dy²)/mu²) = exp(-dx²/mu²) exp(-dy²/mu²): n_p + n_v
        // exponentials per axis instead of l. Scratch for the velocity factors, shared by the axes.
        let mut gy = [0.0; MAX_NEURONS];
        for (k, out_k) in out.iter_mut().enumerate() {
            let x = p[k] * self.inv_pos_span;
            let y = v[k] * self.inv_vel_span;
            for (g, c) in gy[..n_v].iter_mut().zip(&self.vel_centres[..n_v]) {
                let dy = y - c;
                *g = (-dy * dy * self.inv_spread_sq).exp();
            }
            let mut gx = [0.0; MAX_NEURONS];
            let centres = self.centres[..l].iter().step_by(n_v);
            for (g, c) in gx[..n_p].iter_mut().zip(centres) {
                let dx = x - c;
                *g = (-dx * dx * self.inv_spread_sq).exp();
            }
            if let Some(c_p) = self.position_norm_sq {
                let s = position_factor_scale(&gx[..n_p], c_p);
                gx[..n_p].iter_mut().for_each(|g| *g *= s);
            }
            // Neuron j = a n_v + b (position centre a, velocity centre b), in increasing j: the sum
            // runs in the order of the definition.
            let mut acc = 0.0;
            let psi_rows = self.psi[k][..l].chunks_exact_mut(n_v);
            let w_rows = self.weights[k][..l].chunks_exact(n_v);
            for ((psi_row, w_row), gx) in psi_rows.zip(w_rows).zip(&gx[..n_p]) {
                for ((psi, w), g) in psi_row.iter_mut().zip(w_row).zip(&gy[..n_v]) {
                    *psi = gx * g;
                    acc += w * *psi;
                }
            }
            *out_k = acc;
        }
        out
    }

    /// One Euler step of the update law (15): W-hat' = kappa (Psi (K_P e_P + K_V e_V) - K_W W-hat),
    /// with the Psi of the last [`Rbfnn::evaluate`].
    pub fn update(&mut self, drive: [f64; 3], kappa: f64, leakage: f64, dt: f64) {
        let l = self.l;
        for ((w_row, psi_row), d) in self.weights.iter_mut().zip(&self.psi).zip(drive) {
            for (w, psi) in w_row[..l].iter_mut().zip(&psi_row[..l]) {
                *w = *w + dt * kappa * (psi * d - leakage * *w);
            }
        }
    }

    /// Re-seeds the weights so that the output at (p, v) is `target`: per axis the smallest change
    /// of W-hat_k that does it, W-hat_k += Psi_k (target_k - W-hat_k^T Psi_k) / ||Psi_k||² (an axis
    /// whose Psi vanishes keeps its weights).
    pub fn reseed(&mut self, p: [f64; 3], v: [f64; 3], target: [f64; 3]) {
        let out = self.evaluate(p, v);
        let l = self.l;
        for ((w_row, psi_row), (t, o)) in self
            .weights
            .iter_mut()
            .zip(&self.psi)
            .zip(target.iter().zip(out))
        {
            let norm_sq: f64 = psi_row[..l].iter().map(|x| x * x).sum();
            if norm_sq > f64::EPSILON {
                let s = (t - o) / norm_sq;
                for (w, psi) in w_row[..l].iter_mut().zip(&psi_row[..l]) {
                    *w += psi * s;
                }
            }
        }
    }

    /// Projection onto ||W-hat_k|| <= `bound` for every axis (scales a weight vector that left the ball
    /// back onto its surface).
    pub fn project(&mut self, bound: f64) {
        for row in self.weights.iter_mut() {
            let n = row[..self.l].iter().map(|w| w * w).sum::<f64>().sqrt();
            if n > bound {
                let s = bound / n;
                for w in row[..self.l].iter_mut() {
                    *w *= s;
                }
            }
        }
    }

    /// Frobenius norm of the weights.
    pub fn weight_norm(&self) -> f64 {
        self.weights
            .iter()
            .flat_map(|r| r[..self.l].iter())
            .map(|w| w * w)
            .sum::<f64>()
            .sqrt()
    }
}

/// A small deterministic generator (SplitMix64) for the initial weights: the paper draws them randomly;
/// a seed keeps runs reproducible and identical across runners.
pub fn uniform(seed: u64, k: usize, j: usize) -> f64 {
    let mut z =
        seed.wrapping_add(0x9E37_79B9_7F4A_7C15_u64.wrapping_mul((k * MAX_NEURONS + j + 1) as u64));
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^= z >> 31;
    (z >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A re-seeded network outputs the target at the input it was re-seeded at, on every axis, and
    /// the change is the smallest one: along Psi only.
    #[test]
    fn a_reseeded_network_outputs_the_target_at_its_input() {
        let mut nn = Rbfnn::new(10, 5, 20.0, 2.0, 0.88, None, |k, j| 0.05 * uniform(7, k, j));
        let (p, v) = ([1.0, 15.0, 5.0], [0.3, -0.8, 0.0]);
        let before = nn.weight_norm();
        nn.reseed(p, v, [0.5, 0.99, -0.2]);
        let out = nn.evaluate(p, v);
        for (o, t) in out.iter().zip([0.5, 0.99, -0.2]) {
            assert!((o - t).abs() < 1e-12, "{out:?}");
        }
        assert!(nn.weight_norm() > before);
    }

    /// D24: with c_P set, the basis has the same norm at every position of an axis (the plain
    /// Gaussians' norm falls 6.6x from an outer centre to midway between the two), and the
    /// velocity factors are untouched.
    #[test]
    fn scaled_position_factors_give_the_same_basis_norm_everywhere() {
        let norm_sq = |nn: &Rbfnn| -> f64 { nn.psi[1][..nn.l].iter().map(|x| x * x).sum() };
        let mut plain = Rbfnn::new(10, 5, 20.0, 2.0, 0.88, None, |_, _| 0.0);
        let mut scaled = Rbfnn::new(10, 5, 20.0, 2.0, 0.88, Some(1.0), |_, _| 0.0);
        let at = |nn: &mut Rbfnn, y: f64| {
            nn.evaluate([0.0, y, 0.0], [0.0, 0.3, 0.0]);
            norm_sq(nn)
        };
        let (edge, mid) = (at(&mut plain, 20.0), at(&mut plain, 0.0));
        assert!(edge / mid > 6.0, "{edge} {mid}");
        let reference = at(&mut scaled, 20.0);
        for y in [-25.0, -20.0, -7.0, 0.0, 3.0, 12.0, 20.0, 30.0] {
            let n = at(&mut scaled, y);
            assert!(
                (n - reference).abs() < 1e-12 * reference,
                "{y}: {n} vs {reference}"
            );
        }
        // At an outer centre the plain Gaussians already have a norm of about c_P = 1.
        assert!((edge / reference - 1.0).abs() < 0.01, "{edge} {reference}");
        assert_eq!(position_factor_scale(&[0.0, 0.0], 1.0), 1.0);
    }
}
