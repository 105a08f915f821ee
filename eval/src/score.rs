//! Scoring a mission run against the simulator's truth, shared by the offline mission
//! (`starc mission`) and the live one (`starc sim`): detection against the true people, the rig's
//! alignment and world pose against its true pose, every AR frame's projected person points
//! against the see-through masks (the paper's inlier ratio), and how much of each person
//! detected lately those points cover ([`crate::overlay`]). [`Scorer::finish`] writes
//! `report.json` (stable keys, see docs/mission.md), `frames.csv` and the plots.
//!
//! Events come in as the run makes them: [`Scorer::robot_pose`], [`Scorer::detection`],
//! [`Scorer::rig_started`], [`Scorer::alignment`], [`Scorer::frame`]; all times are PTP ns.

use crate::ap::{class_of_pose, ApTally};
use crate::detection::{box_returns, truth_in_world};
use crate::error::{write, EvalError, Result};
use crate::map_sight::MapSight;
use crate::odometry::OdometryLog;
use crate::overlay::{DetectedLog, OverlayTally, DETECTED_WITHIN_NS};
use crate::plots::write_plots;
use crate::quantiles::quantiles;
use crate::report::{
    AlignmentReport, DetectionReport, ExplorationReport, InlierReport, LatencyReport, MapSightReport, MemoryReport,
    PoseErrorReport, PosePrecision, PoseRecall, Report,
};
use crate::truth::{at, people_at, CameraFrame, PersonBox, TruePose, Truth};
use nalgebra::{Isometry3, Vector3};
use starc_pipeline::align::pose_error;
use starc_pipeline::ar::{self, ProjectedPoint};
use starc_pipeline::detect::eval::{match_window, Counts, MatchRule, TruthPerson, WindowMatch};
use starc_pipeline::lio::{Health, LioScan};
use starc_pipeline::mission::{RobotDetection, View};
use std::collections::{BTreeMap, VecDeque};
use std::path::Path;

/// The explored floor area is sampled this often (robot time).
const EXPLORED_EVERY_NS: u64 = 5_000_000_000;
/// An accepted alignment this close to the truth is right (the alignment issue's goal); any
/// other accepted one is wrong.
const RIGHT_M: f64 = 0.10;
const RIGHT_DEG: f64 = 1.0;
/// ... and the goal's time: right within this long of the rig first seeing the robot's map.
const RIGHT_WITHIN_NS: u64 = 10_000_000_000;

/// A camera frame whose overlay waits for the robot's detections to pass its time.
struct PendingFrame {
    index: u64,
    t_ns: u64,
    /// The person points drawn in it (pixels).
    drawn: Vec<(f64, f64)>,
    aligned: bool,
}

/// Everything scored so far.
pub struct Scorer {
    pub truth: Truth,
    counts: Counts,
    windows: usize,
    /// Per true posture: (visible, found); per detected posture: (true, false positives).
    per_true_pose: BTreeMap<&'static str, (usize, usize)>,
    per_detected_pose: BTreeMap<&'static str, (usize, usize)>,
    ap: ApTally,
    rig_first_ns: Option<u64>,
    attempts: usize,
    accepted: usize,
    align_ms: Vec<f64>,
    first_accept: Option<(u64, f64, f64)>,
    /// The first right accepted alignment, after the rig started (ns).
    first_right_ns: Option<u64>,
    accepted_wrong: usize,
    sight: MapSight,
    in_mask: usize,
    in_image: usize,
    true_in_mask: usize,
    true_in_image: usize,
    per_frame_ratio: Vec<f64>,
    err_m: Vec<f64>,
    err_deg: Vec<f64>,
    err_series: Vec<(f64, f64)>,
    /// The robot's LIO poses against its true path; its first pose ties the robot's LIO world
    /// to the truth's ([`Self::lio_t_world`]).
    robot_odom: OdometryLog,
    inlier_series: Vec<(f64, f64)>,
    frame_rows: Vec<String>,
    projected: Vec<ProjectedPoint>,
    /// The robot's newest pose: its detections up to here have all come in.
    robot_ns: Option<u64>,
    /// (robot time, traversable floor known, m^2), every `EXPLORED_EVERY_NS`.
    explored: Vec<(u64, f64)>,
    /// The rig's own LIO poses against its true path (offline runs).
    rig_lio: OdometryLog,
    detected: DetectedLog,
    pending: VecDeque<PendingFrame>,
    overlay: OverlayTally,
}

