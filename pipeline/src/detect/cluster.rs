//! The voxel grid of a window (in x, y and height above the floor), its 26-connected
//! components, and plane peeling for clusters that hold a person and the wall, table or box
//! they touch.

use crate::voxel_hash::{key_of, Key, KeyMap, VoxelHashSet};
use nalgebra::{Matrix3, SymmetricEigen, Vector3};

/// One occupied voxel: the mean of its points (x, y, height above floor).
#[derive(Clone, Copy, Debug)]
pub struct Voxel {
    pub key: Key,
    pub centre: Vector3<f64>,
}

/// The occupied voxels and, for each, its points (indices into the window).
pub struct Grid {
    pub voxels: Vec<Voxel>,
    /// Voxel key to its index in `voxels`.
    index: KeyMap<u32>,
    /// Points of voxel v: `members[offsets[v]..offsets[v + 1]]`.
    offsets: Vec<u32>,
    members: Vec<u32>,
}

impl Grid {
    /// Builds the grid from (point index, x, y, height) of the points kept.
    pub fn new(points: &[(u32, Vector3<f64>)], voxel_m: f64) -> Self {
        let inv = 1.0 / voxel_m;
        let mut map: KeyMap<u32> = KeyMap::default();
        let mut voxel_of = Vec::with_capacity(points.len());
        let mut sums: Vec<(Vector3<f64>, u32)> = Vec::new();
        let mut keys: Vec<Key> = Vec::new();
        for (_, p) in points {
            let key = key_of(p, inv);
            let next = keys.len() as u32;
            let v = *map.entry(key).or_insert(next);
            if v == next {
                keys.push(key);
                sums.push((Vector3::zeros(), 0));
            }
            if let Some(s) = sums.get_mut(v as usize) {
                s.0 += p;
                s.1 += 1;
            }
            voxel_of.push(v);
        }
        // Counting sort of the points by voxel.
        let mut offsets = vec![0u32; keys.len() + 1];
        for &v in &voxel_of {
            if let Some(o) = offsets.get_mut(v as usize + 1) {
                *o += 1;
            }
        }
        for i in 1..offsets.len() {
            offsets[i] += offsets[i - 1];
        }
        let mut fill = offsets.clone();
        let mut members = vec![0u32; voxel_of.len()];
        for ((idx, _), &v) in points.iter().zip(&voxel_of) {
            if let Some(f) = fill.get_mut(v as usize) {
                if let Some(m) = members.get_mut(*f as usize) {
                    *m = *idx;
                }
                *f += 1;
            }
        }
        let voxels = keys
            .into_iter()
            .zip(sums)
            .map(|(key, (sum, n))| Voxel { key, centre: sum / f64::from(n.max(1)) })
            .collect();
        Self { voxels, index: map, offsets, members }
    }

    /// 26-connected components of the whole grid (on the grid's own index).
    pub fn all_components(&self) -> Vec<Vec<u32>> {
        let all: Vec<u32> = (0..self.voxels.len() as u32).collect();
        self.components_on(&all, &self.index)
    }

    /// The window indices of the points in voxel `v`.
    /// The points (indices into the window) of every voxel of `cluster`.
    pub fn points_of_cluster<'a>(&'a self, cluster: &'a [u32]) -> impl Iterator<Item = u32> + 'a {
        cluster.iter().flat_map(|&v| self.points_of(v)).copied()
    }

    pub fn points_of(&self, v: u32) -> &[u32] {
        let (a, b) = (self.offsets.get(v as usize), self.offsets.get(v as usize + 1));
        match (a, b) {
            (Some(&a), Some(&b)) => self.members.get(a as usize..b as usize).unwrap_or(&[]),
            _ => &[],
        }
    }

    /// 26-connected components of a set of voxels (indices into `voxels`).
    pub fn components(&self, subset: &[u32]) -> Vec<Vec<u32>> {
        let mut local: KeyMap<u32> = KeyMap::default();
        local.reserve(subset.len());
        for (i, &v) in subset.iter().enumerate() {
            if let Some(vox) = self.voxels.get(v as usize) {
                local.insert(vox.key, i as u32);
            }
        }
        self.components_on(subset, &local)
    }

