//! What the rig saw before its first alignment's window: the reduced, filtered windows of its
//! earlier searches, kept in its odometry frame. A window of the last 10 s can fit a symmetric
//! building's mirror perfectly; the rooms the responder walked through before rarely fit there
//! too. Keeping them as voxels costs a few MB where keeping their scans would cost hundreds.

use super::recent_voxels::RecentVoxels;
use nalgebra::{Isometry3, Point3, Vector3};
use std::sync::Arc;

/// One point per voxel of the earlier windows (the newest seen there), kept for a span.
pub struct RigHistory {
    /// 0: no history.
    keep_ns: u64,
    voxels: RecentVoxels,
    points: Arc<Vec<Vector3<f64>>>,
}

impl RigHistory {
    pub fn new(voxel_m: f64, keep_ns: u64) -> Self {
        Self { keep_ns, voxels: RecentVoxels::new(voxel_m, keep_ns), points: Arc::new(Vec::new()) }
    }

    /// Adds a window's points (odometry frame) seen up to `end_ns`, and forgets voxels last seen
    /// more than the kept span before it.
    pub fn merge(&mut self, window_odom: &[Vector3<f64>], end_ns: u64) {
        if self.keep_ns == 0 {
            return;
        }
        self.voxels.add(window_odom, end_ns);
        // Sorted by key, so that a search's input does not depend on the map's iteration order.
        self.points = Arc::new(self.voxels.sorted_points());
    }

    /// The kept points, in the rig's odometry frame.
    pub fn points(&self) -> Arc<Vec<Vector3<f64>>> {
        Arc::clone(&self.points)
    }
}

/// A window's points (in its frame) with the history's (odometry frame, `frame_t_odom` takes
/// them into the window's frame), one point per voxel of `voxel_m` (the mean where both have one).
pub fn with_history(
    window: Vec<Vector3<f64>>,
    history_odom: &[Vector3<f64>],
    frame_t_odom: &Isometry3<f64>,
    voxel_m: f64,
) -> Vec<Vector3<f64>> {
    if history_odom.is_empty() {
        return window;
    }
    let mut all = crate::voxel_hash::VoxelMeans::new(voxel_m);
    for p in &window {
        all.add(p);
    }
    for p in history_odom {
        all.add(&(frame_t_odom * Point3::from(*p)).coords);
    }
    all.finish()
}

#[cfg(test)]
mod tests {
    use super::{with_history, RigHistory};
    use nalgebra::{Isometry3, Translation3, Vector3};

    const S: u64 = 1_000_000_000;

    #[test]
    fn voxels_are_kept_for_the_span_after_they_were_last_seen() {
        let mut h = RigHistory::new(0.1, 30 * S);
        let wall = |x: f64| (0..10).map(move |i| Vector3::new(x, f64::from(i) * 0.1, 1.0)).collect::<Vec<_>>();
        h.merge(&wall(0.0), S);
        h.merge(&wall(5.0), 20 * S);
        assert_eq!(h.points().len(), 20);
        // Seen again at 25 s: the first wall stays past 31 s.
        h.merge(&wall(0.0), 25 * S);
        h.merge(&wall(9.0), 40 * S);
        assert_eq!(h.points().len(), 30);
        // 51 s: the second wall (last seen at 20 s) is gone, the first (25 s) is not.
        h.merge(&[], 51 * S);
        assert_eq!(h.points().len(), 20);
        assert!(h.points().iter().all(|p| p.x != 5.0));
        // Non-finite points are never kept; no span: nothing is.
        h.merge(&[Vector3::new(f64::NAN, 0.0, 0.0)], 52 * S);
        assert_eq!(h.points().len(), 20);
        let mut off = RigHistory::new(0.1, 0);
        off.merge(&wall(0.0), S);
        assert!(off.points().is_empty());
    }

    #[test]
    fn the_history_joins_the_window_in_its_frame() {
        // The window's frame is 2 m along x of the odometry's.
        let frame_t_odom = Isometry3::from_parts(Translation3::new(-2.0, 0.0, 0.0), Default::default());
        let window = vec![Vector3::new(1.0, 0.0, 0.0)];
        let history = vec![Vector3::new(3.0, 0.0, 0.0), Vector3::new(7.0, 0.0, 0.0)];
        let joined = with_history(window.clone(), &history, &frame_t_odom, 0.1);
        // The first history point is the window's own (one voxel), the second joins it.
        assert_eq!(joined.len(), 2);
        assert!(joined.iter().any(|p| (p - Vector3::new(5.0, 0.0, 0.0)).norm() < 1e-9), "{joined:?}");
        assert_eq!(with_history(window.clone(), &[], &frame_t_odom, 0.1), window);
    }
}
