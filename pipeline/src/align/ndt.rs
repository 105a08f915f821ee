//! Coarse stage: multi-resolution NDT (Biber and Strasser; the score of Magnusson 2009),
//! Gauss-Newton on SE(3) with left-multiplied updates.
//!
//! The target is cut into cubic cells; each cell with enough points becomes a Gaussian. A source
//! point `x` moved by `T` scores `-d1 exp(-d2/2 · rᵀ Σ⁻¹ r)` against each Gaussian of its own cell
//! and its six face neighbours (`r = T x - μ`). Minimising `Σ d1 exp(..)` by Gauss-Newton is an
//! iteratively re-weighted least squares on `rᵀ Σ⁻¹ r` with weight `-d1 d2 exp(..)`, which is what
//! [`refine_level`] does, with a backtracking step so the score never gets worse.

use super::geometry::{exp_se3, Vec3};
use super::seen_from::{seen_from_opposite_sides, unit_and_side, SeenFrom};
use crate::voxel_hash::{key_of, KeyMap, VoxelHashMap};
use nalgebra::{Isometry3, Matrix3, Matrix6, SymmetricEigen, Vector6};

/// Normal distribution of the target points in one cell (mean and inverse covariance), and
/// where known the side they were seen from: the mean direction towards their sensors, and the
/// direction the points spread least along (a flat cell's normal).
struct Cell {
    mean: Vec3,
    info: Matrix3<f64>,
    seen_from: Vec3,
    normal: Vec3,
}

/// The target as NDT cells of one size. Where the target's sides are known, each cell holds a
/// Gaussian per side (the two faces of a wall thinner than a cell are two), and a source point
/// seen from the other side of a cell's plane does not score against it.
pub struct NdtGrid {
    inv_cell_m: f64,
    cells: KeyMap<Vec<Cell>>,
    d1: f64,
    d2: f64,
    opposite_min_side: f64,
}

/// Fewer points than this do not make a Gaussian.
const MIN_CELL_POINTS: usize = 6;

impl NdtGrid {
    /// The target's Gaussians; knowing, for each target point, the direction towards the sensor that saw
    /// it (`towards_sensor`, same length; otherwise none known); a source point is kept off a
    /// cell seen from the other side of its plane, each at least `opposite_min_side` along its
    /// normal (see [`super::seen_from`]).
    pub fn new_sided(
        target: &[Vec3],
        towards_sensor: &[Vec3],
        cell_m: f64,
        outlier_ratio: f64,
        opposite_min_side: f64,
    ) -> Self {
        let inv_cell_m = 1.0 / cell_m;
        let sided = towards_sensor.len() == target.len();
        let mut buckets: VoxelHashMap<(crate::voxel_hash::Key, u8), (Vec<Vec3>, Vec3)> = VoxelHashMap::default();
        for (i, p) in target.iter().enumerate() {
            let towards = if sided { towards_sensor.get(i).copied() } else { None };
            let (unit, side) = unit_and_side(&towards.unwrap_or_else(Vec3::zeros));
            let e = buckets.entry((key_of(p, inv_cell_m), side)).or_default();
            e.0.push(*p);
            e.1 += unit;
        }
        let mut cells: KeyMap<Vec<Cell>> = KeyMap::default();
        let mut keys: Vec<_> = buckets.keys().copied().collect();
        keys.sort_unstable();
        for key in keys {
            let Some((pts, dir)) = buckets.get(&key) else { continue };
            if let Some(mut cell) = gaussian(pts) {
                cell.seen_from = dir / pts.len().max(1) as f64;
                cells.entry(key.0).or_default().push(cell);
            }
        }
        // Constants of the mixed Gaussian/uniform score (Magnusson 2009, eq. 6.8).
        let c1 = 10.0 * (1.0 - outlier_ratio);
        let c2 = outlier_ratio / (cell_m * cell_m * cell_m);
        let d3 = -c2.ln();
        let d1 = -(c1 + c2).ln() - d3;
        let d2 = -2.0 * ((-(c1 * (-0.5f64).exp() + c2).ln() - d3) / d1).ln();
        Self { inv_cell_m, cells, d1, d2, opposite_min_side }
    }

    pub fn cell_count(&self) -> usize {
        self.cells.len()
    }

    /// Score (lower is better) of `source` moved by `t`, and how many of its points matched a cell.
    pub fn score(&self, source: &[Vec3], t: &Isometry3<f64>) -> (f64, usize) {
        self.evaluate(source, &[], t, None)
    }

