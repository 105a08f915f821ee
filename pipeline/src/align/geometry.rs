//! Points, poses and the voxel-hash neighbour index (on the grid of [`crate::voxel_hash`]).

use crate::cloud::PointCloud;
use crate::voxel_hash::{gap2, key_of, Key, KeyMap, NEIGHBOURS};
use nalgebra::{Isometry3, Matrix3, Rotation3, SymmetricEigen, Translation3, UnitQuaternion, Vector3, Vector6};

pub type Vec3 = Vector3<f64>;

/// The finite, non-zero points of a cloud in f64.
pub fn cloud_points(cloud: &PointCloud) -> Vec<Vec3> {
    cloud
        .points
        .iter()
        .filter(|p| !p.is_zero() && p.x_m.is_finite() && p.y_m.is_finite() && p.z_m.is_finite())
        .map(|p| Vec3::new(f64::from(p.x_m), f64::from(p.y_m), f64::from(p.z_m)))
        .collect()
}

/// Points bucketed by voxel for radius-bounded neighbour queries (the 27 cells around a query).
/// Queries find every neighbour within `cell_m` of the query, and some farther ones.
pub struct VoxelIndex {
    inv_cell_m: f64,
    cell_m: f64,
    /// Indices into `points`, grouped by voxel; `cells` maps a voxel to its range here.
    order: Vec<u32>,
    /// `points` in `order`: a cell's points side by side in memory (the nearest-neighbour scan
    /// reads them in one run instead of jumping through `points`).
    grouped: Vec<Vec3>,
    cells: KeyMap<(u32, u32)>,
    pub points: Vec<Vec3>,
}

impl VoxelIndex {
    pub fn new(points: Vec<Vec3>, cell_m: f64) -> Self {
        let cell_m = cell_m.max(1e-6);
        let inv_cell_m = 1.0 / cell_m;
        let mut keyed: Vec<(Key, u32)> =
            points.iter().enumerate().map(|(i, p)| (key_of(p, inv_cell_m), i as u32)).collect();
        keyed.sort_unstable();
        let mut cells = KeyMap::default();
        let mut start = 0usize;
        while start < keyed.len() {
            let key = keyed[start].0;
            let mut end = start;
            while end < keyed.len() && keyed[end].0 == key {
                end += 1;
            }
            cells.insert(key, (start as u32, end as u32));
            start = end;
        }
        let order: Vec<u32> = keyed.into_iter().map(|k| k.1).collect();
        let grouped = order.iter().filter_map(|&i| points.get(i as usize).copied()).collect();
        Self { inv_cell_m, cell_m, order, grouped, cells, points }
    }

    /// Calls `f(index, squared distance)` for every point of one cell.
    #[inline]
    fn scan_cell(&self, key: Key, q: &Vec3, f: &mut impl FnMut(u32, f64)) {
        let Some(&(a, b)) = self.cells.get(&key) else { return };
        let (a, b) = (a as usize, b as usize);
        if let (Some(points), Some(order)) = (self.grouped.get(a..b), self.order.get(a..b)) {
            for (p, &i) in points.iter().zip(order) {
                f(i, (p - q).norm_squared());
            }
        }
    }

    fn for_each_near(&self, q: &Vec3, mut f: impl FnMut(u32, f64)) {
        let (x, y, z) = key_of(q, self.inv_cell_m);
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    self.scan_cell((x.saturating_add(dx), y.saturating_add(dy), z.saturating_add(dz)), q, &mut f);
                }
            }
        }
    }

    /// Nearest point within `max_m` (which should not exceed the cell size): (index, squared
    /// distance). The query's own cell is searched first; a neighbouring cell only while the
    /// nearest point it could hold is nearer than the best so far.
    pub fn nearest(&self, q: &Vec3, max_m: f64) -> Option<(usize, f64)> {
        self.nearest_where(q, max_m, |_| true)
    }

    /// [`Self::nearest`] among the points whose index `accept` takes.
    pub fn nearest_where(&self, q: &Vec3, max_m: f64, accept: impl Fn(usize) -> bool) -> Option<(usize, f64)> {
        let max2 = max_m * max_m;
        let mut best: Option<(usize, f64)> = None;
        let key = key_of(q, self.inv_cell_m);
        for d in std::iter::once((0, 0, 0)).chain(NEIGHBOURS) {
            if gap2([q.x, q.y, q.z], key, self.cell_m, d) > best.map_or(max2, |b| b.1) {
                continue;
            }
            let cell = (key.0.saturating_add(d.0), key.1.saturating_add(d.1), key.2.saturating_add(d.2));
            self.scan_cell(cell, q, &mut |i, d2| {
                if d2 <= max2 && best.is_none_or(|b| d2 < b.1) && accept(i as usize) {
                    best = Some((i as usize, d2));
                }
            });
        }
        best
    }

    /// Up to `k` nearest points within one cell size, into `out` as (squared distance, index).
    pub fn k_nearest(&self, q: &Vec3, k: usize, out: &mut Vec<(f64, u32)>) {
        out.clear();
        let max2 = 1.0 / (self.inv_cell_m * self.inv_cell_m);
        self.for_each_near(q, |i, d2| {
            if d2 <= max2 {
                out.push((d2, i));
            }
        });
        if out.len() > k {
            out.select_nth_unstable_by(k, |a, b| a.0.total_cmp(&b.0));
            out.truncate(k);
        }
    }
}