impl Scorer {
    pub fn new(truth: Truth) -> Self {
        Self {
            truth,
            counts: Counts::default(),
            windows: 0,
            per_true_pose: BTreeMap::new(),
            per_detected_pose: BTreeMap::new(),
            ap: ApTally::default(),
            rig_first_ns: None,
            attempts: 0,
            accepted: 0,
            align_ms: Vec::new(),
            first_accept: None,
            first_right_ns: None,
            accepted_wrong: 0,
            sight: MapSight::default(),
            in_mask: 0,
            in_image: 0,
            true_in_mask: 0,
            true_in_image: 0,
            per_frame_ratio: Vec::new(),
            err_m: Vec::new(),
            err_deg: Vec::new(),
            err_series: Vec::new(),
            robot_odom: OdometryLog::default(),
            inlier_series: Vec::new(),
            frame_rows: vec![
                "frame,time_s,aligned,detections,age_ms,points_in_image,points_in_mask,pose_error_m,pose_error_deg,render_ms"
                    .to_string(),
            ],
            projected: Vec::new(),
            robot_ns: None,
            explored: Vec::new(),
            rig_lio: OdometryLog::default(),
            detected: DetectedLog::default(),
            pending: VecDeque::new(),
            overlay: OverlayTally::default(),
        }
    }

    /// A robot LIO pose, with the LIO's health when the run reports it (offline; see
    /// [`crate::drift`]); the first one ties the robot's LIO world to the truth's, and each is
    /// scored against the truth in it. The robot reports a scan's detection before its pose.
    pub fn robot_pose(&mut self, end_ns: u64, lidar_pose: &Isometry3<f64>, health: Option<Health>) {
        let truth = at(&self.truth.gt_robot, end_ns);
        self.robot_odom.push(end_ns, lidar_pose, &truth, health);
        self.robot_ns = Some(self.robot_ns.map_or(end_ns, |t| t.max(end_ns)));
    }

    /// Whether the explored area is due at `end_ns` (robot time): every `EXPLORED_EVERY_NS`.
    pub fn explored_due(&self, end_ns: u64) -> bool {
        self.explored.last().is_none_or(|(t, _)| end_ns >= t + EXPLORED_EVERY_NS)
    }

    /// The robot's floor grid knew `area_m2` of traversable floor at `end_ns`.
    pub fn explored(&mut self, end_ns: u64, area_m2: f64) {
        self.explored.push((end_ns, area_m2));
    }

    fn exploration(&self) -> ExplorationReport {
        let first = self.truth.gt_robot.first().map_or(0, |g| g.0);
        ExplorationReport {
            route: match self.truth.explored.as_ref().and_then(|e| e.get("mode")).and_then(|m| m.as_str()) {
                Some("closed_loop") => "explorer",
                _ => "scripted",
            },
            closed_loop: self.truth.explored.clone(),
            area_m2: self.explored.last().map_or(f64::NAN, |e| e.1),
            area_by_time: self.explored.iter().map(|&(t, a)| [t.saturating_sub(first) as f64 * 1e-9, a]).collect(),
        }
    }

    /// The robot's LIO world from the truth's world, fixed at the robot's first pose.
    pub fn lio_t_world(&self) -> Option<Isometry3<f64>> {
        self.robot_odom.frame_t_world()
    }

    /// One pose of the rig's own LIO (its odometry frame) with its health, scored against the
    /// rig's true path ([`crate::odometry`]).
    pub fn rig_lio_pose(&mut self, end_ns: u64, odom: &Isometry3<f64>, health: Health) {
        let truth = at(&self.truth.gt_fpv, end_ns);
        self.rig_lio.push(end_ns, odom, &truth, Some(health));
    }

    /// The rig's first LIO pose (alignment times count from it).
    pub fn rig_started(&mut self, first_ns: u64) {
        self.rig_first_ns.get_or_insert(first_ns);
    }

