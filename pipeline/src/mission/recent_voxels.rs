//! The rig's points of a recent span, one (the newest) per voxel, in its odometry frame: what
//! the responder's view draws of their surroundings (one Avia scan is a rosette of dots in which
//! no one recognises a room; a few seconds of them show the walls, the door and the furniture),
//! and what the first searches remember ([`super::rig_history`]). One point per voxel, not per
//! return, bounds the cost.

use crate::voxel_hash::{key_of, Key, KeyMap};
use nalgebra::Vector3;

/// [`RecentVoxels::points_by_block`]'s blocks: 2^4 = 16 voxels a side.
const BLOCK_SHIFT: i32 = 4;

pub struct RecentVoxels {
    inv_voxel_m: f64,
    /// How long a voxel not seen again is kept (0: only the newest scan).
    keep_ns: u64,
    voxels: KeyMap<(Vector3<f64>, u64)>,
}

impl RecentVoxels {
    pub fn new(voxel_m: f64, keep_ns: u64) -> Self {
        Self { inv_voxel_m: 1.0 / voxel_m.max(1e-3), keep_ns, voxels: KeyMap::default() }
    }

    /// Adds a scan's points (odometry frame) that ended at `end_ns`, and forgets the voxels
    /// last seen more than the kept span before it.
    pub fn add(&mut self, points_odom: &[Vector3<f64>], end_ns: u64) {
        let from_ns = end_ns.saturating_sub(self.keep_ns);
        self.voxels.retain(|_, (_, seen_ns)| *seen_ns >= from_ns && *seen_ns <= end_ns);
        for p in points_odom.iter().filter(|p| p.iter().all(|v| v.is_finite())) {
            self.voxels.insert(key_of(p, self.inv_voxel_m), (*p, end_ns));
        }
    }

    /// The kept points, odometry frame.
    pub fn points(&self) -> impl Iterator<Item = &Vector3<f64>> {
        self.voxels.values().map(|(p, _)| p)
    }

    /// The kept points, sorted by their voxels' keys (an order that does not depend on the
    /// map's).
    pub fn sorted_points(&self) -> Vec<Vector3<f64>> {
        let mut cells: Vec<_> = self.voxels.iter().map(|(k, (p, _))| (*k, *p)).collect();
        cells.sort_unstable_by_key(|c| c.0);
        cells.into_iter().map(|c| c.1).collect()
    }

    /// The kept points grouped by block of 2^`BLOCK_SHIFT` voxels a side (about 1.3 m at 8 cm), blocks
    /// in grid order, into `out`: drawn in this order, consecutive points land near each other
    /// on screen and in the depth buffer (in the hash map's order every point is a cache miss
    /// there). A counting sort, linear in the points: cheap enough to run after every scan.
    pub fn points_by_block(&self, out: &mut Vec<Vector3<f64>>) {
        out.clear();
        let block = |k: &Key| [k.0 >> BLOCK_SHIFT, k.1 >> BLOCK_SHIFT, k.2 >> BLOCK_SHIFT];
        let (mut lo, mut hi) = ([i32::MAX; 3], [i32::MIN; 3]);
        for k in self.voxels.keys() {
            let b = block(k);
            for a in 0..3 {
                lo[a] = lo[a].min(b[a]);
                hi[a] = hi[a].max(b[a]);
            }
        }
        let span = |a: usize| (i64::from(hi[a]) - i64::from(lo[a]) + 1).max(0) as usize;
        let blocks = span(0).saturating_mul(span(1)).saturating_mul(span(2));
        // Kept points far apart (a stray return kilometres off) would make the count table
        // huge: then the map's order it is.
        if self.voxels.is_empty() || blocks > 4 * self.voxels.len() + 4096 {
            out.extend(self.points().copied());
            return;
        }
        let id = |k: &Key| {
            let b = block(k);
            let rel = |a: usize| (i64::from(b[a]) - i64::from(lo[a])) as usize;
            (rel(2) * span(1) + rel(1)) * span(0) + rel(0)
        };
        let mut start = vec![0usize; blocks + 1];
        for k in self.voxels.keys() {
            if let Some(c) = start.get_mut(id(k) + 1) {
                *c += 1;
            }
        }
        let mut sum = 0;
        for c in start.iter_mut() {
            sum += *c;
            *c = sum;
        }
        out.resize(self.voxels.len(), Vector3::zeros());
        for (k, (p, _)) in &self.voxels {
            if let Some(at) = start.get_mut(id(k)) {
                if let Some(slot) = out.get_mut(*at) {
                    *slot = *p;
                }
                *at += 1;
            }
        }
    }

    #[cfg(test)]
    fn len(&self) -> usize {
        self.voxels.len()
    }
}

#[cfg(test)]
mod tests {
    use super::RecentVoxels;
    use nalgebra::Vector3;

    const S: u64 = 1_000_000_000;

    #[test]
    fn one_point_per_voxel_for_the_kept_span() {
        let mut v = RecentVoxels::new(0.1, 3 * S);
        let wall = |x: f64| (0..100).map(move |i| Vector3::new(x, f64::from(i) * 0.01, 1.0)).collect::<Vec<_>>();
        v.add(&wall(0.0), S);
        // 100 points 1 cm apart: 10 voxels of 10 cm.
        assert_eq!(v.len(), 10);
        v.add(&wall(2.0), 3 * S);
        assert_eq!(v.len(), 20);
        // 4 s: the first wall was last seen 3 s ago and is still kept; at 4.1 s it is gone.
        v.add(&[], 4 * S);
        assert_eq!(v.len(), 20);
        v.add(&[], 4 * S + S / 10);
        assert_eq!(v.len(), 10);
        assert!(v.points().all(|p| p.x == 2.0));
        v.add(&[Vector3::new(f64::NAN, 0.0, 0.0)], 5 * S);
        assert_eq!(v.len(), 10);
    }

    #[test]
    fn points_by_block_are_every_point_once_grouped_by_block() {
        let mut v = RecentVoxels::new(0.1, 3 * S);
        let pts: Vec<Vector3<f64>> =
            (0..2000).map(|i| Vector3::new(f64::from(i % 50) * 0.1, f64::from(i / 50) * 0.1, 1.0)).collect();
        v.add(&pts, S);
        let mut out = Vec::new();
        v.points_by_block(&mut out);
        assert_eq!(out.len(), v.len());
        let mut a: Vec<[i64; 3]> = out.iter().map(|p| p.map(|c| (c * 10.0).round() as i64).into()).collect();
        let mut b: Vec<[i64; 3]> = v.points().map(|p| p.map(|c| (c * 10.0).round() as i64).into()).collect();
        a.sort_unstable();
        b.sort_unstable();
        assert_eq!(a, b, "the same points");
        // Grouped: each 1.6 m block's points come in one run.
        let block = |p: &Vector3<f64>| ((p.x / 1.6).floor() as i64, (p.y / 1.6).floor() as i64);
        let runs = out.windows(2).filter(|w| block(&w[0]) != block(&w[1])).count() + 1;
        let blocks: std::collections::HashSet<_> = out.iter().map(block).collect();
        assert_eq!(runs, blocks.len());
        // A stray point kilometres away: every point still, in the map's order.
        v.add(&[Vector3::new(5e4, 0.0, 1.0)], S);
        v.points_by_block(&mut out);
        assert_eq!(out.len(), v.len());
    }
}
