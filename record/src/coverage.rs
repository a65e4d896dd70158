//! Coverage of the target's adjacent area: the share of the target disk (radius R around T_g) that lies
//! inside at least one sensor footprint (centre [P_i1, P_i2], radius P_i3 tan(theta_S / 2)).

/// Grid points of the unit-area-weighted disk, relative to its centre, column by column.
#[derive(Debug, Clone)]
pub struct CoverageGrid {
    /// The columns of grid points: their x offset and their points' range in `ys`.
    columns: Vec<Column>,
    /// The y offsets of the grid points, column by column (increasing y within a column).
    ys: Vec<f64>,
    radius: f64,
    half_fov_tan: f64,
    /// Footprints of this step that can reach the disk: centre x, y and squared radius.
    reaching: Vec<[f64; 3]>,
    /// Footprints of this step that can reach the current column: centre y, the squared x
    /// distance of the column from the centre, squared radius.
    near: Vec<[f64; 3]>,
}

/// One column of grid points (a fixed x offset).
#[derive(Debug, Clone, Copy)]
struct Column {
    x: f64,
    /// Its points: `ys[from..to]`.
    from: usize,
    to: usize,
}

/// Points per radius of the square grid (about pi * 12² = 450 points in the disk).
const GRID_PER_RADIUS: i32 = 12;

/// Slack of the reach test, m: a footprint whose centre is farther than R + r + this from the
/// disk's centre cannot hold a grid point (whose distance from the centre is R up to rounding).
const REACH_SLACK_M: f64 = 1e-6;

impl CoverageGrid {
    /// A grid over the disk of radius `radius` for sensors of full angle of view `fov_deg`.
    pub fn new(radius: f64, fov_deg: f64) -> CoverageGrid {
        let h = radius / GRID_PER_RADIUS as f64;
        let mut columns = Vec::new();
        let mut ys = Vec::new();
        for ix in -GRID_PER_RADIUS..=GRID_PER_RADIUS {
            let from = ys.len();
            for iy in -GRID_PER_RADIUS..=GRID_PER_RADIUS {
                let (x, y) = (ix as f64 * h, iy as f64 * h);
                if x * x + y * y <= radius * radius {
                    ys.push(y);
                }
            }
            if ys.len() > from {
                let x = ix as f64 * h;
                let to = ys.len();
                columns.push(Column { x, from, to });
            }
        }
        CoverageGrid {
            columns,
            ys,
            radius,
            half_fov_tan: (fov_deg.to_radians() * 0.5).tan(),
            reaching: Vec::new(),
            near: Vec::new(),
        }
    }

