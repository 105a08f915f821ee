//! Scoring a mission run against the simulator's truth, shared by the offline mission
//! (`starc mission`) and the live one (`starc sim`): detection against the true people, the rig's
//! alignment and world pose against its true pose, and every AR frame's projected person points
//! against the see-through masks (the paper's inlier ratio). Writes `report.json` (stable keys,
//! see docs/mission.md), `frames.csv` and the plots.

use super::mission_truth::{self as truth, CameraFrame, CameraMount, PersonBox, PersonReturns, Trajectory};
use anyhow::Context;
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion};
use serde::Serialize;
use starc_pipeline::align::pose_error;
use starc_pipeline::ar::{self, ProjectedPoint};
use starc_pipeline::detect::eval::{match_window, Counts, MatchRule, TruthPerson};
use starc_pipeline::detect::WindowPoint;
use starc_pipeline::mission::{RobotDetection, View};
use std::path::{Path, PathBuf};

/// What the simulator wrote about a run.
pub struct Truth {
    pub dir: PathBuf,
    pub scenario: String,
    pub gt_robot: Trajectory,
    pub gt_fpv: Trajectory,
    pub people: Vec<PersonBox>,
    pub frames: Vec<CameraFrame>,
    pub mount: CameraMount,
    /// Which people the robot's returns hit (`labels_robot.bin`); without it, a person's returns
    /// are those of the window inside their box grown by 0.1 m, the floor and furniture included.
    pub robot_returns: Option<PersonReturns>,
}

impl Truth {
    pub fn load(dir: &Path) -> anyhow::Result<Self> {
        let scenario = std::fs::read_to_string(dir.join("scenario.toml"))
            .ok()
            .and_then(|t| t.lines().find_map(|l| l.strip_prefix("name = ").map(|n| n.trim_matches('"').to_string())))
            .unwrap_or_default();
        Ok(Self {
            dir: dir.to_path_buf(),
            scenario,
            gt_robot: truth::read_tum(&dir.join("gt_robot.tum"))?,
            gt_fpv: truth::read_tum(&dir.join("gt_fpv.tum"))?,
            people: truth::read_people(&dir.join("people.csv"))?,
            frames: truth::read_frames(&dir.join("camera/frames.csv"))
                .context("the mission scores camera frames: run `starc sim` without --no-camera")?,
            mount: truth::read_camera(&dir.join("extrinsics.json"))?,
            robot_returns: {
                let path = dir.join("labels_robot.bin");
                if path.exists() {
                    Some(PersonReturns::read(&path)?)
                } else {
                    tracing::warn!(
                        "{}: no labels_robot.bin; a person counts as visible by the returns inside their box",
                        dir.display()
                    );
                    None
                }
            },
        })
    }

    /// Where the responder is expected to start, in the robot's LIO world: the rig's true pose at
    /// `t_ns`, moved `hint_m` and turned `hint_deg` (standing for a marked entry point or a
    /// hand-off next to the robot).
    pub fn start_hint(&self, lio_t_world: &Isometry3<f64>, t_ns: u64, hint_m: f64, hint_deg: f64) -> Isometry3<f64> {
        let off = Isometry3::from_parts(
            Translation3::new(0.8 * hint_m, -0.6 * hint_m, 0.0),
            UnitQuaternion::from_euler_angles(0.0, 0.0, hint_deg.to_radians()),
        );
        lio_t_world * truth::at(&self.gt_fpv, t_ns) * off
    }
}

#[derive(Default, Serialize)]
pub struct Quantiles {
    pub p50: f64,
    pub p99: f64,
    pub max: f64,
    pub n: usize,
}

pub fn quantiles(v: &[f64]) -> Quantiles {
    let mut s: Vec<f64> = v.iter().copied().filter(|x| x.is_finite()).collect();
    s.sort_by(f64::total_cmp);
    let q = |f: f64| s.get(((s.len().saturating_sub(1)) as f64 * f).round() as usize).copied().unwrap_or(f64::NAN);
    Quantiles { p50: q(0.5), p99: q(0.99), max: q(1.0), n: s.len() }
}

