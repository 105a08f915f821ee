//! report.json: what a scored mission run measured. The keys are stable (docs/mission.md lists
//! them; benches and tests read them back): fields are only ever added.

use crate::error::{write, EvalError, Result};
use crate::quantiles::{quantiles, Quantiles};
use serde::Serialize;
use std::path::Path;

#[derive(Debug, Serialize)]
pub struct Report {
    pub scenario: String,
    /// What ran: "offline" (one process, no link, no nodes) or "live" (mock devices, the robot
    /// and rig nodes, the link on loopback).
    pub mode: &'static str,
    pub duration_s: f64,
    pub inlier_ratio: InlierReport,
    /// Overlay metrics that drawing fewer points cannot raise (see [`crate::overlay`]).
    pub overlay: OverlayReport,
    pub detection: DetectionReport,
    pub alignment: AlignmentReport,
    pub rig_pose_error: PoseErrorReport,
    pub robot_pose_error: RobotPoseErrorReport,
    /// The rig's own LIO against its true path, scored as the robot's (offline runs, which
    /// report its health; null where the rig never ran).
    pub rig_lio_error: Option<RobotPoseErrorReport>,
    pub exploration: ExplorationReport,
    pub latency_ms: LatencyReport,
    pub memory: MemoryReport,
    pub wall_s: f64,
}

impl Report {
    /// Pretty JSON with a final newline, as report.json holds it (NaN is written as null).
    pub fn to_json(&self) -> serde_json::Result<String> {
        Ok(serde_json::to_string_pretty(self)? + "\n")
    }

    /// Writes `path` (report.json).
    pub fn write(&self, path: &Path) -> Result<()> {
        let json = self.to_json().map_err(|source| EvalError::Json { path: path.to_path_buf(), source })?;
        write(path, json)
    }
}

#[derive(Debug, Serialize)]
pub struct InlierReport {
    /// Projected person points inside the see-through mask over all projected points in the image,
    /// pooled over every frame that showed detections.
    pub pooled: f64,
    pub points_in_mask: usize,
    /// The same, projected through the true camera pose (separates detection from pose error).
    pub pooled_true_pose: f64,
    pub points_in_image: usize,
    pub frames_scored: usize,
    pub per_frame: Quantiles,
}

/// Over (camera frame, person) pairs of the people the robot detected in the last second.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct OverlayReport {
    /// The mean share of a person's see-through mask pixels within 2 px of a drawn point, over
    /// the pairs where the person is in the mask (NaN, written null, without any).
    pub person_coverage: f64,
    pub coverage_pairs: usize,
    /// The share of the pairs of a person in the mask and behind a wall in which at least one
    /// drawn point lands within 2 px of their mask.
    pub people_shown: f64,
    pub shown_pairs: usize,
    /// `people_shown` over the frames the rig drew aligned only: what the view leaves undrawn
    /// once the rig is placed (1.0 when it draws every person detected behind a wall there;
    /// a wrong alignment draws them elsewhere and counts against it).
    pub people_shown_aligned: f64,
    pub shown_pairs_aligned: usize,
}

#[derive(Debug, Serialize)]
pub struct DetectionReport {
    pub precision: f64,
    pub recall: f64,
    pub true_positives: usize,
    pub false_positives: usize,
    pub misses: usize,
    pub windows: usize,
    /// Recall per true posture (standing, sitting, crouching, lying): visible people, and how
    /// many of them were found.
    pub per_true_pose: std::collections::BTreeMap<&'static str, PoseRecall>,
    /// Precision per detected posture (upright, low, lying): true and false positives.
    pub per_detected_pose: std::collections::BTreeMap<&'static str, PosePrecision>,
    /// Average precision per posture class, bird's-eye view (see [`crate::ap`]).
    pub average_precision: std::collections::BTreeMap<&'static str, crate::ap::ClassAp>,
}

#[derive(Debug, Default, Serialize, Clone, Copy)]
pub struct PoseRecall {
    pub visible: usize,
    pub found: usize,
    pub recall: f64,
}

#[derive(Debug, Default, Serialize, Clone, Copy)]
pub struct PosePrecision {
    pub true_positives: usize,
    pub false_positives: usize,
    pub precision: f64,
}

#[derive(Debug, Serialize)]
pub struct AlignmentReport {
    /// Time of the first accepted alignment after the rig's LIO started (s); null if none.
    pub first_accepted_after_s: Option<f64>,
    pub attempts: usize,
    pub accepted: usize,
    pub time_ms: Quantiles,
    /// The first accepted alignment's error against the truth.
    pub first_error_m: Option<f64>,
    pub first_error_deg: Option<f64>,
    /// The first accepted alignment within 10 cm and 1 deg of the truth, after the rig's LIO
    /// started (s); null if none.
    pub first_right_after_s: Option<f64>,
    /// Accepted alignments (first ones and re-registrations) more than 10 cm or 1 deg off.
    pub accepted_wrong: usize,
    /// When the rig's view first lay on the robot's map, and whether it was placed in time.
    pub map_sight: MapSightReport,
}

