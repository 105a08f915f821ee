//! A voxel-hash map in the style of iVox: a hash from voxel coordinates to a few points each;
//! nearest neighbours come from the query's voxel and its 26 neighbours. Voxels far from the
//! sensor are dropped, so the map stays local and its cost bounded.

use crate::voxel_hash::{gap2, key_of, Key, KeyMap, NEIGHBOURS};
use nalgebra::Vector3;

#[derive(Clone, Debug)]
pub struct VoxelMap {
    resolution_m: f64,
    inv_resolution: f64,
    per_voxel: usize,
    /// A new point closer than this to one already in its voxel adds nothing.
    min_spacing_m: f64,
    radius_m: f64,
    voxels: KeyMap<Vec<Vector3<f64>>>,
    points: usize,
}

impl VoxelMap {
    pub fn new(resolution_m: f64, per_voxel: usize, min_spacing_m: f64, radius_m: f64) -> Self {
        Self {
            resolution_m,
            inv_resolution: 1.0 / resolution_m,
            per_voxel,
            min_spacing_m,
            radius_m,
            voxels: KeyMap::default(),
            points: 0,
        }
    }

    pub fn len(&self) -> usize {
        self.points
    }

    pub fn is_empty(&self) -> bool {
        self.points == 0
    }

    fn key(&self, p: &Vector3<f64>) -> Key {
        key_of(p, self.inv_resolution)
    }

    /// Adds a world point unless its voxel is full or already holds one close by.
    pub fn insert(&mut self, p: Vector3<f64>) {
        let key = self.key(&p);
        let (cap, spacing2) = (self.per_voxel, self.min_spacing_m * self.min_spacing_m);
        let v = self.voxels.entry(key).or_default();
        if v.len() >= cap || v.iter().any(|q| (q - p).norm_squared() < spacing2) {
            return;
        }
        v.push(p);
        self.points += 1;
    }

    /// Drops every voxel whose centre is farther than the map radius from `centre`.
    pub fn trim(&mut self, centre: &Vector3<f64>) {
        let (res, r2) = (self.resolution_m, self.radius_m * self.radius_m);
        let mut removed = 0;
        self.voxels.retain(|&(x, y, z), pts| {
            let c = Vector3::new(f64::from(x) + 0.5, f64::from(y) + 0.5, f64::from(z) + 0.5) * res;
            let keep = (c - centre).norm_squared() <= r2;
            if !keep {
                removed += pts.len();
            }
            keep
        });
        self.points -= removed;
    }

    /// Up to `k` nearest points to `q` within `max_dist_m`, nearest first, into `out`. The
    /// query's voxel is searched first, then its neighbours, each only while it could hold a
    /// point nearer than the k-th found so far.
    pub fn nearest(&self, q: &Vector3<f64>, k: usize, max_dist_m: f64, out: &mut Vec<(f64, Vector3<f64>)>) {
        out.clear();
        let key = self.key(q);
        let max2 = max_dist_m * max_dist_m;
        // The 27 voxels around the query: near a voxel's edges and corners the nearest points
        // lie in edge and corner neighbours, which the face neighbours alone (iVox's NEARBY7)
        // miss, and the scan loses its nearest planes (docs/lio.md, Map).
        for d in std::iter::once((0, 0, 0)).chain(NEIGHBOURS) {
            let bound = if out.len() < k { max2 } else { out.last().map_or(max2, |l| l.0) };
            if gap2([q.x, q.y, q.z], key, self.resolution_m, d) > bound {
                continue;
            }
            let cell = (key.0.saturating_add(d.0), key.1.saturating_add(d.1), key.2.saturating_add(d.2));
            let Some(v) = self.voxels.get(&cell) else { continue };
            for p in v {
                let d2 = (p - q).norm_squared();
                if d2 > max2 {
                    continue;
                }
                if out.len() < k {
                    let at = out.partition_point(|e| e.0 < d2);
                    out.insert(at, (d2, *p));
                } else if out.last().is_some_and(|l| d2 < l.0) {
                    out.pop();
                    let at = out.partition_point(|e| e.0 < d2);
                    out.insert(at, (d2, *p));
                }
            }
        }
    }

    /// Every point of the local map (for export).
    pub fn points(&self) -> impl Iterator<Item = &Vector3<f64>> {
        self.voxels.values().flatten()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nearest_matches_a_brute_force_search_over_the_27_voxels() {
        let mut next = crate::rng::uniform(99u64);
        let mut map = VoxelMap::new(0.5, 20, 0.0, 100.0);
        for _ in 0..3000 {
            map.insert(Vector3::new(next() * 3.0, next() * 3.0, next()));
        }
        let all: Vec<Vector3<f64>> = map.points().copied().collect();
        let mut out = Vec::new();
        for _ in 0..300 {
            let q = Vector3::new(next() * 3.4 - 0.2, next() * 3.4 - 0.2, next() * 1.4 - 0.2);
            for (k, max_m) in [(5, 0.5), (5, 0.2), (1, 0.5)] {
                map.nearest(&q, k, max_m, &mut out);
                let mut brute: Vec<f64> =
                    all.iter().map(|p| (p - q).norm_squared()).filter(|&d2| d2 <= max_m * max_m).collect();
                brute.sort_by(f64::total_cmp);
                brute.truncate(k);
                let got: Vec<f64> = out.iter().map(|e| e.0).collect();
                assert_eq!(got, brute, "query {q:?}, k {k}, radius {max_m}");
            }
        }
    }

    #[test]
    fn finds_the_nearest_across_voxels_and_trims_far_ones() {
        let mut map = VoxelMap::new(0.5, 10, 0.01, 5.0);
        for i in 0..20 {
            map.insert(Vector3::new(f64::from(i) * 0.1, 0.0, 0.0));
        }
        map.insert(Vector3::new(100.0, 0.0, 0.0));
        assert_eq!(map.len(), 21);
        let mut out = Vec::new();
        map.nearest(&Vector3::new(0.52, 0.01, 0.0), 3, 1.0, &mut out);
        let xs: Vec<f64> = out.iter().map(|(_, p)| (p.x * 10.0).round() / 10.0).collect();
        assert_eq!(xs, vec![0.5, 0.6, 0.4]);
        map.trim(&Vector3::zeros());
        assert_eq!(map.len(), 20);
    }
}