    /// One rig scan, to find when the rig first sees the robot's map ([`crate::map_sight`]);
    /// `map` gives the robot's map (its LIO world) as it stands, asked for only when it changed.
    pub fn rig_scan(&mut self, scan: &LioScan, map_len: usize, map: impl FnOnce() -> Vec<Vector3<f64>>) {
        let (Some(first), Some(l_t_w)) = (self.rig_first_ns, self.lio_t_world()) else { return };
        let Some(since_ns) = scan.end_ns.checked_sub(first) else { return };
        if self.sight.wants_map(map_len, scan.end_ns) {
            self.sight.set_map(map(), scan.end_ns);
        }
        let gt_fpv = &self.truth.gt_fpv;
        self.sight.scan(scan, since_ns / 1_000_000_000, |t| l_t_w * at(gt_fpv, t));
    }

    /// One detection window of the robot, matched against the true people.
    pub fn detection(&mut self, d: &RobotDetection) {
        let Some(l_t_w) = self.lio_t_world() else { return };
        let boxes = people_at(&self.truth.people, d.stamp_ns);
        let truth_people = truth_in_world(&boxes, &l_t_w, &d.points, self.truth.robot_returns.as_ref());
        let rule = MatchRule::default();
        let m = match_window(&d.found, &truth_people, &rule);
        self.tally_poses(d, &boxes, &truth_people, &m, &rule);
        let posed: Vec<(TruthPerson, TruePose)> =
            truth_people.iter().cloned().zip(boxes.iter().map(|b| b.pose)).collect();
        self.ap.window(&d.found, &posed, rule.min_returns);
        for label in m.detection_label.iter().flatten() {
            self.detected.record(*label, d.stamp_ns);
        }
        if tracing::enabled!(tracing::Level::DEBUG) {
            let w_t_l = l_t_w.inverse();
            for (det, label) in d.found.iter().zip(&m.detection_label) {
                let at = w_t_l.transform_point(&det.centre_m.into());
                if label.is_none() {
                    tracing::debug!(stamp_ns = d.stamp_ns, x_m = at.x, y_m = at.y, z_m = at.z, size_m = ?det.size_m, pose = ?det.pose, score = det.score, "false positive (scenario frame)");
                } else {
                    tracing::trace!(stamp_ns = d.stamp_ns, x_m = at.x, y_m = at.y, z_m = at.z, size_m = ?det.size_m, pose = ?det.pose, score = det.score, "true positive (scenario frame)");
                }
            }
            // Each miss, and each person the box would have counted but their labels do not,
            // with both counts.
            for t in &truth_people {
                let in_box = box_returns(t, &d.points);
                let what = if m.missed.contains(&t.label) {
                    "missed (scenario frame)"
                } else if t.returns < rule.min_returns && in_box >= rule.min_returns {
                    "not visible: too few returns on them, though enough inside their box"
                } else {
                    continue;
                };
                let at = w_t_l.transform_point(&t.centre_m.into());
                tracing::debug!(
                    stamp_ns = d.stamp_ns,
                    label = t.label,
                    x_m = at.x,
                    y_m = at.y,
                    returns = t.returns,
                    box_returns = in_box,
                    "{what}"
                );
            }
        }
        self.counts.add(&m.counts);
        self.windows += 1;
    }

    /// Recall per true posture and precision per detected posture, for one window.
    fn tally_poses(
        &mut self,
        d: &RobotDetection,
        boxes: &[PersonBox],
        people: &[TruthPerson],
        m: &WindowMatch,
        rule: &MatchRule,
    ) {
        for (b, t) in boxes.iter().zip(people).filter(|(_, t)| t.returns >= rule.min_returns) {
            let e = self.per_true_pose.entry(b.pose.name()).or_default();
            e.0 += 1;
            e.1 += usize::from(!m.missed.contains(&t.label));
        }
        for (det, label) in d.found.iter().zip(&m.detection_label) {
            let visible =
                label.and_then(|l| people.iter().find(|t| t.label == l)).map(|t| t.returns >= rule.min_returns);
            let e = self.per_detected_pose.entry(class_of_pose(det.pose)).or_default();
            match visible {
                Some(true) => e.0 += 1,
                Some(false) => {}
                None => e.1 += 1,
            }
        }
    }