#[derive(Serialize)]
pub struct Report {
    pub scenario: String,
    /// What ran: "offline" (one process, no link, no nodes) or "live" (mock devices, the robot
    /// and rig nodes, the link on loopback).
    pub mode: &'static str,
    pub duration_s: f64,
    pub inlier_ratio: InlierReport,
    pub detection: DetectionReport,
    pub alignment: AlignmentReport,
    pub rig_pose_error: PoseErrorReport,
    pub latency_ms: LatencyReport,
    pub memory: MemoryReport,
    pub wall_s: f64,
}

#[derive(Serialize)]
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

#[derive(Serialize)]
pub struct DetectionReport {
    pub precision: f64,
    pub recall: f64,
    pub true_positives: usize,
    pub false_positives: usize,
    pub misses: usize,
    pub windows: usize,
}

#[derive(Serialize)]
pub struct AlignmentReport {
    /// Time of the first accepted alignment after the rig's LIO started (s); null if none.
    pub first_accepted_after_s: Option<f64>,
    pub attempts: usize,
    pub accepted: usize,
    pub time_ms: Quantiles,
    /// The first accepted alignment's error against the truth.
    pub first_error_m: Option<f64>,
    pub first_error_deg: Option<f64>,
}

#[derive(Serialize)]
pub struct PoseErrorReport {
    pub translation_m: Quantiles,
    pub rotation_deg: Quantiles,
}

#[derive(Default, Serialize)]
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

#[derive(Serialize)]
pub struct MemoryReport {
    /// The whole process (both sides in the offline run; both nodes and the mocks live): peak
    /// resident MiB.
    pub peak_rss_mib: Option<f64>,
    /// Live: each node's own heap-held state is not separable in one process; its peak RSS when
    /// run as its own process is in docs/mission.md.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub note: Option<String>,
}

fn yaw_of(q: &UnitQuaternion<f64>) -> f64 {
    q.euler_angles().2
}

/// The true people in the LIO world, each with the window's returns on them: from the simulator's
/// labels where it wrote them (as the detect bench counts), else those inside their box grown by
/// 0.1 m (`box_returns`, which also counts the floor and furniture around them).
fn truth_in_world(
    people: &[PersonBox],
    lio_t_world: &Isometry3<f64>,
    points: &[WindowPoint],
    labelled: Option<&PersonReturns>,
) -> Vec<TruthPerson> {
    let yaw = yaw_of(&lio_t_world.rotation);
    let (from_ns, to_ns) = points.iter().fold((u64::MAX, 0), |(a, b), p| (a.min(p.t_ns), b.max(p.t_ns)));
    people
        .iter()
        .map(|p| {
            let centre = (lio_t_world * Point3::from(p.centre_m)).coords;
            let yaw_rad = p.yaw_rad + yaw;
            let mut t = TruthPerson { label: p.label, centre_m: centre, size_m: p.size_m, yaw_rad, returns: 0 };
            t.returns = match labelled {
                Some(l) => l.on_person(p.label, from_ns, to_ns),
                None => box_returns(&t, points),
            };
            t
        })
        .collect()
}

/// The window's returns inside a person's box grown by 0.1 m on every side.
fn box_returns(t: &TruthPerson, points: &[WindowPoint]) -> usize {
    points.iter().filter(|q| t.contains(&q.xyz(), 0.1)).count()
}

/// Everything scored so far.
pub struct Scorer {
    pub truth: Truth,
    /// The robot's LIO world from the truth's world, fixed at the robot's first pose.
    pub lio_t_world: Option<Isometry3<f64>>,
    counts: Counts,
    windows: usize,
    rig_first_ns: Option<u64>,
    attempts: usize,
    accepted: usize,
    align_ms: Vec<f64>,
    first_accept: Option<(u64, f64, f64)>,
    in_mask: usize,
    in_image: usize,
    true_in_mask: usize,
    true_in_image: usize,
    per_frame_ratio: Vec<f64>,
    err_m: Vec<f64>,
    err_deg: Vec<f64>,
    err_series: Vec<(f64, f64)>,
    inlier_series: Vec<(f64, f64)>,
    frame_rows: Vec<String>,
    projected: Vec<ProjectedPoint>,
}