    /// Covered share (0..1) of the disk centred on `target` by sensors at `positions`. A grid point
    /// [x, y] is covered when it lies in at least one footprint: (x - c_x)² + (y - c_y)² at most
    /// r², with the footprint's centre c = [P_i1, P_i2] and radius r = P_i3 tan(theta_S / 2).
    ///
    /// Computed column by column, every point's answer bit for bit the one of that definition:
    /// footprints that cannot reach the disk are left out first; in a column (one x for all its
    /// points) (x - c_x)² is computed once per footprint, and a footprint whose (x - c_x)² alone
    /// exceeds r² is left out of the column (a sum of it and a square is never smaller, rounding
    /// included). A footprint holds a contiguous run of a column's points (y - c_y is monotonic
    /// in y and the rounded sum monotonic in |y - c_y|), so a column whose first and last points
    /// it holds is covered whole.
    pub fn covered_fraction(
        &mut self,
        target: [f64; 2],
        positions: impl Iterator<Item = [f64; 3]>,
    ) -> f64 {
        self.reaching.clear();
        for q in positions {
            let r = q[2].max(0.0) * self.half_fov_tan;
            let (dx, dy) = (q[0] - target[0], q[1] - target[1]);
            let reach = self.radius + r + REACH_SLACK_M;
            if dx * dx + dy * dy <= reach * reach {
                self.reaching.push([q[0], q[1], r * r]);
            }
        }
        let holds = |n: &[f64; 3], y: f64| {
            let dy = y - n[0];
            n[1] + dy * dy <= n[2]
        };
        let mut covered = 0usize;
        for col in &self.columns {
            let x = target[0] + col.x;
            self.near.clear();
            for f in &self.reaching {
                let dx = x - f[0];
                let dx2 = dx * dx;
                if dx2 <= f[2] {
                    self.near.push([f[1], dx2, f[2]]);
                }
            }
            if self.near.is_empty() {
                continue;
            }
            let ys = &self.ys[col.from..col.to];
            let (first, last) = (target[1] + ys[0], target[1] + ys[ys.len() - 1]);
            if self.near.iter().any(|n| holds(n, first) && holds(n, last)) {
                covered += ys.len();
                continue;
            }
            for py in ys {
                let y = target[1] + py;
                if self.near.iter().any(|n| holds(n, y)) {
                    covered += 1;
                }
            }
        }
        covered as f64 / self.ys.len() as f64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The grid points, [x, y] relative to the disk's centre.
    fn points(g: &CoverageGrid) -> Vec<[f64; 2]> {
        g.columns
            .iter()
            .flat_map(|c| g.ys[c.from..c.to].iter().map(move |&y| [c.x, y]))
            .collect()
    }

    /// The definition, point by point over every footprint.
    fn brute_force(g: &CoverageGrid, target: [f64; 2], positions: &[[f64; 3]]) -> f64 {
        let points = points(g);
        let hits = points
            .iter()
            .filter(|p| {
                let (x, y) = (target[0] + p[0], target[1] + p[1]);
                positions.iter().any(|q| {
                    let r = q[2].max(0.0) * g.half_fov_tan;
                    let (dx, dy) = (x - q[0], y - q[1]);
                    dx * dx + dy * dy <= r * r
                })
            })
            .count();
        hits as f64 / points.len() as f64
    }

    #[test]
    fn the_column_by_column_count_gives_the_definition_bit_for_bit_on_random_swarms() {
        let mut rng = crate::rng::SplitMix64::new(21);
        let mut g = CoverageGrid::new(3.5, 50.0);
        let h = 3.5 / GRID_PER_RADIUS as f64;
        for case in 0..3000 {
            let target = [40.0 * rng.unit() - 20.0, 40.0 * rng.unit() - 20.0];
            let n = 1 + rng.below(8);
            let positions: Vec<[f64; 3]> = (0..n)
                .map(|_| {
                    let mut q = [
                        target[0] + 12.0 * rng.unit() - 6.0,
                        target[1] + 12.0 * rng.unit() - 6.0,
                        8.0 * rng.unit() - 1.0,
                    ];
                    if case % 3 == 0 {
                        // Centre on a grid line and radius through a grid point: footprint
                        // edges exactly on points (the ties of <=).
                        let (ix, iy) = (rng.below(25) as f64 - 12.0, rng.below(25) as f64 - 12.0);
                        q[0] = target[0] + ix * h;
                        q[1] = target[1] + iy * h;
                        let k = rng.below(8) as f64;
                        q[2] = k * h / g.half_fov_tan;
                    }
                    q
                })
                .collect();
            let want = brute_force(&g, target, &positions);
            let got = g.covered_fraction(target, positions.iter().copied());
            assert_eq!(
                got.to_bits(),
                want.to_bits(),
                "case {case}: {got} vs {want}"
            );
        }
    }

    #[test]
    fn leaving_out_footprints_that_cannot_reach_the_disk_changes_no_coverage_value() {
        let mut g = CoverageGrid::new(3.5, 50.0);
        let target = [1.25, -14.75];
        let mut positions = Vec::new();
        // Rings of sensors from inside the disk to far outside it, at several heights.
        for k in 0..120 {
            let (a, rad) = (k as f64 * 0.7, 0.3 * k as f64);
            let h = [5.0, 3.0, 0.0, -1.0, 8.0][k % 5];
            positions.push([target[0] + rad * a.cos(), target[1] + rad * a.sin(), h]);
        }
        for n in [1, 3, 5, 20, 60, 120] {
            let want = brute_force(&g, target, &positions[..n]);
            let got = g.covered_fraction(target, positions[..n].iter().copied());
            assert_eq!(got.to_bits(), want.to_bits(), "n = {n}: {got} vs {want}");
        }
        // The paper's five cover slots at 5 m cover the whole disk; nobody at all covers nothing.
        let five: Vec<[f64; 3]> = (0..5)
            .map(|i| {
                let a = std::f64::consts::FRAC_PI_2 + 0.4 * std::f64::consts::PI * i as f64;
                [target[0] + 2.0 * a.cos(), target[1] + 2.0 * a.sin(), 5.0]
            })
            .collect();
        assert_eq!(g.covered_fraction(target, five.into_iter()), 1.0);
        assert_eq!(g.covered_fraction(target, std::iter::empty()), 0.0);
    }
}