    /// An alignment attempt that ran: `accepted` when the rig took it.
    pub fn alignment(&mut self, end_ns: u64, world_t_lidar: &Isometry3<f64>, total_ms: f64, accepted: bool) {
        self.attempts += 1;
        self.align_ms.push(total_ms);
        if !accepted {
            if let Some(l_t_w) = self.lio_t_world().filter(|_| total_ms.is_finite()) {
                let (m, deg) = pose_error(world_t_lidar, &(l_t_w * at(&self.truth.gt_fpv, end_ns)));
                tracing::debug!(error_m = m, error_deg = deg, "rig alignment refused");
            }
            return;
        }
        self.accepted += 1;
        if let Some(l_t_w) = self.lio_t_world() {
            let (m, deg) = pose_error(world_t_lidar, &(l_t_w * at(&self.truth.gt_fpv, end_ns)));
            tracing::info!(error_m = m, error_deg = deg, "rig alignment accepted");
            let since_ns = end_ns.saturating_sub(self.rig_first_ns.unwrap_or(end_ns));
            self.first_accept.get_or_insert((since_ns, m, deg));
            if m <= RIGHT_M && deg <= RIGHT_DEG {
                self.first_right_ns.get_or_insert(since_ns);
            } else {
                self.accepted_wrong += 1;
            }
        }
    }

    /// One camera frame as the rig rendered it; with `png_dir`, its AR frame is written there.
    pub fn frame(&mut self, f: &CameraFrame, view: &View, render_ms: f64, png_dir: Option<&Path>) -> Result<()> {
        if let Some(dir) = png_dir {
            let path = dir.join(format!("{:06}.png", f.index));
            let png = view.frame.to_png().map_err(|source| EvalError::Pipeline { path: path.clone(), source })?;
            write(&path, png)?;
        }
        let camera = &self.truth.mount.camera;
        self.projected.clear();
        if view.aligned {
            ar::project_people(camera, &view.world_t_camera, &view.people, &mut self.projected);
        }
        let (mut in_image, mut in_mask, mut true_pose) = (0, 0, (0, 0));
        if view.aligned && !view.people.is_empty() {
            if let Some(mask) = self.truth.see_through(f.index)? {
                let (w, h) = (mask.width, mask.height);
                (in_mask, in_image) = ar::mask_inlier_ratio(&self.projected, &mask.pixels, w, h);
                // The same people through the true camera pose: what detection alone scores.
                if let Some(l_t_w) = self.lio_t_world() {
                    let mut with_truth = Vec::new();
                    ar::project_people(camera, &(l_t_w * f.world_t_camera), &view.people, &mut with_truth);
                    true_pose = ar::mask_inlier_ratio(&with_truth, &mask.pixels, w, h);
                }
            }
        }
        let rig_pose = view.aligned.then(|| view.world_t_camera * self.truth.mount.lidar_t_camera.inverse());
        let pose_error = match (rig_pose, self.lio_t_world()) {
            (Some(p), Some(l_t_w)) => Some(pose_error(&p, &(l_t_w * at(&self.truth.gt_fpv, f.t_ns)))),
            _ => None,
        };
        let t_s = f.t_ns.saturating_sub(self.truth.frames.first().map_or(0, |f| f.t_ns)) as f64 * 1e-9;
        if let Some((m, deg)) = pose_error {
            self.err_m.push(m);
            self.err_deg.push(deg);
            self.err_series.push((t_s, m * 100.0));
        }
        self.true_in_mask += true_pose.0;
        self.true_in_image += true_pose.1;
        if in_image > 0 {
            self.inlier_series.push((t_s, 100.0 * in_mask as f64 / in_image as f64));
            self.in_mask += in_mask;
            self.in_image += in_image;
            self.per_frame_ratio.push(in_mask as f64 / in_image as f64);
        }
        self.frame_rows.push(format!(
            "{},{}.{:09},{},{},{},{},{},{},{},{:.3}",
            f.index,
            f.t_ns / 1_000_000_000,
            f.t_ns % 1_000_000_000,
            view.aligned,
            view.people.len(),
            view.detection_age_ms.map_or(String::new(), |a| format!("{a:.1}")),
            in_image,
            in_mask,
            pose_error.map_or(String::new(), |e| format!("{:.4}", e.0)),
            pose_error.map_or(String::new(), |e| format!("{:.3}", e.1)),
            render_ms
        ));
        let drawn = self.projected.iter().map(|p| (p.u, p.v)).collect();
        self.pending.push_back(PendingFrame { index: f.index, t_ns: f.t_ns, drawn, aligned: view.aligned });
        self.score_overlays(false)
    }

