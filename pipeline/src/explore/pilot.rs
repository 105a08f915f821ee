//! The explorer on a real robot's inputs, sans-IO: the LIO's placed scans and poses, which come
//! late and ten times a second, and the base's wheel odometry, which comes every few
//! milliseconds. The base's pose for a control step is the newest LIO pose carried forward by
//! the wheels' motion since that scan ended, so the controller neither waits for the next scan
//! nor drives on a pose 100 ms old.
//!
//! The explorer's grid is made at the first pose: its floor lies `lidar_height_m` under the
//! LiDAR there, and home is where the base stood. The LiDAR is taken to sit above the base's
//! centre with no yaw against it (the STARC mast).

use super::control::Pose2;
use super::explorer::{ExploreConfig, ExploreStep, Explorer};
use nalgebra::{Isometry3, Vector3};
use std::collections::VecDeque;

/// Wheel odometry older than this is dropped (a scan's pose is never later than this).
const ODOM_KEEP_NS: u64 = 3_000_000_000;

/// Settings of the pilot.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PilotConfig {
    pub explore: ExploreConfig,
    /// Height of the LiDAR's optical centre above the floor the base stands on.
    pub lidar_height_m: f64,
    /// Every how many of a placed scan's returns go into the grid (1: all).
    pub scan_stride: usize,
    /// The LiDAR's minimum range (the Avia's datasheet: 1 m): the grid's
    /// ([`OccupancyConfig::min_range_m`](super::OccupancyConfig)) and, with the height, the
    /// ring around the start whose floor the LiDAR cannot see
    /// ([`ExploreConfig::blind_radius_m`]), each where that is left at 0.
    pub lidar_min_range_m: f64,
}

impl PilotConfig {
    /// The radius of the floor around the base the LiDAR cannot see: where its minimum range
    /// meets the floor, and a cell more.
    pub fn blind_radius_m(&self) -> f64 {
        let h = self.lidar_height_m;
        (self.lidar_min_range_m.powi(2) - h * h).max(0.0).sqrt() + self.explore.occupancy.cell_m
    }

    /// From how near and how far a frontier is looked at: beyond the minimum range, within
    /// a metre more.
    pub fn view_from_m(&self) -> (f64, f64) {
        let near = self.lidar_min_range_m + self.explore.occupancy.cell_m;
        (near, near + 1.0)
    }
}

/// See the module's documentation.
pub struct Pilot {
    cfg: PilotConfig,
    explorer: Option<Explorer>,
    /// The newest LIO pose of the base and its time.
    anchor: Option<(u64, Pose2)>,
    /// The wheels' integrated pose (in their own frame) by time.
    odom: VecDeque<(u64, Pose2)>,
}

impl Pilot {
    pub fn new(cfg: PilotConfig) -> Self {
        Self { cfg, explorer: None, anchor: None, odom: VecDeque::new() }
    }

    /// The explorer, once the first scan has made it.
    pub fn explorer(&self) -> Option<&Explorer> {
        self.explorer.as_ref()
    }

    pub fn explorer_mut(&mut self) -> Option<&mut Explorer> {
        self.explorer.as_mut()
    }

    /// The base's measured twist at `t_ns` (body frame: forward, left, counter-clockwise), in
    /// time order.
    pub fn on_wheels(&mut self, t_ns: u64, vx_m_s: f64, vy_m_s: f64, wz_rad_s: f64) {
        let twist = super::control::BodyTwist { vx_m_s, vy_m_s, wz_rad_s };
        let next = match self.odom.back() {
            Some(&(t0, p)) if t_ns > t0 => p.after(&twist, (t_ns - t0) as f64 * 1e-9),
            Some(_) => return,
            None => Pose2 { x_m: 0.0, y_m: 0.0, yaw_rad: 0.0 },
        };
        self.odom.push_back((t_ns, next));
        while self.odom.front().is_some_and(|&(t, _)| t + ODOM_KEEP_NS < t_ns) {
            self.odom.pop_front();
        }
    }

    /// A placed scan: the LiDAR's pose at its end `end_ns` and its returns in the same world
    /// (every `scan_stride`th is kept).
    pub fn on_scan(
        &mut self,
        end_ns: u64,
        lidar_pose: &Isometry3<f64>,
        points: impl IntoIterator<Item = Vector3<f64>>,
    ) {
        let origin = lidar_pose.translation.vector;
        let pose = base_pose(lidar_pose);
        if self.explorer.is_none() {
            let mut explore = self.cfg.explore;
            explore.occupancy.floor_z_m = origin.z - self.cfg.lidar_height_m;
            if explore.blind_radius_m <= 0.0 {
                explore.blind_radius_m = self.cfg.blind_radius_m();
            }
            if explore.view_from_m.1 <= 0.0 {
                explore.view_from_m = self.cfg.view_from_m();
            }
            if explore.occupancy.min_range_m <= 0.0 {
                explore.occupancy.min_range_m = self.cfg.lidar_min_range_m;
            }
            self.explorer = Explorer::new(explore, [pose.x_m, pose.y_m]);
        }
        self.anchor = Some((end_ns, pose));
        if let Some(explorer) = self.explorer.as_mut() {
            let stride = self.cfg.scan_stride.max(1);
            let kept: Vec<Vector3<f64>> = points.into_iter().step_by(stride).collect();
            explorer.add_scan(&origin, &kept);
        }
    }

