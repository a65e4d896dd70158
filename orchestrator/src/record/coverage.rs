//! Coverage of the target's adjacent area: the share of the target disk (radius R around T_g) that lies
//! inside at least one sensor footprint (centre [P_i1, P_i2], radius P_i3 tan(theta_S / 2)).

/// Grid points of the unit-area-weighted disk, relative to its centre.
#[derive(Debug, Clone)]
pub struct CoverageGrid {
    points: Vec<[f64; 2]>,
    half_fov_tan: f64,
}

/// Points per radius of the square grid (about pi * 12² = 450 points in the disk).
const GRID_PER_RADIUS: i32 = 12;

impl CoverageGrid {
    /// A grid over the disk of radius `radius` for sensors of full angle of view `fov_deg`.
    pub fn new(radius: f64, fov_deg: f64) -> CoverageGrid {
        let h = radius / GRID_PER_RADIUS as f64;
        let mut points = Vec::new();
        for ix in -GRID_PER_RADIUS..=GRID_PER_RADIUS {
            for iy in -GRID_PER_RADIUS..=GRID_PER_RADIUS {
                let (x, y) = (ix as f64 * h, iy as f64 * h);
                if x * x + y * y <= radius * radius {
                    points.push([x, y]);
                }
            }
        }
        CoverageGrid {
            points,
            half_fov_tan: (fov_deg.to_radians() * 0.5).tan(),
        }
    }

    /// Covered share (0..1) of the disk centred on `target` by sensors at `positions`.
    pub fn covered_fraction(
        &self,
        target: [f64; 2],
        positions: impl Iterator<Item = [f64; 3]> + Clone,
    ) -> f64 {
        let mut covered = 0usize;
        for p in &self.points {
            let (x, y) = (target[0] + p[0], target[1] + p[1]);
            let hit = positions.clone().any(|q| {
                let r = q[2].max(0.0) * self.half_fov_tan;
                let (dx, dy) = (x - q[0], y - q[1]);
                dx * dx + dy * dy <= r * r
            });
            if hit {
                covered += 1;
            }
        }
        covered as f64 / self.points.len() as f64
    }
}