impl Scorer {
    pub fn new(truth: Truth) -> Self {
        Self {
            truth,
            lio_t_world: None,
            counts: Counts::default(),
            windows: 0,
            rig_first_ns: None,
            attempts: 0,
            accepted: 0,
            align_ms: Vec::new(),
            first_accept: None,
            in_mask: 0,
            in_image: 0,
            true_in_mask: 0,
            true_in_image: 0,
            per_frame_ratio: Vec::new(),
            err_m: Vec::new(),
            err_deg: Vec::new(),
            err_series: Vec::new(),
            inlier_series: Vec::new(),
            frame_rows: vec![
                "frame,time_s,aligned,detections,age_ms,points_in_image,points_in_mask,pose_error_m,pose_error_deg,render_ms"
                    .to_string(),
            ],
            projected: Vec::new(),
        }
    }

    /// A robot LIO pose; the first one ties the robot's LIO world to the truth's.
    pub fn robot_pose(&mut self, end_ns: u64, lidar_pose: &Isometry3<f64>) {
        if self.lio_t_world.is_none() {
            self.lio_t_world = Some(lidar_pose * truth::at(&self.truth.gt_robot, end_ns).inverse());
        }
    }

    /// The rig's first LIO pose (alignment times count from it).
    pub fn rig_started(&mut self, first_ns: u64) {
        self.rig_first_ns.get_or_insert(first_ns);
    }

