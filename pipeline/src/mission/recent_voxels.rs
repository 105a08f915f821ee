//! The rig's points of a recent span, one (the newest) per voxel, in its odometry frame: what
//! the responder's view draws of their surroundings (one Avia scan is a rosette of dots in which
//! no one recognises a room; a few seconds of them show the walls, the door and the furniture),
//! and what the first searches remember ([`super::rig_history`]). One point per voxel, not per
//! return, bounds the cost.

use crate::voxel_hash::{key_of, KeyMap};
use nalgebra::Vector3;

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

    pub fn len(&self) -> usize {
        self.voxels.len()
    }

    pub fn is_empty(&self) -> bool {
        self.voxels.is_empty()
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
}