    /// The base's pose at `t_ns`: the newest LIO pose moved by the wheels since. `None` before
    /// the first scan.
    pub fn pose_at(&self, t_ns: u64) -> Option<Pose2> {
        let (t_scan, anchor) = self.anchor?;
        let (Some(from), Some(to)) = (self.odom_at(t_scan), self.odom_at(t_ns)) else { return Some(anchor) };
        Some(compose(&anchor, &between(&from, &to)))
    }

    /// The wheels' pose at the newest sample at or before `t_ns` (the oldest kept if none).
    fn odom_at(&self, t_ns: u64) -> Option<Pose2> {
        let i = self.odom.partition_point(|&(t, _)| t <= t_ns);
        self.odom.get(i.saturating_sub(1)).map(|&(_, p)| p)
    }

    /// One control step at `t_ns`, `dt_s` after the last: the twist to command. `None` (stand)
    /// before the first scan.
    pub fn step(&mut self, t_ns: u64, dt_s: f64) -> Option<ExploreStep> {
        let pose = self.pose_at(t_ns)?;
        let explorer = self.explorer.as_mut()?;
        Some(explorer.step(t_ns as f64 * 1e-9, &pose, &[], dt_s))
    }
}

/// The base's pose under a LiDAR at `lidar_pose` (above its centre, no yaw against it): its
/// position in the plane and the heading of its x axis.
pub fn base_pose(lidar_pose: &Isometry3<f64>) -> Pose2 {
    let origin = lidar_pose.translation.vector;
    let x_axis = lidar_pose.rotation * Vector3::x();
    Pose2 { x_m: origin.x, y_m: origin.y, yaw_rad: x_axis.y.atan2(x_axis.x) }
}

/// `b` seen from `a`: the motion from pose `a` to pose `b`, in `a`'s frame.
pub fn between(a: &Pose2, b: &Pose2) -> Pose2 {
    let [x_m, y_m] = a.to_body([b.x_m, b.y_m]);
    Pose2 { x_m, y_m, yaw_rad: b.yaw_rad - a.yaw_rad }
}

/// The motion `d` (in `a`'s frame) applied at `a`.
pub fn compose(a: &Pose2, d: &Pose2) -> Pose2 {
    let (s, c) = a.yaw_rad.sin_cos();
    Pose2 { x_m: a.x_m + c * d.x_m - s * d.y_m, y_m: a.y_m + s * d.x_m + c * d.y_m, yaw_rad: a.yaw_rad + d.yaw_rad }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion};

    fn pilot() -> Pilot {
        Pilot::new(PilotConfig {
            explore: ExploreConfig::default(),
            lidar_height_m: 0.5,
            scan_stride: 1,
            lidar_min_range_m: 1.0,
        })
    }

    #[test]
    fn the_scan_pose_is_carried_forward_by_the_wheels() {
        let mut p = pilot();
        assert!(p.pose_at(0).is_none() && p.step(0, 0.05).is_none());
        // Wheels: 0.5 m/s forward from t = 0 (their own frame starts anywhere).
        for k in 0..=200u64 {
            p.on_wheels(k * 5_000_000, 0.5, 0.0, 0.0);
        }
        // The scan that ended at 0.5 s put the LiDAR at (2, 1), facing +y, 0.6 m up.
        let pose = Isometry3::from_parts(
            Translation3::new(2.0, 1.0, 0.6),
            UnitQuaternion::from_euler_angles(0.0, 0.1, std::f64::consts::FRAC_PI_2),
        );
        p.on_scan(500_000_000, &pose, [Vector3::new(2.0, 3.0, 0.1)]);
        let now = p.pose_at(800_000_000).unwrap_or_else(|| panic!("a pose"));
        // 0.3 s later at 0.5 m/s along +y.
        assert!((now.x_m - 2.0).abs() < 1e-9 && (now.y_m - 1.15).abs() < 1e-9, "{now:?}");
        assert!((now.yaw_rad - std::f64::consts::FRAC_PI_2).abs() < 1e-9);
        let grid = p.explorer().map(|e| *e.grid().config());
        assert!(grid.is_some_and(|g| (g.floor_z_m - 0.1).abs() < 1e-12), "{grid:?}");
        assert!(p.step(800_000_000, 0.05).is_some());
    }

    #[test]
    fn composing_undoes_between() {
        let a = Pose2 { x_m: 1.0, y_m: -2.0, yaw_rad: 0.7 };
        let b = Pose2 { x_m: -0.5, y_m: 3.0, yaw_rad: -2.1 };
        let c = compose(&a, &between(&a, &b));
        assert!(
            (c.x_m - b.x_m).abs() < 1e-12 && (c.y_m - b.y_m).abs() < 1e-12 && (c.yaw_rad - b.yaw_rad).abs() < 1e-12
        );
    }
}
