//! People in a window of the robot's points: oriented 3D boxes with scores, and the points of
//! each person (the paper's P_human, the points the AR view draws in red).
//!
//! A [`Detector`] takes a [`DetectWindow`] (de-skewed points in a gravity-aligned world frame,
//! z up, plus the sensor's pose and the window's time stamp) and appends [`Detection`]s. The
//! shipped one, [`GeometricDetector`], is classical: floor and ceiling removed relative to the
//! estimated planes, a voxel grid, 26-connected voxel clusters, oversized clusters split by
//! peeling off planes, then a scorer over cluster geometry for upright, sitting/crouching and
//! lying people. A learned detector (PointPillars) can sit behind the same trait.
//!
//! ```no_run
//! # use starc_pipeline::detect::{DetectConfig, DetectWindow, Detector, GeometricDetector, WindowPoint};
//! # use starc_time::{Clock, Stamp};
//! # fn f(points: &[WindowPoint], pose: nalgebra::Isometry3<f64>) -> Result<(), starc_pipeline::PipelineError> {
//! let mut detector = GeometricDetector::new(DetectConfig::default())?;
//! let window = DetectWindow { stamp: Stamp::new(1, Clock::Ptp), sensor_pose: pose, points };
//! let mut found = Vec::new();
//! detector.detect(&window, &mut found);
//! for d in &found {
//!     println!("{:?} at {:?}, score {:.2}, {} points", d.pose, d.centre_m, d.score, d.point_indices.len());
//! }
//! # Ok(()) }
//! ```

mod carve;
mod classify;
mod cluster;
mod config;
pub mod eval;
mod features;
mod floor;
mod follow;
mod fov;
mod geometric;
mod occlusion;
mod person_part;
pub mod pillars;
pub mod trees;

pub use config::{DetectConfig, DetectorKind, PillarsConfig, TreesConfig};
pub use features::ClusterFeatures;
pub use floor::{estimate_floor, FloorModel};
pub use geometric::GeometricDetector;
pub use occlusion::Silhouette;

use nalgebra::{Isometry3, Point3, Vector3};
use starc_time::Stamp;

/// One de-skewed return in the world frame (z up), with its firing time.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct WindowPoint {
    pub x_m: f32,
    pub y_m: f32,
    pub z_m: f32,
    pub t_ns: u64,
}

impl WindowPoint {
    pub fn xyz(&self) -> Vector3<f64> {
        Vector3::new(f64::from(self.x_m), f64::from(self.y_m), f64::from(self.z_m))
    }
}

/// The input of one detection: a few scans' worth of points.
#[derive(Clone, Copy, Debug)]
pub struct DetectWindow<'a> {
    /// The time the detections are valid at (normally the end of the window; PTP clock).
    pub stamp: Stamp,
    /// The sensor's pose in the world at `stamp` (its position sets ranges; the floor is looked
    /// for below it).
    pub sensor_pose: Isometry3<f64>,
    /// De-skewed points in the world frame.
    pub points: &'a [WindowPoint],
}

/// Moves points of the sensor frame into the world, each with the pose at its own firing time
/// (`pose_at`, e.g. the LIO's trajectory interpolated): the de-skew for callers that hold raw
/// sensor points.
pub fn to_world(
    sensor_points: impl IntoIterator<Item = ([f32; 3], u64)>,
    pose_at: impl Fn(u64) -> Isometry3<f64>,
    out: &mut Vec<WindowPoint>,
) {
    for ([x, y, z], t_ns) in sensor_points {
        let p = pose_at(t_ns).transform_point(&Point3::new(f64::from(x), f64::from(y), f64::from(z)));
        out.push(WindowPoint { x_m: p.x as f32, y_m: p.y as f32, z_m: p.z as f32, t_ns });
    }
}

/// The posture a detection's shape fits best.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum PersonPose {
    /// Standing or walking.
    Upright,
    /// Sitting or crouching (or an upright person of whom only the upper part shows).
    Low,
    /// Lying on the floor.
    Lying,
}

/// One person found in a window.
#[derive(Clone, Debug, PartialEq)]
pub struct Detection {
    /// The window's stamp: downstream ages and expiry are measured from it.
    pub stamp: Stamp,
    /// Oriented box: centre in the world, size (length along `yaw_rad`, width, height).
    pub centre_m: Vector3<f64>,
    pub size_m: Vector3<f64>,
    pub yaw_rad: f64,
    /// Confidence in [0, 1].
    pub score: f64,
    pub pose: PersonPose,
    /// Indices into the window's points of the person's points (inside the box, floor excluded).
    pub point_indices: Vec<u32>,
}

impl Detection {
    /// Whether a world point lies in the box, grown by `margin_m` on every side.
    pub fn contains(&self, p: &Vector3<f64>, margin_m: f64) -> bool {
        let (s, c) = self.yaw_rad.sin_cos();
        let d = p - self.centre_m;
        let local = [c * d.x + s * d.y, -s * d.x + c * d.y, d.z];
        (0..3).all(|i| local[i].abs() <= self.size_m[i] / 2.0 + margin_m)
    }
}

/// A person detector: a window of points and its time in, detections out.
pub trait Detector {
    /// A short name for logs and reports.
    fn name(&self) -> &'static str;
    /// Appends the people found in `window` to `out` (cleared by the caller, not here).
    fn detect(&mut self, window: &DetectWindow<'_>, out: &mut Vec<Detection>);
    /// The floor the last window was judged against, if the detector estimated one.
    fn last_floor(&self) -> Option<FloorModel> {
        None
    }
}

/// The detector `cfg.kind` names.
pub fn make_detector(cfg: &DetectConfig) -> Result<Box<dyn Detector + Send>, crate::PipelineError> {
    Ok(match cfg.kind {
        DetectorKind::Geometric | DetectorKind::Trees => Box::new(GeometricDetector::new(cfg.clone())?),
        DetectorKind::Pointpillars => Box::new(pillars::PillarsDetector::new(cfg)?),
    })
}

#[cfg(test)]
mod tests;
#[cfg(test)]
mod tests_trees;