    pub fn detection(&mut self, d: &RobotDetection) {
        if let Some(l_t_w) = &self.lio_t_world {
            let truth_people = truth_in_world(
                &truth::people_at(&self.truth.people, d.stamp_ns),
                l_t_w,
                &d.points,
                self.truth.robot_returns.as_ref(),
            );
            let rule = MatchRule::default();
            let m = match_window(&d.found, &truth_people, &rule);
            if tracing::enabled!(tracing::Level::DEBUG) {
                let w_t_l = l_t_w.inverse();
                for (det, label) in d.found.iter().zip(&m.detection_label) {
                    if label.is_none() {
                        let at = w_t_l.transform_point(&det.centre_m.into());
                        tracing::debug!(stamp_ns = d.stamp_ns, x_m = at.x, y_m = at.y, z_m = at.z, size_m = ?det.size_m, pose = ?det.pose, score = det.score, "false positive (scenario frame)");
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
    }

    /// An alignment attempt that ran: `accepted` when the rig took it.
    pub fn alignment(&mut self, end_ns: u64, world_t_lidar: &Isometry3<f64>, total_ms: f64, accepted: bool) {
        self.attempts += 1;
        self.align_ms.push(total_ms);
        if !accepted {
            if let Some(l_t_w) = self.lio_t_world.as_ref().filter(|_| total_ms.is_finite()) {
                let (m, deg) = pose_error(world_t_lidar, &(l_t_w * truth::at(&self.truth.gt_fpv, end_ns)));
                tracing::debug!(error_m = m, error_deg = deg, "rig alignment refused");
            }
            return;
        }
        self.accepted += 1;
        if let Some(l_t_w) = &self.lio_t_world {
            let (m, deg) = pose_error(world_t_lidar, &(l_t_w * truth::at(&self.truth.gt_fpv, end_ns)));
            tracing::info!(error_m = m, error_deg = deg, "rig alignment accepted");
            if self.first_accept.is_none() {
                let first = self.rig_first_ns.unwrap_or(end_ns);
                self.first_accept = Some((end_ns.saturating_sub(first), m, deg));
            }
        }
    }

    /// One camera frame as the rig rendered it.
    pub fn frame(
        &mut self,
        f: &CameraFrame,
        view: &View,
        render_ms: f64,
        png_dir: Option<&Path>,
    ) -> anyhow::Result<()> {
        if let Some(dir) = png_dir {
            std::fs::write(dir.join(format!("{:06}.png", f.index)), view.frame.to_png()?)?;
        }
        let camera = &self.truth.mount.camera;
        self.projected.clear();
        if view.aligned {
            ar::project_people(camera, &view.world_t_camera, &view.people, &mut self.projected);
        }
        let (mut in_image, mut in_mask, mut true_pose) = (0, 0, (0, 0));
        if view.aligned && !view.people.is_empty() {
            let mask_path = self.truth.dir.join(format!("camera/see_through/{:06}.png", f.index));
            if let Ok(bytes) = std::fs::read(&mask_path) {
                let (w, h, mask) = ar::read_mask_png(&bytes)?;
                (in_mask, in_image) = ar::mask_inlier_ratio(&self.projected, &mask, w, h);
                // The same people through the true camera pose: what detection alone scores.
                if let Some(l_t_w) = &self.lio_t_world {
                    let mut with_truth = Vec::new();
                    ar::project_people(camera, &(l_t_w * f.world_t_camera), &view.people, &mut with_truth);
                    true_pose = ar::mask_inlier_ratio(&with_truth, &mask, w, h);
                }
            }
        }
        let rig_pose = view.aligned.then(|| view.world_t_camera * self.truth.mount.lidar_t_camera.inverse());
        let pose_error = match (rig_pose, &self.lio_t_world) {
            (Some(p), Some(l_t_w)) => Some(pose_error(&p, &(l_t_w * truth::at(&self.truth.gt_fpv, f.t_ns)))),
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
        Ok(())
    }

    /// The report, written with `frames.csv` and the plots into `out`.
    pub fn finish(
        self,
        mode: &'static str,
        latency: LatencyReport,
        total_ms: &[f64],
        memory: MemoryReport,
        wall_s: f64,
        out: &Path,
    ) -> anyhow::Result<Report> {
        let gt = &self.truth.gt_robot;
        let report = Report {
            scenario: self.truth.scenario.clone(),
            mode,
            duration_s: gt.last().map_or(0.0, |(t, _)| (t - gt.first().map_or(*t, |g| g.0)) as f64 * 1e-9),
            inlier_ratio: InlierReport {
                pooled: if self.in_image > 0 { self.in_mask as f64 / self.in_image as f64 } else { f64::NAN },
                points_in_mask: self.in_mask,
                pooled_true_pose: if self.true_in_image > 0 {
                    self.true_in_mask as f64 / self.true_in_image as f64
                } else {
                    f64::NAN
                },
                points_in_image: self.in_image,
                frames_scored: self.per_frame_ratio.len(),
                per_frame: quantiles(&self.per_frame_ratio),
            },
            detection: DetectionReport {
                precision: self.counts.precision(),
                recall: self.counts.recall(),
                true_positives: self.counts.true_positives,
                false_positives: self.counts.false_positives,
                misses: self.counts.misses,
                windows: self.windows,
            },
            alignment: AlignmentReport {
                first_accepted_after_s: self.first_accept.map(|(dt, _, _)| dt as f64 * 1e-9),
                attempts: self.attempts,
                accepted: self.accepted,
                time_ms: quantiles(&self.align_ms),
                first_error_m: self.first_accept.map(|(_, m, _)| m),
                first_error_deg: self.first_accept.map(|(_, _, d)| d),
            },
            rig_pose_error: PoseErrorReport {
                translation_m: quantiles(&self.err_m),
                rotation_deg: quantiles(&self.err_deg),
            },
            latency_ms: latency,
            memory,
            wall_s,
        };
        let json = serde_json::to_string_pretty(&report)?;
        std::fs::write(out.join("report.json"), json + "\n")?;
        std::fs::write(out.join("frames.csv"), self.frame_rows.join("\n") + "\n")?;
        write_plots(out, &self.err_series, &self.inlier_series, total_ms)?;
        Ok(report)
    }
}
/// plots/: the rig's pose error and the inlier ratio over time, the latency histogram.
fn write_plots(
    out: &std::path::Path,
    err_cm: &[(f64, f64)],
    inlier_pct: &[(f64, f64)],
    total_ms: &[f64],
) -> anyhow::Result<()> {
    use super::svg_plot::{histogram, lines, Series};
    let dir = out.join("plots");
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    let err = lines(
        "rig world pose error against the truth",
        "time (s)",
        "position error (cm)",
        &[Series { name: "rig", colour: "#c33", points: err_cm }],
    );
    let inl = lines(
        "projected person points inside the see-through mask",
        "time (s)",
        "inlier ratio (%)",
        &[Series { name: "per frame", colour: "#36c", points: inlier_pct }],
    );
    let lat = histogram("compute latency per robot scan (LIO + detection + AR frame)", "ms", total_ms, 30);
    for (name, svg) in [("pose_error.svg", err), ("inlier_ratio.svg", inl), ("latency.svg", lat)] {
        std::fs::write(dir.join(name), svg).with_context(|| format!("writing {}", dir.join(name).display()))?;
    }
    Ok(())
}

pub fn summary(r: &Report) -> String {
    use std::fmt::Write as _;
    let mut o = String::new();
    let pct = |v: f64| if v.is_finite() { format!("{:.1} %", v * 100.0) } else { "n/a".into() };
    let _ = writeln!(o, "mission {} ({}, {:.1} s):", r.scenario, r.mode, r.duration_s);
    let i = &r.inlier_ratio;
    let _ = writeln!(
        o,
        "  inlier ratio (person points in the see-through masks): {} over {} frames (through the true camera pose: {})",
        pct(i.pooled),
        i.frames_scored,
        pct(i.pooled_true_pose)
    );
    let d = &r.detection;
    let _ = writeln!(
        o,
        "  detection: precision {:.3}, recall {:.3} ({} true, {} false, {} missed over {} windows)",
        d.precision, d.recall, d.true_positives, d.false_positives, d.misses, d.windows
    );
    let a = &r.alignment;
    match (a.first_accepted_after_s, a.first_error_m, a.first_error_deg) {
        (Some(t), Some(m), Some(deg)) => {
            let _ = writeln!(
                o,
                "  alignment: first accepted {t:.1} s after the rig started, {:.1} cm / {deg:.2} deg off the truth; \
                 {} of {} attempts accepted, {:.0} ms median",
                m * 100.0,
                a.accepted,
                a.attempts,
                a.time_ms.p50
            );
        }
        _ => {
            let _ = writeln!(o, "  alignment: none accepted in {} attempts: nothing was drawn", a.attempts);
        }
    }
    let e = &r.rig_pose_error;
    let _ = writeln!(
        o,
        "  rig world pose error: {:.1} cm median, {:.1} cm p99; {:.2} deg median",
        e.translation_m.p50 * 100.0,
        e.translation_m.p99 * 100.0,
        e.rotation_deg.p50
    );
    let l = &r.latency_ms;
    let _ = writeln!(
        o,
        "  latency (p50 / p99): L_SLAM {:.1} / {:.1} ms, L_comm {:.1} / {:.1} ms, L_viz {:.1} / {:.1} ms, total {:.1} / {:.1} ms{}; \
         peak memory {:.0} MiB",
        l.slam_p50,
        l.slam_p99,
        l.comm_p50,
        l.comm_p99,
        l.viz_p50,
        l.viz_p99,
        l.total_p50,
        l.total_p99,
        if r.mode == "offline" { " (compute only: no link in this path)" } else { "" },
        r.memory.peak_rss_mib.unwrap_or(f64::NAN)
    );
    o
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use nalgebra::Vector3;

    #[test]
    fn a_person_is_visible_by_the_returns_on_them_not_by_what_lies_in_their_box() {
        let person = PersonBox {
            t_ns: 0,
            label: 1,
            centre_m: Vector3::new(2.0, 0.0, 0.9),
            size_m: Vector3::new(0.4, 0.5, 1.8),
            yaw_rad: 0.0,
        };
        // 40 floor returns inside the box grown by 0.1 m, fired over [1000, 1039] ns.
        let points: Vec<WindowPoint> = (0..40u64)
            .map(|i| WindowPoint { x_m: 1.85 + 0.0075 * i as f32, y_m: 0.2, z_m: -0.05, t_ns: 1_000 + i })
            .collect();
        let by_box = truth_in_world(std::slice::from_ref(&person), &Isometry3::identity(), &points, None);
        assert_eq!(by_box[0].returns, 40);
        // The labels say none of them hit the person, and 5 of a packet in the window did.
        let file = super::super::mission_truth::tests::labels_file(&[(999, &[1; 9]), (1_010, &[0, 1, 1, 1, 1, 1])]);
        let labels = PersonReturns::read(file.path()).unwrap();
        let by_label = truth_in_world(&[person], &Isometry3::identity(), &points, Some(&labels));
        assert_eq!(by_label[0].returns, 5, "only the packet first fired inside the window counts");
    }
}
