//! The learned detector's training data (docs/pillars.md): the robot's detection windows of a
//! simulated run, made by the mission's own robot core (its LIO, its window of placed scans),
//! moved into the model frame, with each true person's box, pose class and returns, and a person
//! label per point. Written as .npy files that numpy reads without help.

use crate::clusters::{survey_window, LabelledPerson, COLUMNS};
use crate::detection::truth_in_world;
use crate::error::write;
use crate::truth::TruePose;
use crate::truth::{at, people_at, read_people, read_tum, PersonBox, PersonReturns, Trajectory};
use crate::{EvalError, Result};
use nalgebra::Isometry3;
use starc_pipeline::detect::eval::{MatchRule, TruthPerson};
use starc_pipeline::detect::pillars::npy::{le_bytes, npy};
use starc_pipeline::detect::pillars::ModelFrame;
use starc_pipeline::detect::{DetectConfig, DetectWindow, GeometricDetector, WindowPoint};
use starc_pipeline::mission::{MissionInput, RobotCore, RobotCoreConfig, RobotDetection, RobotStep, Side};
use starc_time::{Clock, Stamp};
use std::path::Path;

/// The crop of the exported points: the model's crop (docs/pillars.md) and a margin that lets
/// training turn a window by a few degrees without running out of points.
const KEEP_X_M: (f32, f32) = (-1.0, 20.2);
const KEEP_ABS_Y_M: f32 = 10.6;
const KEEP_Z_M: (f32, f32) = (-0.3, 2.7);
/// A point counts as a person's when inside their box grown by this much.
const PERSON_MARGIN_M: f64 = 0.05;
/// ... and at least this far above the floor (their feet's returns are the floor's).
const PERSON_MIN_HEIGHT_M: f64 = 0.05;

/// What a building's run gives the exporter.
pub struct BuildingTruth {
    pub gt_robot: Trajectory,
    pub people: Vec<PersonBox>,
    pub returns: PersonReturns,
}

impl BuildingTruth {
    /// From a `starc sim` output directory (the camera is not needed).
    pub fn load(dir: &Path) -> Result<Self> {
        Ok(Self {
            gt_robot: read_tum(&dir.join("gt_robot.tum"))?,
            people: read_people(&dir.join("people.csv"))?,
            returns: PersonReturns::read(&dir.join("labels_robot.bin"))?,
        })
    }
}

/// How windows are picked and framed.
#[derive(Clone, Copy, Debug)]
pub struct ExportOptions {
    /// Every Nth detection window (the mission runs one per scan over 3 scans: 3 gives windows
    /// that share no scan).
    pub every: usize,
    /// The sensor's height above the floor when a window shows no floor.
    pub sensor_height_m: f64,
    /// Write the windows' points, labels and boxes (the PointPillars data).
    pub points: bool,
    /// Write clusters.npy: every cluster the geometric detector judges, for the trees
    /// ([`crate::clusters`]).
    pub clusters: bool,
}

impl Default for ExportOptions {
    fn default() -> Self {
        Self { every: 3, sensor_height_m: 0.45, points: true, clusters: false }
    }
}

/// What one building gave.
#[derive(Clone, Copy, Debug, Default, serde::Serialize)]
pub struct Exported {
    pub windows: usize,
    pub points: usize,
    pub boxes: usize,
    /// Boxes with enough returns for the evaluation to demand them (`MatchRule::min_returns`).
    pub visible_boxes: usize,
    /// Rows of clusters.npy (0 when not written).
    pub clusters: usize,
}

/// The arrays of a building, filled window by window.
#[derive(Default)]
struct Arrays {
    points_cm: Vec<i16>,
    labels: Vec<u16>,
    windows: Vec<i64>,
    boxes: Vec<f32>,
    visible: usize,
    clusters: Vec<f32>,
    /// The detector that surveys each window's clusters, when clusters.npy is written.
    surveyor: Option<GeometricDetector>,
}

/// Runs the robot's core over a run's inputs and writes its windows into `out`
/// (points.npy, labels.npy, windows.npy, boxes.npy).
pub fn export_building<E: std::fmt::Display>(
    inputs: impl Iterator<Item = std::result::Result<MissionInput, E>>,
    truth: &BuildingTruth,
    opts: &ExportOptions,
    out: &Path,
) -> Result<Exported> {
    let pipeline = |source| EvalError::Pipeline { path: out.to_path_buf(), source };
    let mut core = RobotCore::new(RobotCoreConfig::default()).map_err(pipeline)?;
    let detect_cfg = DetectConfig::default();
    let mut arrays = Arrays::default();
    if opts.clusters {
        arrays.surveyor = Some(crate::clusters::surveyor().map_err(pipeline)?);
    }
    let (mut steps, mut lio_t_world, mut seen) = (Vec::new(), None, 0usize);
    for input in inputs {
        match input.map_err(|e| EvalError::Input(e.to_string()))? {
            MissionInput::Imu(Side::Robot, s) => core.push_imu(s, &mut steps),
            MissionInput::Scan(Side::Robot, s) => core.push_scan(s, &mut steps),
            MissionInput::Wheel(Side::Robot, w) => core.push_wheel(w),
            _ => {}
        }
        for step in steps.drain(..) {
            // The first pose ties the LIO's world to the truth's, as the scorer does.
            let l_t_w = *lio_t_world
                .get_or_insert_with(|| step.output.lidar_pose * at(&truth.gt_robot, step.output.end_ns).inverse());
            let Some(d) = &step.detection else { continue };
            seen += 1;
            if (seen - 1) % opts.every.max(1) == 0 {
                add_window(&mut arrays, &step, d, &l_t_w, truth, &detect_cfg, opts);
            }
        }
    }
    write_arrays(&arrays, opts, out)
}