    /// The overlay metrics of the frames whose time the robot has passed (`all`: every frame
    /// left, at the end of the run): who it detected in the second before each is known then.
    fn score_overlays(&mut self, all: bool) -> Result<()> {
        while let Some(f) = self.pending.front() {
            if !all && self.robot_ns.is_none_or(|t| f.t_ns > t) {
                break;
            }
            let Some(f) = self.pending.pop_front() else { break };
            let detected = self.detected.recent(f.t_ns, DETECTED_WITHIN_NS);
            if detected.is_empty() {
                continue;
            }
            let Some(see_through) = self.truth.see_through(f.index)? else { continue };
            let visible = self.truth.visible(f.index)?;
            self.overlay.frame(&see_through, visible.as_ref(), &f.drawn, &detected, f.aligned);
        }
        Ok(())
    }

    /// The report, written as `report.json` with `frames.csv` and the plots into `out`.
    pub fn finish(
        mut self,
        mode: &'static str,
        latency: LatencyReport,
        total_ms: &[f64],
        memory: MemoryReport,
        wall_s: f64,
        out: &Path,
    ) -> Result<Report> {
        self.score_overlays(true)?;
        let gt = &self.truth.gt_robot;
        let ratio = |a: usize, b: usize| if b > 0 { a as f64 / b as f64 } else { f64::NAN };
        let report = Report {
            scenario: self.truth.scenario.clone(),
            mode,
            duration_s: gt.last().map_or(0.0, |(t, _)| (t - gt.first().map_or(*t, |g| g.0)) as f64 * 1e-9),
            inlier_ratio: InlierReport {
                pooled: ratio(self.in_mask, self.in_image),
                points_in_mask: self.in_mask,
                pooled_true_pose: ratio(self.true_in_mask, self.true_in_image),
                points_in_image: self.in_image,
                frames_scored: self.per_frame_ratio.len(),
                per_frame: quantiles(&self.per_frame_ratio),
            },
            overlay: self.overlay.report(),
            detection: DetectionReport {
                precision: self.counts.precision(),
                recall: self.counts.recall(),
                true_positives: self.counts.true_positives,
                false_positives: self.counts.false_positives,
                misses: self.counts.misses,
                windows: self.windows,
                per_true_pose: self
                    .per_true_pose
                    .iter()
                    .map(|(&k, &(visible, found))| {
                        (k, PoseRecall { visible, found, recall: found as f64 / visible.max(1) as f64 })
                    })
                    .collect(),
                per_detected_pose: self
                    .per_detected_pose
                    .iter()
                    .map(|(&k, &(tp, fp))| {
                        let precision = if tp + fp == 0 { 1.0 } else { tp as f64 / (tp + fp) as f64 };
                        (k, PosePrecision { true_positives: tp, false_positives: fp, precision })
                    })
                    .collect(),
                average_precision: self.ap.report(),
            },
            alignment: AlignmentReport {
                first_accepted_after_s: self.first_accept.map(|(dt, _, _)| dt as f64 * 1e-9),
                attempts: self.attempts,
                accepted: self.accepted,
                time_ms: quantiles(&self.align_ms),
                first_error_m: self.first_accept.map(|(_, m, _)| m),
                first_error_deg: self.first_accept.map(|(_, _, d)| d),
                first_right_after_s: self.first_right_ns.map(|ns| ns as f64 * 1e-9),
                accepted_wrong: self.accepted_wrong,
                map_sight: self.map_sight_report(),
            },
            rig_pose_error: PoseErrorReport {
                translation_m: quantiles(&self.err_m),
                rotation_deg: quantiles(&self.err_deg),
            },
            robot_pose_error: self.robot_odom.report(),
            rig_lio_error: (!self.rig_lio.is_empty()).then(|| self.rig_lio.report()),
            exploration: self.exploration(),
            latency_ms: latency,
            memory,
            wall_s,
        };
        report.write(&out.join("report.json"))?;
        write(&out.join("frames.csv"), self.frame_rows.join("\n") + "\n")?;
        write(&out.join("robot_error.csv"), self.robot_odom.csv())?;
        if report.rig_lio_error.is_some() {
            write(&out.join("rig_error.csv"), self.rig_lio.csv())?;
        }
        write_plots(out, &self.err_series, &self.inlier_series, total_ms)?;
        Ok(report)
    }