    /// [`Self::components`] with `local` mapping each voxel key of `subset` to its position there.
    fn components_on(&self, subset: &[u32], local: &KeyMap<u32>) -> Vec<Vec<u32>> {
        let mut parent: Vec<u32> = (0..subset.len() as u32).collect();
        for (i, &v) in subset.iter().enumerate() {
            let Some(vox) = self.voxels.get(v as usize) else { continue };
            let (x, y, z) = vox.key;
            for (dx, dy, dz) in FORWARD {
                if let Some(&j) = local.get(&(x.wrapping_add(dx), y.wrapping_add(dy), z.wrapping_add(dz))) {
                    union(&mut parent, i as u32, j);
                }
            }
        }
        // Groups indexed by their root (a vector, not a hash map: this runs for every cluster).
        let mut group_of = vec![u32::MAX; subset.len()];
        let mut out: Vec<Vec<u32>> = Vec::new();
        for (i, &v) in subset.iter().enumerate() {
            let root = find(&mut parent, i as u32) as usize;
            let Some(slot) = group_of.get_mut(root) else { continue };
            if *slot == u32::MAX {
                *slot = out.len() as u32;
                out.push(Vec::new());
            }
            if let Some(g) = out.get_mut(*slot as usize) {
                g.push(v);
            }
        }
        // Deterministic order (HashMap iteration is not).
        out.sort_unstable_by_key(|g| g.first().copied().unwrap_or(0));
        out
    }
}

/// Half of the 26 neighbours (the other half finds us).
const FORWARD: [(i32, i32, i32); 13] = [
    (1, 0, 0),
    (-1, 1, 0),
    (0, 1, 0),
    (1, 1, 0),
    (-1, -1, 1),
    (0, -1, 1),
    (1, -1, 1),
    (-1, 0, 1),
    (0, 0, 1),
    (1, 0, 1),
    (-1, 1, 1),
    (0, 1, 1),
    (1, 1, 1),
];

fn find(parent: &mut [u32], mut i: u32) -> u32 {
    while let Some(&p) = parent.get(i as usize) {
        if p == i {
            break;
        }
        // Path halving.
        let gp = parent.get(p as usize).copied().unwrap_or(p);
        if let Some(slot) = parent.get_mut(i as usize) {
            *slot = gp;
        }
        i = gp;
    }
    i
}

fn union(parent: &mut [u32], a: u32, b: u32) {
    let (ra, rb) = (find(parent, a), find(parent, b));
    if ra != rb {
        if let Some(slot) = parent.get_mut(ra.max(rb) as usize) {
            *slot = ra.min(rb);
        }
    }
}

