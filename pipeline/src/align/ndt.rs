//! Coarse stage: multi-resolution NDT (Biber and Strasser; the score of Magnusson 2009),
//! Gauss-Newton on SE(3) with left-multiplied updates.
//!
//! The target is cut into cubic cells; each cell with enough points becomes a Gaussian. A source
//! point `x` moved by `T` scores `-d1 exp(-d2/2 · rᵀ Σ⁻¹ r)` against each Gaussian of its own cell
//! and its six face neighbours (`r = T x - μ`). Minimising `Σ d1 exp(..)` by Gauss-Newton is an
//! iteratively re-weighted least squares on `rᵀ Σ⁻¹ r` with weight `-d1 d2 exp(..)`, which is what
//! [`refine_level`] does, with a backtracking step so the score never gets worse.

use super::geometry::{exp_se3, Vec3};
use crate::voxel_hash::{key_of, KeyMap};
use nalgebra::{Isometry3, Matrix3, Matrix6, SymmetricEigen, Vector6};

/// Normal distribution of the target points in one cell (mean and inverse covariance).
struct Cell {
    mean: Vec3,
    info: Matrix3<f64>,
}

/// The target as NDT cells of one size.
pub struct NdtGrid {
    inv_cell_m: f64,
    cells: KeyMap<Cell>,
    d1: f64,
    d2: f64,
}

/// Fewer points than this do not make a Gaussian.
const MIN_CELL_POINTS: usize = 6;

impl NdtGrid {
    pub fn new(target: &[Vec3], cell_m: f64, outlier_ratio: f64) -> Self {
        let inv_cell_m = 1.0 / cell_m;
        let mut buckets: KeyMap<Vec<Vec3>> = KeyMap::default();
        for p in target {
            buckets.entry(key_of(p, inv_cell_m)).or_default().push(*p);
        }
        let mut cells = KeyMap::default();
        for (key, pts) in buckets {
            if pts.len() < MIN_CELL_POINTS {
                continue;
            }
            let n = pts.len() as f64;
            let mean = pts.iter().sum::<Vec3>() / n;
            let mut cov = Matrix3::zeros();
            for p in &pts {
                let d = p - mean;
                cov += d * d.transpose();
            }
            cov /= n - 1.0;
            // Flat cells (walls, floor) have a near-zero eigenvalue; clamping it to 1% of the
            // largest keeps the inverse bounded (Magnusson's regularisation).
            let eig = SymmetricEigen::new(cov);
            let max = eig.eigenvalues.max();
            if max.is_nan() || max <= 0.0 {
                continue;
            }
            let floor = (max * 0.01).max(1e-6);
            let inv_vals = eig.eigenvalues.map(|l| 1.0 / l.max(floor));
            let info = eig.eigenvectors * Matrix3::from_diagonal(&inv_vals) * eig.eigenvectors.transpose();
            cells.insert(key, Cell { mean, info });
        }
        // Constants of the mixed Gaussian/uniform score (Magnusson 2009, eq. 6.8).
        let c1 = 10.0 * (1.0 - outlier_ratio);
        let c2 = outlier_ratio / (cell_m * cell_m * cell_m);
        let d3 = -c2.ln();
        let d1 = -(c1 + c2).ln() - d3;
        let d2 = -2.0 * ((-(c1 * (-0.5f64).exp() + c2).ln() - d3) / d1).ln();
        Self { inv_cell_m, cells, d1, d2 }
    }

    pub fn cell_count(&self) -> usize {
        self.cells.len()
    }

    /// Score (lower is better) of `source` moved by `t`, and how many of its points matched a cell.
    pub fn score(&self, source: &[Vec3], t: &Isometry3<f64>) -> (f64, usize) {
        self.evaluate(source, t, None)
    }

    /// Score (lower is better), and when `normal` is given, the Gauss-Newton system (H, g).
    fn evaluate(
        &self,
        source: &[Vec3],
        t: &Isometry3<f64>,
        mut normal: Option<(&mut Matrix6<f64>, &mut Vector6<f64>)>,
    ) -> (f64, usize) {
        const NEIGHBOURS: [(i32, i32, i32); 7] =
            [(0, 0, 0), (1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1)];
        let mut score = 0.0;
        let mut matched = 0usize;
        for p in source {
            let q = t * nalgebra::Point3::from(*p);
            let q = q.coords;
            let (x, y, z) = key_of(&q, self.inv_cell_m);
            let mut hit = false;
            for (dx, dy, dz) in NEIGHBOURS {
                let Some(cell) = self.cells.get(&(x.saturating_add(dx), y.saturating_add(dy), z.saturating_add(dz)))
                else {
                    continue;
                };
                let r = q - cell.mean;
                let ir = cell.info * r;
                let m = r.dot(&ir);
                let e = (-0.5 * self.d2 * m).exp();
                if e < 1e-12 {
                    continue;
                }
                hit = true;
                score += self.d1 * e;
                if let Some((h, g)) = normal.as_mut() {
                    let w = -self.d1 * self.d2 * e;
                    // dq/dxi = [-[q]x | I]
                    let mut j = nalgebra::Matrix3x6::zeros();
                    j.fixed_view_mut::<3, 3>(0, 0).copy_from(&(-q.cross_matrix()));
                    j.fixed_view_mut::<3, 3>(0, 3).copy_from(&Matrix3::identity());
                    let ji = j.transpose() * cell.info;
                    **h += w * (ji * j);
                    **g += w * (ji * r);
                }
            }
            if hit {
                matched += 1;
            }
        }
        (score, matched)
    }
}

/// Outcome of one NDT level.
pub struct LevelResult {
    pub pose: Isometry3<f64>,
    pub iterations: u32,
}

/// Gauss-Newton on one grid from `pose`.
pub fn refine_level(grid: &NdtGrid, source: &[Vec3], pose: Isometry3<f64>, max_iterations: u32) -> LevelResult {
    let mut pose = pose;
    let mut iterations = 0;
    let (mut score, _) = grid.evaluate(source, &pose, None);
    for _ in 0..max_iterations {
        iterations += 1;
        let mut h = Matrix6::zeros();
        let mut g = Vector6::zeros();
        grid.evaluate(source, &pose, Some((&mut h, &mut g)));
        // A little Levenberg damping keeps the step finite in directions the cells do not constrain.
        let damping = 1e-6 * h.trace().max(1e-9);
        let Some(chol) = (h + Matrix6::identity() * damping).cholesky() else { break };
        let step = -chol.solve(&g);
        let mut scale = 1.0;
        let mut improved = false;
        for _ in 0..6 {
            let candidate = exp_se3(&(step * scale)) * pose;
            let (s, _) = grid.evaluate(source, &candidate, None);
            if s <= score {
                pose = candidate;
                score = s;
                improved = true;
                break;
            }
            scale *= 0.5;
        }
        if !improved || (step * scale).norm() < 1e-4 {
            break;
        }
    }
    LevelResult { pose, iterations }
}
