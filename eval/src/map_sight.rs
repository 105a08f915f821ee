//! When the rig first sees what the robot has mapped: the yardstick of the alignment goal
//! ("aligned within 10 s of the rig first seeing mapped structure"). A responder looking into
//! rooms the robot never looked into cannot be placed by any registration, so a session is
//! judged from the first second in which enough of the rig's returns, placed at the rig's true
//! pose, lie on the robot's map as it stood then. Scorer-only: it reads the truth.

use nalgebra::{Isometry3, Point3, Vector3};
use starc_pipeline::align::VoxelIndex;
use starc_pipeline::lio::LioScan;
use std::collections::BTreeMap;

/// A rig return lies on the map when a map point is this close to it at the true pose (the
/// aligner's inlier distance is of this order; the truth ties the frames to a few cm).
pub const ON_MAP_M: f64 = 0.3;
/// A second in which at least this share of the rig's returns lie on the map ...
pub const MIN_SHARE: f64 = 0.3;
/// ... out of at least this many sampled returns (a rig facing a wall inside the Avia's blind
/// zone returns almost nothing, and a share of a handful says nothing).
pub const MIN_RETURNS: usize = 100;
/// Returns sampled per rig scan: enough for a share, cheap beside the mission.
const SAMPLED_PER_SCAN: usize = 100;
/// The map is re-indexed at most this often (the robot adds to it every scan).
const REINDEX_NS: u64 = 1_000_000_000;

/// Per second of the rig's run: sampled returns on the map, and all sampled.
#[derive(Default)]
pub struct MapSight {
    index: Option<VoxelIndex>,
    indexed_len: usize,
    indexed_ns: u64,
    seconds: BTreeMap<u64, (usize, usize)>,
}

impl MapSight {
    /// Whether the map should be handed in again before the next scan is scored.
    pub fn wants_map(&self, map_len: usize, t_ns: u64) -> bool {
        map_len != self.indexed_len && (self.index.is_none() || t_ns >= self.indexed_ns + REINDEX_NS)
    }

    /// The robot's map as it stands at `t_ns`, in the robot's LIO world.
    pub fn set_map(&mut self, points: Vec<Vector3<f64>>, t_ns: u64) {
        self.indexed_len = points.len();
        self.indexed_ns = t_ns;
        self.index = Some(VoxelIndex::new(points, ON_MAP_M));
    }

    /// One rig scan: its sampled returns placed by `world_t_lidar_at` (the true LiDAR pose in the
    /// robot's LIO world at a time) and counted into the second `second` of the rig's run.
    pub fn scan(&mut self, scan: &LioScan, second: u64, world_t_lidar_at: impl Fn(u64) -> Isometry3<f64>) {
        let Some(index) = &self.index else { return };
        let step = scan.points.len().div_ceil(SAMPLED_PER_SCAN).max(1);
        let (mut on, mut all) = (0, 0);
        for p in scan.points.iter().step_by(step) {
            let world = world_t_lidar_at(p.t_ns) * Point3::from(p.xyz());
            all += 1;
            on += usize::from(index.nearest(&world.coords, ON_MAP_M).is_some());
        }
        let e = self.seconds.entry(second).or_default();
        e.0 += on;
        e.1 += all;
    }

    /// The first second (since the rig started) that saw the map, if any.
    pub fn first_seen_s(&self) -> Option<u64> {
        self.seconds.iter().find(|(_, &(on, all))| sees_map(on, all)).map(|(s, _)| *s)
    }

    /// The largest share of a second's returns on the map (0 without any second).
    pub fn best_share(&self) -> f64 {
        self.seconds
            .values()
            .filter(|(_, all)| *all >= MIN_RETURNS)
            .map(|&(on, all)| share(on, all))
            .fold(0.0, f64::max)
    }

    /// Seconds with enough returns to judge, and of them those that saw the map.
    pub fn seconds_seeing(&self) -> (usize, usize) {
        let judged = self.seconds.values().filter(|(_, all)| *all >= MIN_RETURNS).count();
        let seeing = self.seconds.values().filter(|&&(on, all)| sees_map(on, all)).count();
        (judged, seeing)
    }
}

fn share(on: usize, all: usize) -> f64 {
    on as f64 / all.max(1) as f64
}

fn sees_map(on: usize, all: usize) -> bool {
    all >= MIN_RETURNS && share(on, all) >= MIN_SHARE
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use starc_pipeline::lio::{Clock, TimedPoint};

    fn wall_scan(x_m: f32, n: usize) -> LioScan {
        let points = (0..n)
            .map(|i| TimedPoint { x_m, y_m: (i % 20) as f32 * 0.1 - 1.0, z_m: (i / 20) as f32 * 0.1, t_ns: 0 })
            .collect();
        LioScan { start_ns: 0, end_ns: 0, clock: Clock::Ptp, points }
    }

    #[test]
    fn a_second_sees_the_map_when_enough_returns_lie_on_it() {
        let mut s = MapSight::default();
        let wall: Vec<Vector3<f64>> =
            (0..400).map(|i| Vector3::new(3.0, (i % 20) as f64 * 0.1 - 1.0, (i / 20) as f64 * 0.1)).collect();
        assert!(s.wants_map(wall.len(), 0));
        s.set_map(wall, 0);
        // Second 0: the rig looks at a wall the robot has not mapped (8 m away); second 1: at
        // the mapped wall 3 m ahead; second 2: a handful of returns only.
        s.scan(&wall_scan(8.0, 400), 0, |_| Isometry3::identity());
        s.scan(&wall_scan(3.0, 400), 1, |_| Isometry3::identity());
        s.scan(&wall_scan(3.0, 10), 2, |_| Isometry3::identity());
        assert_eq!(s.first_seen_s(), Some(1));
        assert_eq!(s.seconds_seeing(), (2, 1));
        assert!((s.best_share() - 1.0).abs() < 1e-9);
        // The same scan placed 1 m off the truth is off the map.
        let mut t = MapSight::default();
        t.set_map((0..400).map(|i| Vector3::new(3.0, (i % 20) as f64 * 0.1, (i / 20) as f64 * 0.1)).collect(), 0);
        t.scan(&wall_scan(2.0, 400), 0, |_| Isometry3::identity());
        assert_eq!(t.first_seen_s(), None);
    }
}