/// The largest plane among a cluster's voxel centres (RANSAC, then a least-squares refit),
/// returned as the voxels on it, when it is larger than `min_length` x `min_width`. Horizontal
/// planes lower than `keep_low_horizontal_m` are not candidates.
pub fn peel_plane(
    grid: &Grid,
    cluster: &[u32],
    tolerance_m: f64,
    min_length_m: f64,
    min_width_m: f64,
    keep_low_horizontal_m: f64,
    seed: u64,
) -> Option<(Vec<u32>, Vec<u32>)> {
    let pts: Vec<Vector3<f64>> =
        cluster.iter().filter_map(|&v| grid.voxels.get(v as usize)).map(|v| v.centre).collect();
    let n = pts.len();
    if n < 10 {
        return None;
    }
    let mut rng = seed ^ (n as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15);
    let mut next = |m: usize| {
        // SplitMix64: deterministic, so detections repeat exactly on the same input.
        rng = rng.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = rng;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        ((z ^ (z >> 31)) % m as u64) as usize
    };
    // Count inliers on a subsample: the plane choice needs no more.
    let stride = (n / 400).max(1);
    let mut best: Option<(usize, Vector3<f64>, f64)> = None;
    for _ in 0..80 {
        let (a, b, c) = (next(n), next(n), next(n));
        let (Some(pa), Some(pb), Some(pc)) = (pts.get(a), pts.get(b), pts.get(c)) else { continue };
        let normal = (pb - pa).cross(&(pc - pa));
        let len = normal.norm();
        if len < 1e-6 {
            continue;
        }
        let normal = normal / len;
        let d = normal.dot(pa);
        // A horizontal plane this low is more likely a person lying against the furniture
        // than furniture: it is never peeled.
        if normal.z.abs() > 0.9 && (d / normal.z).abs() < keep_low_horizontal_m {
            continue;
        }
        let count = pts.iter().step_by(stride).filter(|p| (normal.dot(p) - d).abs() < tolerance_m).count();
        if best.is_none_or(|(c, _, _)| count > c) {
            best = Some((count, normal, d));
        }
    }
    let (_, mut normal, mut d) = best?;
    // Refit on the inliers (PCA), then take the inliers of the refit plane.
    for _ in 0..2 {
        let inl: Vec<&Vector3<f64>> = pts.iter().filter(|p| (normal.dot(p) - d).abs() < tolerance_m).collect();
        if inl.len() < 3 {
            return None;
        }
        let mean = inl.iter().copied().sum::<Vector3<f64>>() / inl.len() as f64;
        let mut cov = Matrix3::zeros();
        for p in &inl {
            let q = *p - mean;
            cov += q * q.transpose();
        }
        let eig = SymmetricEigen::new(cov);
        let k = eig.eigenvalues.imin();
        normal = eig.eigenvectors.column(k).into_owned();
        d = normal.dot(&mean);
    }
    let (mut on, mut off) = (Vec::new(), Vec::new());
    for (&v, p) in cluster.iter().zip(&pts) {
        if (normal.dot(p) - d).abs() < tolerance_m {
            on.push(v);
        } else {
            off.push(v);
        }
    }
    // In-plane extents of the inliers.
    let u = if normal.z.abs() < 0.9 { Vector3::z().cross(&normal) } else { Vector3::x().cross(&normal) };
    let u = u.normalize();
    let w = normal.cross(&u);
    let (mut umin, mut umax, mut wmin, mut wmax) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for &v in &on {
        if let Some(vox) = grid.voxels.get(v as usize) {
            let (a, b) = (u.dot(&vox.centre), w.dot(&vox.centre));
            umin = umin.min(a);
            umax = umax.max(a);
            wmin = wmin.min(b);
            wmax = wmax.max(b);
        }
    }
    let (eu, ew) = (umax - umin, wmax - wmin);
    let (long, short) = if eu >= ew { (eu, ew) } else { (ew, eu) };
    (long >= min_length_m && short >= min_width_m).then_some((on, off))
}

/// For a cluster that is mostly low (at least `min_low_share` of its voxels below `low_m`):
/// the cluster without every voxel column that reaches above `low_m`. It separates a person
/// lying against furniture (a row of seats, a bed's headboard) from it when no plane is large
/// enough to peel. `None` when the cluster is not mostly low or nothing would change.
pub fn drop_tall_columns(grid: &Grid, cluster: &[u32], low_m: f64, min_low_share: f64) -> Option<Vec<u32>> {
    let centre = |v: u32| grid.voxels.get(v as usize);
    let low = cluster.iter().filter(|&&v| centre(v).is_some_and(|c| c.centre.z < low_m)).count();
    if (low as f64) < min_low_share * cluster.len() as f64 {
        return None;
    }
    let tall: VoxelHashSet<(i32, i32)> =
        cluster.iter().filter_map(|&v| centre(v)).filter(|c| c.centre.z >= low_m).map(|c| (c.key.0, c.key.1)).collect();
    let rest: Vec<u32> =
        cluster.iter().copied().filter(|&v| centre(v).is_some_and(|c| !tall.contains(&(c.key.0, c.key.1)))).collect();
    (!rest.is_empty() && rest.len() < cluster.len()).then_some(rest)
}