    fn map_sight_report(&self) -> MapSightReport {
        let (seconds_judged, seconds_seeing_map) = self.sight.seconds_seeing();
        let sees_map_after_s = self.sight.first_seen_s();
        let right_in_time = sees_map_after_s.map(|s| {
            let deadline_ns = s * 1_000_000_000 + RIGHT_WITHIN_NS;
            self.first_right_ns.is_some_and(|ns| ns <= deadline_ns)
        });
        MapSightReport {
            sees_map_after_s: sees_map_after_s.map(|s| s as f64),
            best_share: self.sight.best_share(),
            seconds_judged,
            seconds_seeing_map,
            right_within_10s: right_in_time,
        }
    }
}

/// The root mean square of the finite values of `v` (NaN when there are none).
pub(crate) fn rmse(v: &[f64]) -> f64 {
    let (sum, n) = v.iter().filter(|x| x.is_finite()).fold((0.0, 0usize), |(s, n), x| (s + x * x, n + 1));
    if n == 0 {
        f64::NAN
    } else {
        (sum / n as f64).sqrt()
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use crate::truth::CameraMount;
    use nalgebra::{Translation3, UnitQuaternion, Vector3};
    use starc_pipeline::ar::CameraModel;

    /// A truth with only the robot's trajectory: 10 s along x, turning 3 deg a second.
    fn truth() -> Truth {
        let gt_robot = (0..=10u64)
            .map(|s| {
                let yaw = (3.0 * s as f64).to_radians();
                let pose = Isometry3::from_parts(
                    Translation3::new(s as f64, 0.5, 1.2),
                    UnitQuaternion::from_euler_angles(0.0, 0.0, yaw),
                );
                (s * 1_000_000_000, pose)
            })
            .collect();
        Truth {
            dir: std::path::PathBuf::new(),
            scenario: "synthetic".into(),
            gt_robot,
            gt_fpv: Vec::new(),
            people: Vec::new(),
            frames: Vec::new(),
            mount: CameraMount { camera: CameraModel::default(), lidar_t_camera: Isometry3::identity() },
            robot_returns: None,
            explored: None,
        }
    }

    #[test]
    fn robot_poses_are_scored_against_the_truth_from_the_first_pose_on() {
        let mut score = Scorer::new(truth());
        // The LIO world: anywhere, turned any way.
        let lio_t_world = Isometry3::from_parts(
            Translation3::new(-4.0, 7.0, 0.3),
            UnitQuaternion::from_euler_angles(0.02, -0.01, 1.1),
        );
        // After the first pose, every pose 5 cm off (3 cm, 4 cm in the truth's world) and
        // turned 2 deg about its own z.
        let off = Translation3::new(0.03, 0.04, 0.0);
        let turn = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 2f64.to_radians());
        let times: Vec<u64> = (0..20u64).map(|i| i * 500_000_000).collect();
        for (i, &t) in times.iter().enumerate() {
            let truth = at(&score.truth.gt_robot, t);
            let pose = if i == 0 { lio_t_world * truth } else { lio_t_world * off * truth * turn };
            score.robot_pose(t, &pose, None);
        }
        let out = tempfile::tempdir().unwrap();
        let memory = MemoryReport { peak_rss_mib: None, note: None };
        let report = score.finish("offline", LatencyReport::default(), &[], memory, 0.0, out.path()).unwrap();
        let e = &report.robot_pose_error;
        assert_eq!(e.translation_m.n, 20);
        assert!((e.translation_m.p50 - 0.05).abs() < 1e-9, "{:?}", e.translation_m);
        assert!((e.translation_m.max - 0.05).abs() < 1e-9);
        assert!((e.rotation_deg.p50 - 2.0).abs() < 1e-9, "{:?}", e.rotation_deg);
        // The first pose is the anchor: no error, and one of the twenty in the RMSE.
        let rmse = 0.05 * (19.0f64 / 20.0).sqrt();
        assert!((e.rmse_m - rmse).abs() < 1e-9, "{} != {rmse}", e.rmse_m);
        let json: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.path().join("report.json")).unwrap()).unwrap();
        for key in ["translation_m/p50", "translation_m/p99", "translation_m/max", "rotation_deg/p50", "rmse_m"] {
            assert!(json.pointer(&format!("/robot_pose_error/{key}")).is_some_and(|v| v.is_f64()), "{key}");
        }
        // No rig pose came: its odometry is not scored, and says so.
        assert!(json.pointer("/rig_lio_error").is_some_and(serde_json::Value::is_null));
        assert!(!out.path().join("rig_error.csv").exists());
        assert!(json.pointer("/rig_pose_error/translation_m").is_some(), "the rig's key stays");
        let csv = std::fs::read_to_string(out.path().join("robot_error.csv")).unwrap();
        let lines: Vec<&str> = csv.lines().collect();
        assert_eq!(lines.len(), 21, "a header and one row per pose");
        assert_eq!(lines[0], "time_s,error_m,error_deg,health");
        assert_eq!(lines[1], "0.000,0.0000,0.000,", "no health reported: the field stays empty");
        assert_eq!(lines[20], "9.500,0.0500,2.000,");
    }

    /// A rig scan of a wall 3 m ahead of the LiDAR (x forward), 200 returns at `t_ns`.
    fn wall_scan(t_ns: u64) -> LioScan {
        let points = (0..200)
            .map(|i| starc_pipeline::lio::TimedPoint {
                x_m: 3.0,
                y_m: (i % 20) as f32 * 0.1 - 1.0,
                z_m: (i / 20) as f32 * 0.1,
                t_ns,
            })
            .collect();
        LioScan { start_ns: t_ns, end_ns: t_ns, clock: starc_pipeline::lio::Clock::Ptp, points }
    }

    #[test]
    fn the_rig_is_judged_from_when_it_first_sees_the_map() {
        // The rig stands at the truth's origin, looking along x; the robot's map gains the
        // wall it looks at 4 s after the rig started.
        let mut t = truth();
        t.gt_fpv = vec![(0, Isometry3::identity()), (60_000_000_000, Isometry3::identity())];
        let mut score = Scorer::new(t);
        score.robot_pose(0, &at(&score.truth.gt_robot, 0), None);
        score.rig_started(1_000_000_000);
        let wall: Vec<Vector3<f64>> =
            (0..200).map(|i| Vector3::new(3.0, (i % 20) as f64 * 0.1 - 1.0, (i / 20) as f64 * 0.1)).collect();
        for s in 1..20u64 {
            let map = if s >= 5 { wall.clone() } else { vec![Vector3::new(-20.0, 0.0, 0.0)] };
            score.rig_scan(&wall_scan(s * 1_000_000_000), map.len(), || map.clone());
        }
        // A wrong alignment at 6 s (30 cm off), a right one at 12 s: 8 s after it saw the map.
        let off = Isometry3::translation(0.3, 0.0, 0.0);
        score.alignment(7_000_000_000, &off, 50.0, true);
        score.alignment(13_000_000_000, &Isometry3::identity(), 50.0, true);
        let out = tempfile::tempdir().unwrap();
        let memory = MemoryReport { peak_rss_mib: None, note: None };
        let report = score.finish("offline", LatencyReport::default(), &[], memory, 0.0, out.path()).unwrap();
        let a = &report.alignment;
        assert_eq!(a.map_sight.sees_map_after_s, Some(4.0));
        assert_eq!(a.map_sight.right_within_10s, Some(true));
        assert_eq!(a.accepted_wrong, 1);
        assert_eq!(a.first_right_after_s, Some(12.0));
        assert_eq!(a.first_accepted_after_s, Some(6.0));
    }

    #[test]
    fn rmse_of_nothing_is_nan() {
        assert!(rmse(&[]).is_nan());
        assert!((rmse(&[3.0, f64::NAN, 4.0]) - 12.5f64.sqrt()).abs() < 1e-12);
    }
}