/// The shape of a neighbourhood: the unit normal (eigenvector of the smallest eigenvalue of the
/// points' covariance) and the eigenvalues, smallest first.
#[derive(Clone, Copy, Debug)]
pub struct LocalShape {
    pub normal: Vec3,
    pub eigenvalues: [f64; 3],
}

impl LocalShape {
    /// Smallest eigenvalue over their sum: 0 on a plane, 1/3 for scattered points.
    pub fn curvature(&self) -> f64 {
        let total: f64 = self.eigenvalues.iter().sum();
        if total > 0.0 {
            self.eigenvalues[0].max(0.0) / total
        } else {
            0.0
        }
    }
}

/// PCA of the `k` nearest neighbours of each point within the index's cell; `None` where fewer
/// than 5 are found.
pub fn local_shapes(index: &VoxelIndex, k: usize) -> Vec<Option<LocalShape>> {
    let mut nn = Vec::with_capacity(k.min(256));
    index
        .points
        .iter()
        .map(|p| {
            index.k_nearest(p, k, &mut nn);
            if nn.len() < 5 {
                return None;
            }
            let near = nn.iter().filter_map(|&(_, i)| index.points.get(i as usize));
            let mean = near.clone().sum::<Vec3>() / nn.len() as f64;
            let cov = near.fold(Matrix3::zeros(), |acc, q| acc + (q - mean) * (q - mean).transpose());
            let eig = SymmetricEigen::new(cov);
            let mut idx = [0usize, 1, 2];
            idx.sort_by(|&a, &b| eig.eigenvalues[a].total_cmp(&eig.eigenvalues[b]));
            let normal: Vec3 = eig.eigenvectors.column(idx[0]).into_owned();
            let eigenvalues = idx.map(|i| eig.eigenvalues[i]);
            (normal.norm() > 0.0).then(|| LocalShape { normal: normal.normalize(), eigenvalues })
        })
        .collect()
}

/// PCA normals from the `k` nearest neighbours within `radius_m`; `None` where fewer than 5
/// neighbours are found or the neighbourhood is not plane-like (smallest eigenvalue above a third
/// of the middle one: a corner or scattered points, where a plane has no meaning).
pub fn estimate_normals(points: &[Vec3], radius_m: f64, k: usize) -> Vec<Option<Vec3>> {
    let index = VoxelIndex::new(points.to_vec(), radius_m);
    local_shapes(&index, k)
        .into_iter()
        .map(|s| {
            let s = s?;
            let [l0, l1, _] = s.eigenvalues;
            (l1 > 0.0 && l0 <= l1 / 3.0).then_some(s.normal)
        })
        .collect()
}

/// At most `max` of `items`, taken evenly through them (the voxel order spreads points in
/// space); all of them when `max` is 0.
pub fn thin<T: Copy>(items: Vec<T>, max: usize) -> Vec<T> {
    if items.len() <= max || max == 0 {
        return items;
    }
    let step = items.len() as f64 / max as f64;
    (0..max).filter_map(|i| items.get((i as f64 * step) as usize).copied()).collect()
}

/// SE(3) exponential of a twist (rotation vector first, then translation), as used for the
/// left-multiplied updates `T <- exp(xi) T` of both solvers. The translation part is applied
/// directly (first-order), which is exact enough for the small steps a solver takes.
pub fn exp_se3(xi: &Vector6<f64>) -> Isometry3<f64> {
    let rot = UnitQuaternion::from_scaled_axis(Vec3::new(xi[0], xi[1], xi[2]));
    Isometry3::from_parts(Translation3::new(xi[3], xi[4], xi[5]), rot)
}

/// A pose from x, y, z and yaw (degrees, about +z).
pub fn pose_xyz_yaw(x_m: f64, y_m: f64, z_m: f64, yaw_deg: f64) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(x_m, y_m, z_m),
        UnitQuaternion::from_euler_angles(0.0, 0.0, yaw_deg.to_radians()),
    )
}

/// A pose from a row-major 4x4 matrix; `None` when the rotation block is not a rotation.
pub fn pose_from_rows(m: &[[f64; 4]; 4]) -> Option<Isometry3<f64>> {
    let r = Matrix3::new(m[0][0], m[0][1], m[0][2], m[1][0], m[1][1], m[1][2], m[2][0], m[2][1], m[2][2]);
    if !r.iter().all(|v| v.is_finite())
        || ((r.transpose() * r) - Matrix3::identity()).norm() > 1e-3
        || r.determinant() < 0.0
    {
        return None;
    }
    let rot = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix(&r));
    Some(Isometry3::from_parts(Translation3::new(m[0][3], m[1][3], m[2][3]), rot))
}

/// Row-major 4x4 matrix of a pose.
pub fn pose_rows(t: &Isometry3<f64>) -> [[f64; 4]; 4] {
    let m = t.to_homogeneous();
    let mut rows = [[0.0; 4]; 4];
    for (r, row) in rows.iter_mut().enumerate() {
        for (c, v) in row.iter_mut().enumerate() {
            *v = m[(r, c)];
        }
    }
    rows
}

/// Translation (m) and rotation (deg) between two poses.
pub fn pose_error(a: &Isometry3<f64>, b: &Isometry3<f64>) -> (f64, f64) {
    let d = a.inverse() * b;
    (d.translation.vector.norm(), d.rotation.angle().to_degrees())
}