/// The rig's view against the robot's map at the rig's true pose, per second of its run
/// (`starc_eval::map_sight`): a second sees the map when at least 30 % of at least 100 sampled
/// returns lie within 0.3 m of it.
#[derive(Debug, Serialize)]
pub struct MapSightReport {
    /// The first second (since the rig's LIO started) that saw the map; null if none did.
    pub sees_map_after_s: Option<f64>,
    /// The largest share of a second's returns on the map.
    pub best_share: f64,
    pub seconds_judged: usize,
    pub seconds_seeing_map: usize,
    /// The goal: a right alignment (10 cm, 1 deg) within 10 s of `sees_map_after_s`; null
    /// when the rig never saw the map.
    pub right_within_10s: Option<bool>,
}

#[derive(Debug, Serialize)]
pub struct PoseErrorReport {
    pub translation_m: Quantiles,
    pub rotation_deg: Quantiles,
}

/// The floor the robot's scans made known on its route (docs/explore.md): the traversable area
/// of its occupancy grid. Offline runs only (the live robot node does not grow the grid yet).
#[derive(Debug, Serialize)]
pub struct ExplorationReport {
    /// Which route: "scripted" (the scenario's waypoints) or "explorer" (`starc sim --explore`).
    pub route: &'static str,
    /// The loop's own report (`starc_eval::explore_loop::LoopReport`, as the run's
    /// exploration.json holds it): the explorer's (`starc sim --explore`), or the scripted
    /// route's measured the same way (`--measure-route`).
    pub closed_loop: Option<serde_json::Value>,
    /// At the end (NaN, written null, without a grid).
    pub area_m2: f64,
    /// (seconds since the robot's first pose, m^2), every 5 s of the robot's time.
    pub area_by_time: Vec<[f64; 2]>,
}

/// A device's LIO poses against its true poses, the LIO world tied to the truth's at the first
/// pose (the absolute pose error of evo's APE with that anchor instead of a fitted alignment):
/// the robot's (`robot_pose_error`) and the rig's own odometry (`rig_lio_error`).
#[derive(Debug, Serialize)]
pub struct RobotPoseErrorReport {
    pub translation_m: Quantiles,
    pub rotation_deg: Quantiles,
    /// The root mean square of the translation errors over every pose (NaN, written null,
    /// without any).
    pub rmse_m: f64,
    /// Stretches where the error grew by more than 10 cm within 5 s, and how many of them the
    /// LIO's health never flagged (offline runs, which report the health).
    pub drift: Option<crate::drift::DriftReport>,
}

#[derive(Debug, Default, Serialize)]
pub struct LatencyReport {
    /// Offline: the LIO per robot scan plus the detection of its window. Live: from the host
    /// receiving the last packet of a robot scan to its detections leaving on the link.
    pub slam_p50: f64,
    pub slam_p99: f64,
    /// Live: from leaving the robot to arriving at the rig (host clocks, offset-corrected).
    /// Offline: no link (0).
    pub comm_p50: f64,
    pub comm_p99: f64,
    /// Offline: projection and rendering of one AR frame. Live: from arriving at the rig to the
    /// first AR frame that shows the detection, rendered.
    pub viz_p50: f64,
    pub viz_p99: f64,
    pub total_p50: f64,
    pub total_p99: f64,
}

impl LatencyReport {
    /// From the measurements (ms) of each part and of the total.
    pub fn from_parts(slam: &[f64], comm: &[f64], viz: &[f64], total: &[f64]) -> Self {
        let (s, c, v, t) = (quantiles(slam), quantiles(comm), quantiles(viz), quantiles(total));
        let zero_if_empty = |q: &Quantiles, v: f64| if q.n == 0 { 0.0 } else { v };
        Self {
            slam_p50: s.p50,
            slam_p99: s.p99,
            comm_p50: zero_if_empty(&c, c.p50),
            comm_p99: zero_if_empty(&c, c.p99),
            viz_p50: v.p50,
            viz_p99: v.p99,
            total_p50: t.p50,
            total_p99: t.p99,
        }
    }
}

#[derive(Debug, Serialize)]
pub struct MemoryReport {
    /// The whole process (both sides in the offline run; both nodes and the mocks live): peak
    /// resident MiB.
    pub peak_rss_mib: Option<f64>,
    /// Live: each node's own heap-held state is not separable in one process; its peak RSS when
    /// run as its own process is in docs/mission.md.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub note: Option<String>,
}