    /// Score (lower is better), and when `normal` is given, the Gauss-Newton system (H, g).
    fn evaluate(
        &self,
        source: &[Vec3],
        sides: &[Vec3],
        t: &Isometry3<f64>,
        mut normal: Option<(&mut Matrix6<f64>, &mut Vector6<f64>)>,
    ) -> (f64, usize) {
        const NEIGHBOURS: [(i32, i32, i32); 7] =
            [(0, 0, 0), (1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1)];
        let mut score = 0.0;
        let mut matched = 0usize;
        for (k, p) in source.iter().enumerate() {
            let q = t * nalgebra::Point3::from(*p);
            let q = q.coords;
            let side = sides.get(k).map(|a| t.rotation * a);
            let (x, y, z) = key_of(&q, self.inv_cell_m);
            // dq/dxi = [-[q]x | I], the same for every cell the point scores against.
            let j = normal.is_some().then(|| {
                let mut j = nalgebra::Matrix3x6::zeros();
                j.fixed_view_mut::<3, 3>(0, 0).copy_from(&(-q.cross_matrix()));
                j.fixed_view_mut::<3, 3>(0, 3).copy_from(&Matrix3::identity());
                j
            });
            let mut hit = false;
            for (dx, dy, dz) in NEIGHBOURS {
                let Some(here) = self.cells.get(&(x.saturating_add(dx), y.saturating_add(dy), z.saturating_add(dz)))
                else {
                    continue;
                };
                for cell in here {
                    if side.is_some_and(|a| {
                        seen_from_opposite_sides(&cell.normal, &a, &cell.seen_from, self.opposite_min_side)
                    }) {
                        continue;
                    }
                    let r = q - cell.mean;
                    let ir = cell.info * r;
                    let m = r.dot(&ir);
                    let e = (-0.5 * self.d2 * m).exp();
                    if e < 1e-12 {
                        continue;
                    }
                    hit = true;
                    score += self.d1 * e;
                    if let (Some((h, g)), Some(j)) = (normal.as_mut(), &j) {
                        let w = -self.d1 * self.d2 * e;
                        let ji = j.transpose() * cell.info;
                        **h += w * (ji * j);
                        **g += w * (ji * r);
                    }
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

/// Gauss-Newton on one grid from `pose`; `seen` tells which side the source's surfaces were seen from (empty: unknown).
pub fn refine_level(
    grid: &NdtGrid,
    source: &[Vec3],
    seen: &SeenFrom,
    pose: Isometry3<f64>,
    max_iterations: u32,
) -> LevelResult {
    let mut pose = pose;
    let mut iterations = 0;
    let sides = seen.at_each(source, grid.opposite_min_side);
    let (mut score, _) = grid.evaluate(source, &sides, &pose, None);
    for _ in 0..max_iterations {
        iterations += 1;
        let mut h = Matrix6::zeros();
        let mut g = Vector6::zeros();
        grid.evaluate(source, &sides, &pose, Some((&mut h, &mut g)));
        // A little Levenberg damping keeps the step finite in directions the cells do not constrain.
        let damping = 1e-6 * h.trace().max(1e-9);
        let Some(chol) = (h + Matrix6::identity() * damping).cholesky() else { break };
        let step = -chol.solve(&g);
        let mut scale = 1.0;
        let mut improved = false;
        for _ in 0..6 {
            let candidate = exp_se3(&(step * scale)) * pose;
            let (s, _) = grid.evaluate(source, &sides, &candidate, None);
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

/// The Gaussian of a cell's points (at least [`MIN_CELL_POINTS`]), its sides not yet known.
fn gaussian(pts: &[Vec3]) -> Option<Cell> {
    if pts.len() < MIN_CELL_POINTS {
        return None;
    }
    let n = pts.len() as f64;
    let mean = pts.iter().sum::<Vec3>() / n;
    let mut cov = Matrix3::zeros();
    for p in pts {
        let d = p - mean;
        cov += d * d.transpose();
    }
    cov /= n - 1.0;
    // Flat cells (walls, floor) have a near-zero eigenvalue; clamping it to 1% of the
    // largest keeps the inverse bounded (Magnusson's regularisation).
    let eig = SymmetricEigen::new(cov);
    let max = eig.eigenvalues.max();
    if max.is_nan() || max <= 0.0 {
        return None;
    }
    let normal = eig.eigenvectors.column(eig.eigenvalues.imin()).into_owned();
    let floor = (max * 0.01).max(1e-6);
    let inv_vals = eig.eigenvalues.map(|l| 1.0 / l.max(floor));
    let info = eig.eigenvectors * Matrix3::from_diagonal(&inv_vals) * eig.eigenvectors.transpose();
    Some(Cell { mean, info, seen_from: Vec3::zeros(), normal })
}