fn add_window(
    arrays: &mut Arrays,
    step: &RobotStep,
    d: &RobotDetection,
    l_t_w: &Isometry3<f64>,
    truth: &BuildingTruth,
    cfg: &DetectConfig,
    opts: &ExportOptions,
) {
    let window = DetectWindow {
        stamp: Stamp::new(d.stamp_ns, Clock::Ptp),
        sensor_pose: step.output.lidar_pose,
        points: &d.points,
    };
    let frame = ModelFrame::of_window(&window, cfg, opts.sensor_height_m);
    let boxes_now = people_at(&truth.people, d.stamp_ns);
    let people = truth_in_world(&boxes_now, l_t_w, &d.points, Some(&truth.returns));
    let index = (arrays.windows.len() / 2) as f32;
    let labels: Vec<u16> = d.points.iter().map(|p| person_label(p, &people, &frame)).collect();
    if let Some(det) = arrays.surveyor.as_mut() {
        let labelled: Vec<LabelledPerson<'_>> =
            people.iter().zip(&boxes_now).map(|(t, b)| LabelledPerson { truth: t, posture: posture(b.pose) }).collect();
        survey_window(det, &window, &labels, &labelled, index as usize, &mut arrays.clusters);
    }
    let first = arrays.labels.len() as i64;
    if opts.points {
        for (p, &label) in d.points.iter().zip(&labels) {
            let m = frame.point_to_model(p);
            if kept(m) {
                arrays.points_cm.extend(m.map(|v| (v * 100.0).round() as i16));
                arrays.labels.push(label);
            }
        }
    }
    arrays.windows.extend([first, arrays.labels.len() as i64 - first]);
    for (person, truth_box) in people.iter().zip(&boxes_now) {
        let [x, y, z] = frame.to_model(person.centre_m.x, person.centre_m.y, person.centre_m.z);
        let yaw = person.yaw_rad - frame.yaw_rad();
        let s = person.size_m;
        let class = truth_box.pose.class_index() as f64;
        let row = [f64::from(index), x, y, z, s.x, s.y, s.z, yaw, class, person.returns as f64];
        arrays.boxes.extend(row.map(|v| v as f32));
        arrays.visible += usize::from(person.returns >= MatchRule::default().min_returns);
    }
}

fn kept(m: [f32; 3]) -> bool {
    (KEEP_X_M.0..KEEP_X_M.1).contains(&m[0]) && m[1].abs() < KEEP_ABS_Y_M && (KEEP_Z_M.0..KEEP_Z_M.1).contains(&m[2])
}

/// The label of the person whose box holds the point (above the floor), else 0.
fn person_label(p: &WindowPoint, people: &[TruthPerson], frame: &ModelFrame) -> u16 {
    let xyz = p.xyz();
    if frame.floor().height(xyz.x, xyz.y, xyz.z) < PERSON_MIN_HEIGHT_M {
        return 0;
    }
    people.iter().find(|t| t.contains(&xyz, PERSON_MARGIN_M)).map_or(0, |t| t.label)
}

/// The trees' posture column: 1 standing, 2 sitting or crouching, 3 lying.
fn posture(pose: TruePose) -> u8 {
    match pose {
        TruePose::Standing => 1,
        TruePose::Sitting | TruePose::Crouching => 2,
        TruePose::Lying => 3,
    }
}

fn write_arrays(a: &Arrays, opts: &ExportOptions, out: &Path) -> Result<Exported> {
    std::fs::create_dir_all(out).map_err(|source| EvalError::Write { path: out.to_path_buf(), source })?;
    let n = a.labels.len();
    let windows = a.windows.len() / 2;
    let boxes = a.boxes.len() / 10;
    if opts.points {
        write(&out.join("points.npy"), npy("<i2", &[n, 3], &le_bytes(&a.points_cm, i16::to_le_bytes)))?;
        write(&out.join("labels.npy"), npy("<u2", &[n], &le_bytes(&a.labels, u16::to_le_bytes)))?;
        write(&out.join("windows.npy"), npy("<i8", &[windows, 2], &le_bytes(&a.windows, i64::to_le_bytes)))?;
        write(&out.join("boxes.npy"), npy("<f4", &[boxes, 10], &le_bytes(&a.boxes, f32::to_le_bytes)))?;
    }
    let clusters = a.clusters.len() / COLUMNS;
    if opts.clusters {
        let table = npy("<f4", &[clusters, COLUMNS], &le_bytes(&a.clusters, f32::to_le_bytes));
        write(&out.join("clusters.npy"), table)?;
    }
    Ok(Exported { windows, points: n, boxes, visible_boxes: a.visible, clusters })
}
