//! `starc mission SIM_DIR [--out DIR] [--frames-every N]`: the see-through mission, offline, on
//! the output of a `starc sim` run, in one process, in time order:
//!
//! - robot: its Avia's packets from the pcap into the LIO; every 0.5 s the last five scans, placed
//!   in the robot's world by the LIO, go to the person detector;
//! - rig: its own LIO; its scans over a window aligned to the robot's map (floor and ceiling bands
//!   removed) with NDT + ICP and yaw reseeding, then re-registered every few seconds; the world
//!   pose composed from the alignment and the rig's odometry, corrected in bounded steps;
//! - each camera frame: the latest detections' person points projected through the rig's world
//!   pose into the camera, scored against the simulator's see-through mask (the paper's inlier
//!   ratio), and rendered as the responder's AR frame;
//!
//! and writes `report.json` (stable keys, see docs/mission.md), `frames.csv`, the AR frames and
//! both LIO trajectories. The link and the nodes are not in this path: latencies are compute
//! times.

use super::lio::peak_rss_mib;
use super::lio_input::{internal_imu, lio_scan};
use super::mission_truth::{self as truth, CameraFrame, PersonBox, Trajectory};
use anyhow::{bail, Context};
use nalgebra::{Isometry3, Point3, UnitQuaternion, Vector3};
use serde::Serialize;
use starc_hil::sim::truth::tum_line;
use starc_livox::capture;
use starc_livox::data::DataPacket;
use starc_livox::scan::{ScanAssembler, ScanConfig};
use starc_pipeline::align::{pose_error, voxel_downsample, AlignConfig, Aligner};
use starc_pipeline::ar::{self, ArPerson, ArStatus, CameraModel, OrientedBox, ProjectedPoint, RenderConfig};
use starc_pipeline::detect::eval::{match_window, Counts, MatchRule, TruthPerson};
use starc_pipeline::detect::{to_world, DetectConfig, DetectWindow, Detector, GeometricDetector, WindowPoint};
use starc_pipeline::lio::{Lio, LioConfig, LioScan, ScanOutput};
use starc_pipeline::pose::{PoseBuffer, WorldPose, WorldPoseConfig};
use starc_time::{Clock, Stamp};
use std::collections::{HashMap, VecDeque};
use std::io::Write as _;
use std::net::Ipv4Addr;
use std::path::PathBuf;
use std::time::Instant;

const ROBOT_AVIA: Ipv4Addr = Ipv4Addr::new(192, 168, 1, 101);
const FPV_AVIA: Ipv4Addr = Ipv4Addr::new(192, 168, 2, 102);
/// Scans per detection window (0.3 s at 10 Hz); the detector runs after every robot scan.
const DETECT_SCANS: usize = 3;
/// The robot's map for alignment keeps one point per voxel of this size.
const MAP_VOXEL_M: f64 = 0.1;
/// The rig's first alignment waits for this much of its own map; later ones use this window.
const FIRST_WINDOW_NS: u64 = 3_000_000_000;
/// Until the first alignment, each retry uses all of the rig's scans so far, up to this long:
/// a longer window sees more of the building and aliases less.
const MAX_FIRST_WINDOW_NS: u64 = 10_000_000_000;
/// Only the points of a detection fired this close to its stamp are drawn: older ones of a
/// walking person trail behind them.
const FRESH_POINTS_NS: u64 = 100_000_000;
const TRACK_WINDOW_NS: u64 = 3_000_000_000;
/// A re-registration (drift correction) must be at least this well conditioned: a borderline
/// one (a corridor's axis) moves a good odometry pose more than it corrects it.
const TRACK_MIN_DEGENERACY: f64 = 0.02;
/// Detections stay on screen this long after the robot last saw them (then expire).
const HOLD_NS: u64 = 1_000_000_000;
const RETRY_NS: u64 = 1_000_000_000;
const REREGISTER_NS: u64 = 5_000_000_000;

#[derive(clap::Args)]
pub struct Args {
    /// The output directory of a `starc sim` run (with its camera masks: no --no-camera).
    pub dir: PathBuf,
    /// Where to write the report, frames and trajectories (default: DIR/mission).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Write every Nth AR frame as PNG (0: none).
    #[arg(long, default_value_t = 5)]
    pub frames_every: u64,
    /// How well the responder's start is known (as from a marked entry point or a hand-off next
    /// to the robot): the first alignment is seeded this far off the rig's true start, in metres
    /// and degrees; the yaw grid searches around it, and a result farther than `--start-gate-m`
    /// from it is refused.
    #[arg(long, default_value_t = 1.0)]
    pub start_hint_m: f64,
    #[arg(long, default_value_t = 20.0)]
    pub start_hint_deg: f64,
    #[arg(long, default_value_t = 2.0)]
    pub start_gate_m: f64,
}

/// One device's LIO and the raw scans waiting for their output.
struct Side {
    assembler: ScanAssembler,
    lio: Lio,
    pending: VecDeque<LioScan>,
    last: Option<(u64, Isometry3<f64>)>,
    tum: Vec<String>,
    slam_ms: Vec<f64>,
}

impl Side {
    fn new() -> anyhow::Result<Self> {
        Ok(Self {
            assembler: ScanAssembler::new(ScanConfig::default()).map_err(|e| anyhow::anyhow!("{e}"))?,
            lio: Lio::new(LioConfig::default()),
            pending: VecDeque::new(),
            last: None,
            tum: Vec::new(),
            slam_ms: Vec::new(),
        })
    }

    /// The raw scan of an output, its points placed by the poses at its start and end.
    fn place(&mut self, o: &ScanOutput) -> Vec<WindowPoint> {
        while self.pending.front().is_some_and(|s| s.end_ns < o.end_ns) {
            self.pending.pop_front();
        }
        let prev = self.last.map_or(o.lidar_pose, |(_, p)| p);
        self.last = Some((o.end_ns, o.lidar_pose));
        self.tum.push(tum_line(o.end_ns, &o.lidar_pose));
        self.slam_ms.push(o.elapsed_us as f64 * 1e-3);
        let Some(raw) = self.pending.pop_front().filter(|s| s.end_ns == o.end_ns) else { return Vec::new() };
        let span = raw.end_ns.saturating_sub(raw.start_ns).max(1) as f64;
        let pose_at = |t_ns: u64| {
            let f = t_ns.saturating_sub(raw.start_ns) as f64 / span;
            prev.lerp_slerp(&o.lidar_pose, f.clamp(0.0, 1.0))
        };
        let sensor = raw
            .points
            .iter()
            .filter(|p| p.x_m * p.x_m + p.y_m * p.y_m + p.z_m * p.z_m > 0.25)
            .map(|p| ([p.x_m, p.y_m, p.z_m], p.t_ns));
        let mut placed = Vec::with_capacity(raw.points.len());
        to_world(sensor, pose_at, &mut placed);
        placed
    }
}

/// The latest detections, as the rig draws them.
struct Shown {
    stamp_ns: u64,
    people: Vec<ArPerson>,
}

#[derive(Default, Serialize)]
struct Quantiles {
    p50: f64,
    p99: f64,
    max: f64,
    n: usize,
}

fn quantiles(v: &[f64]) -> Quantiles {
    let mut s: Vec<f64> = v.iter().copied().filter(|x| x.is_finite()).collect();
    s.sort_by(f64::total_cmp);
    let q = |f: f64| s.get(((s.len().saturating_sub(1)) as f64 * f).round() as usize).copied().unwrap_or(f64::NAN);
    Quantiles { p50: q(0.5), p99: q(0.99), max: q(1.0), n: s.len() }
}

#[derive(Serialize)]
struct Report {
    scenario: String,
    /// What ran: "offline" (one process, no link, no nodes).
    mode: &'static str,
    duration_s: f64,
    inlier_ratio: InlierReport,
    detection: DetectionReport,
    alignment: AlignmentReport,
    rig_pose_error: PoseErrorReport,
    latency_ms: LatencyReport,
    memory: MemoryReport,
    wall_s: f64,
}

#[derive(Serialize)]
struct InlierReport {
    /// Projected person points inside the see-through mask over all projected points in the image,
    /// pooled over every frame that showed detections.
    pooled: f64,
    points_in_mask: usize,
    /// The same, projected through the true camera pose (separates detection from pose error).
    pooled_true_pose: f64,
    points_in_image: usize,
    frames_scored: usize,
    per_frame: Quantiles,
}

#[derive(Serialize)]
struct DetectionReport {
    precision: f64,
    recall: f64,
    true_positives: usize,
    false_positives: usize,
    misses: usize,
    windows: usize,
}

#[derive(Serialize)]
struct AlignmentReport {
    /// Time of the first accepted alignment after the rig's LIO started (s); null if none.
    first_accepted_after_s: Option<f64>,
    attempts: usize,
    accepted: usize,
    time_ms: Quantiles,
    /// The first accepted alignment's error against the truth.
    first_error_m: Option<f64>,
    first_error_deg: Option<f64>,
}

#[derive(Serialize)]
struct PoseErrorReport {
    translation_m: Quantiles,
    rotation_deg: Quantiles,
}

#[derive(Serialize)]
struct LatencyReport {
    /// LIO per robot scan plus the detection of its window (when it ran).
    slam_p50: f64,
    slam_p99: f64,
    /// The link: not in the offline path (0).
    comm_p50: f64,
    comm_p99: f64,
    /// Projection and rendering of one AR frame.
    viz_p50: f64,
    viz_p99: f64,
    total_p50: f64,
    total_p99: f64,
}

#[derive(Serialize)]
struct MemoryReport {
    /// The whole process (both LIOs, the detector, the aligner): peak resident MiB.
    peak_rss_mib: Option<f64>,
}

fn yaw_of(q: &UnitQuaternion<f64>) -> f64 {
    q.euler_angles().2
}

/// The true people in the LIO world, with the window's returns inside each box.
fn truth_in_world(people: &[PersonBox], lio_t_world: &Isometry3<f64>, points: &[WindowPoint]) -> Vec<TruthPerson> {
    let yaw = yaw_of(&lio_t_world.rotation);
    people
        .iter()
        .map(|p| {
            let centre = (lio_t_world * Point3::from(p.centre_m)).coords;
            let yaw_rad = p.yaw_rad + yaw;
            let (s, c) = yaw_rad.sin_cos();
            let returns = points
                .iter()
                .filter(|q| {
                    let d = q.xyz() - centre;
                    let local = [c * d.x + s * d.y, -s * d.x + c * d.y, d.z];
                    (0..3).all(|i| local[i].abs() <= p.size_m[i] / 2.0 + 0.1)
                })
                .count();
            TruthPerson { label: p.label, centre_m: centre, size_m: p.size_m, yaw_rad, returns }
        })
        .collect()
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let started = Instant::now();
    let dir = &args.dir;
    let out = args.out.clone().unwrap_or_else(|| dir.join("mission"));
    std::fs::create_dir_all(out.join("ar")).with_context(|| format!("creating {}", out.display()))?;
    let gt_robot = truth::read_tum(&dir.join("gt_robot.tum"))?;
    let gt_fpv = truth::read_tum(&dir.join("gt_fpv.tum"))?;
    let people = truth::read_people(&dir.join("people.csv"))?;
    let frames = truth::read_frames(&dir.join("camera/frames.csv"))
        .context("the mission scores camera frames: run `starc sim` without --no-camera")?;
    let mount = truth::read_camera(&dir.join("extrinsics.json"))?;
    let scenario = std::fs::read_to_string(dir.join("scenario.toml"))
        .ok()
        .and_then(|t| t.lines().find_map(|l| l.strip_prefix("name = ").map(|n| n.trim_matches('"').to_string())))
        .unwrap_or_default();
    let camera = mount.camera.clone();

    let mut robot = Side::new()?;
    let mut fpv = Side::new()?;
    let mut detector = GeometricDetector::new(DetectConfig::default())?;
    let mut window: VecDeque<Vec<WindowPoint>> = VecDeque::new();
    let mut map: HashMap<(i32, i32, i32), Vector3<f64>> = HashMap::new();
    let mut lio_t_world: Option<Isometry3<f64>> = None;
    let mut shown: VecDeque<Shown> = VecDeque::new();
    let mut counts = Counts::default();
    let mut windows = 0usize;
    let mut detect_ms_by_scan: Vec<(usize, f64)> = Vec::new();

    let mut world = WorldPose::new(WorldPoseConfig::default());
    let mut odom = PoseBuffer::new(100_000);
    let mut rig_scans: VecDeque<LioScan> = VecDeque::new();
    let mut rig_points: Vec<Vector3<f64>> = Vec::new();
    let mut rig_first_ns: Option<u64> = None;
    let mut start_hint = Isometry3::identity();
    let mut start_hint_at: Option<u64> = None;
    let mut next_align_ns = 0u64;
    let (mut attempts, mut accepted) = (0usize, 0usize);
    let mut align_ms = Vec::new();
    let mut first_accept: Option<(u64, f64, f64)> = None;
    let align_cfg = AlignConfig::default();
    // Re-registration starts from the current world pose: one attempt, no seed search, no NDT
    // levels coarser than a room.
    let track_cfg = AlignConfig {
        min_degeneracy_index: TRACK_MIN_DEGENERACY,
        reseed_yaw_step_deg: 0.0,
        ndt_resolutions_m: vec![2.0, 1.0],
        seed_levels: 1,
        ..AlignConfig::default()
    };

    let mut next_frame = 0usize;
    let (mut in_mask, mut in_image) = (0usize, 0usize);
    let (mut true_in_mask, mut true_in_image) = (0usize, 0usize);
    let mut per_frame_ratio = Vec::new();
    let (mut err_m, mut err_deg) = (Vec::new(), Vec::new());
    let mut viz_ms = Vec::new();
    let (mut err_series, mut inlier_series) = (Vec::new(), Vec::new());
    let mut frame_rows = vec![
        "frame,time_s,aligned,detections,age_ms,points_in_image,points_in_mask,pose_error_m,pose_error_deg,render_ms"
            .to_string(),
    ];
    let mut projected: Vec<ProjectedPoint> = Vec::new();
    let render_cfg = RenderConfig::default();

    let mut outs = Vec::new();
    let cap = capture::open(&dir.join("avia.pcap"))
        .with_context(|| format!("opening {}", dir.join("avia.pcap").display()))?;
    for item in cap {
        let d = item?;
        let Some(src) = d.src else { continue };
        let is_robot = *src.ip() == ROBOT_AVIA;
        if !is_robot && *src.ip() != FPV_AVIA {
            continue;
        }
        let Ok(packet) = DataPacket::parse(&d.payload) else { continue };
        let side = if is_robot { &mut robot } else { &mut fpv };
        if let Some(s) = internal_imu(&packet) {
            side.lio.push_imu(s, &mut outs);
        } else if !packet.is_imu() {
            let mut done = Vec::new();
            side.assembler.push(&packet, None, &mut done);
            for scan in done {
                let scan = lio_scan(&scan);
                side.pending.push_back(scan.clone());
                if !is_robot {
                    rig_scans.push_back(scan.clone());
                }
                side.lio.push_scan(scan, &mut outs);
            }
        }
        for o in outs.drain(..) {
            if is_robot {
                let placed = robot.place(&o);
                lio_t_world.get_or_insert_with(|| o.lidar_pose * truth::at(&gt_robot, o.end_ns).inverse());
                window.push_back(placed);
                if window.len() > DETECT_SCANS {
                    window.pop_front();
                }
                for p in window.back().into_iter().flatten() {
                    let v = p.xyz() / MAP_VOXEL_M;
                    map.entry((v.x.floor() as i32, v.y.floor() as i32, v.z.floor() as i32)).or_insert(p.xyz());
                }
                if window.len() == DETECT_SCANS {
                    let points: Vec<WindowPoint> = window.iter().flatten().copied().collect();
                    let t0 = Instant::now();
                    let w = DetectWindow {
                        stamp: Stamp::new(o.end_ns, Clock::Ptp),
                        sensor_pose: o.lidar_pose,
                        points: &points,
                    };
                    let mut found = Vec::new();
                    detector.detect(&w, &mut found);
                    detect_ms_by_scan.push((robot.slam_ms.len() - 1, t0.elapsed().as_secs_f64() * 1e3));
                    if let Some(l_t_w) = &lio_t_world {
                        let truth_people = truth_in_world(&truth::people_at(&people, o.end_ns), l_t_w, &points);
                        counts.add(&match_window(&found, &truth_people, &MatchRule::default()).counts);
                        windows += 1;
                    }
                    let people_shown = found
                        .iter()
                        .map(|det| ArPerson {
                            points_world: det
                                .point_indices
                                .iter()
                                .filter_map(|&i| points.get(i as usize))
                                .filter(|p| p.t_ns + FRESH_POINTS_NS >= o.end_ns)
                                .map(WindowPoint::xyz)
                                .collect(),
                            bbox: Some(OrientedBox {
                                centre_m: det.centre_m,
                                size_m: det.size_m,
                                yaw_rad: det.yaw_rad,
                            }),
                            age_ns: 0,
                        })
                        .collect();
                    shown.push_back(Shown { stamp_ns: o.end_ns, people: people_shown });
                    while shown.front().is_some_and(|s| s.stamp_ns + HOLD_NS < o.end_ns) {
                        shown.pop_front();
                    }
                }
            } else {
                let placed = fpv.place(&o);
                rig_points = placed.iter().map(WindowPoint::xyz).collect();
                let _ = world.push_odometry(o.end_ns, o.lidar_pose);
                let _ = odom.push(o.end_ns, o.lidar_pose);
                let first = *rig_first_ns.get_or_insert(o.end_ns);
                if start_hint_at != Some(first) {
                    // Where the responder is expected: the true start, off by the hint's error.
                    if let Some(l_t_w) = &lio_t_world {
                        let h = args.start_hint_m;
                        let off = Isometry3::from_parts(
                            nalgebra::Translation3::new(0.8 * h, -0.6 * h, 0.0),
                            UnitQuaternion::from_euler_angles(0.0, 0.0, args.start_hint_deg.to_radians()),
                        );
                        start_hint = l_t_w * truth::at(&gt_fpv, first) * off;
                        start_hint_at = Some(first);
                    }
                }
                while rig_scans.front().is_some_and(|s| s.end_ns + MAX_FIRST_WINDOW_NS < o.end_ns) {
                    rig_scans.pop_front();
                }
                let aligned = world.correction().is_some();
                let w_ns = if aligned { TRACK_WINDOW_NS } else { FIRST_WINDOW_NS };
                let window_ns = if aligned { w_ns } else { (o.end_ns - first).min(MAX_FIRST_WINDOW_NS) };
                if o.end_ns >= first + w_ns && o.end_ns >= next_align_ns && map.len() > 1000 {
                    // The window in a gravity-aligned frame at the rig; both sides reduced to 10 cm
                    // voxels. (Preparing both with `prepare_map`, floor and ceiling thinned, placed
                    // the auditorium's rig 68 cm off and accepted it; reduced alike, it refuses.)
                    let (src_raw, frame) = rig_window(&rig_scans, &odom, o.end_ns, window_ns);
                    let src = voxel_downsample(&src_raw, MAP_VOXEL_M);
                    let target: Vec<Vector3<f64>> = map.values().copied().collect();
                    let cfg = if aligned { track_cfg.clone() } else { align_cfg.clone() };
                    let report = Aligner::new(&target, cfg).map(|aligner| {
                        // Without a world pose the responder is taken to start near the robot:
                        // seed at the robot's position; the yaw grid does the rest.
                        let guess_fpv = world.world_pose(o.end_ns).ok().flatten().unwrap_or(start_hint);
                        let r = aligner.align(&src, &(guess_fpv * o.lidar_pose.inverse() * frame));
                        // The registered frame back to the rig's LiDAR pose in the world.
                        let w_t_fpv = r.pose * frame.inverse() * o.lidar_pose;
                        (r, w_t_fpv)
                    });
                    attempts += 1;
                    next_align_ns = o.end_ns + if aligned { REREGISTER_NS } else { RETRY_NS };
                    match report {
                        Ok((r, w_t_fpv)) => {
                            align_ms.push(r.total_ms);
                            // Re-registrations are held to their own, stricter acceptance (track_cfg);
                            // the first alignment must also land near the expected start.
                            let off = (w_t_fpv.translation.vector - start_hint.translation.vector).norm();
                            let near_start = aligned || off <= args.start_gate_m;
                            if r.accepted && !near_start {
                                tracing::info!(off_m = off, "rig alignment refused: too far from the expected start");
                            }
                            if r.accepted && near_start {
                                accepted += 1;
                                if let (Some(l_t_w), Some(best)) = (&lio_t_world, r.best()) {
                                    let (m, deg) = pose_error(&w_t_fpv, &(l_t_w * truth::at(&gt_fpv, o.end_ns)));
                                    tracing::info!(
                                        t_s = (o.end_ns - first) as f64 * 1e-9,
                                        error_m = m,
                                        error_deg = deg,
                                        degeneracy = best.metrics.degeneracy_index,
                                        inliers = best.metrics.inlier_ratio,
                                        rms_m = best.metrics.rms_residual_m,
                                        "rig alignment accepted"
                                    );
                                }
                                let _ = world.push_registration(o.end_ns, w_t_fpv);
                                if first_accept.is_none() {
                                    if let Some(l_t_w) = &lio_t_world {
                                        let truth_pose = l_t_w * truth::at(&gt_fpv, o.end_ns);
                                        let (m, deg) = pose_error(&w_t_fpv, &truth_pose);
                                        first_accept = Some((o.end_ns - first, m, deg));
                                    }
                                }
                            } else {
                                tracing::info!(failure = ?r.failure, "rig alignment rejected");
                            }
                        }
                        Err(e) => tracing::warn!("rig alignment could not run: {e}"),
                    }
                }
            }
        }
        // Frames once both devices have passed their time.
        let horizon = robot.last.map_or(0, |(t, _)| t).min(fpv.last.map_or(0, |(t, _)| t));
        while let Some(f) = frames.get(next_frame).filter(|f| f.t_ns <= horizon) {
            next_frame += 1;
            world.step_frame();
            let row = render_frame(
                f,
                &args,
                &out,
                &camera,
                &mount.lidar_t_camera,
                &world,
                &rig_points,
                &shown,
                lio_t_world.as_ref(),
                &gt_fpv,
                &render_cfg,
                dir,
                &mut projected,
            )?;
            let t_s = f.t_ns.saturating_sub(frames.first().map_or(0, |f| f.t_ns)) as f64 * 1e-9;
            if let Some((m, deg)) = row.pose_error {
                err_m.push(m);
                err_deg.push(deg);
                err_series.push((t_s, m * 100.0));
            }
            if row.in_image > 0 {
                inlier_series.push((t_s, 100.0 * row.in_mask as f64 / row.in_image as f64));
            }
            true_in_mask += row.true_pose.0;
            true_in_image += row.true_pose.1;
            if row.in_image > 0 {
                in_mask += row.in_mask;
                in_image += row.in_image;
                per_frame_ratio.push(row.in_mask as f64 / row.in_image as f64);
            }
            viz_ms.push(row.render_ms);
            frame_rows.push(row.csv);
        }
    }
    if robot.last.is_none() || fpv.last.is_none() {
        bail!(
            "{}: the LIO produced no poses for {} (did both devices stand still at power-on?)",
            dir.display(),
            if robot.last.is_none() { "the robot" } else { "the rig" }
        );
    }

    // Latency per robot scan: its LIO time plus the detection that ran on it.
    let mut slam = robot.slam_ms.clone();
    for (i, ms) in &detect_ms_by_scan {
        if let Some(s) = slam.get_mut(*i) {
            *s += ms;
        }
    }
    let (sq, vq) = (quantiles(&slam), quantiles(&viz_ms));
    let total: Vec<f64> = slam.iter().map(|s| s + vq.p50).collect();
    let tq = quantiles(&total);
    let report = Report {
        scenario,
        mode: "offline",
        duration_s: gt_robot.last().map_or(0.0, |(t, _)| (t - gt_robot[0].0) as f64 * 1e-9),
        inlier_ratio: InlierReport {
            pooled: if in_image > 0 { in_mask as f64 / in_image as f64 } else { f64::NAN },
            points_in_mask: in_mask,
            pooled_true_pose: if true_in_image > 0 { true_in_mask as f64 / true_in_image as f64 } else { f64::NAN },
            points_in_image: in_image,
            frames_scored: per_frame_ratio.len(),
            per_frame: quantiles(&per_frame_ratio),
        },
        detection: DetectionReport {
            precision: counts.precision(),
            recall: counts.recall(),
            true_positives: counts.true_positives,
            false_positives: counts.false_positives,
            misses: counts.misses,
            windows,
        },
        alignment: AlignmentReport {
            first_accepted_after_s: first_accept.map(|(dt, _, _)| dt as f64 * 1e-9),
            attempts,
            accepted,
            time_ms: quantiles(&align_ms),
            first_error_m: first_accept.map(|(_, m, _)| m),
            first_error_deg: first_accept.map(|(_, _, d)| d),
        },
        rig_pose_error: PoseErrorReport { translation_m: quantiles(&err_m), rotation_deg: quantiles(&err_deg) },
        latency_ms: LatencyReport {
            slam_p50: sq.p50,
            slam_p99: sq.p99,
            comm_p50: 0.0,
            comm_p99: 0.0,
            viz_p50: vq.p50,
            viz_p99: vq.p99,
            total_p50: tq.p50,
            total_p99: tq.p99,
        },
        memory: MemoryReport { peak_rss_mib: peak_rss_mib() },
        wall_s: started.elapsed().as_secs_f64(),
    };
    let json = serde_json::to_string_pretty(&report)?;
    std::fs::write(out.join("report.json"), json + "\n")?;
    std::fs::write(out.join("frames.csv"), frame_rows.join("\n") + "\n")?;
    write_plots(&out, &err_series, &inlier_series, &total)?;
    std::fs::write(out.join("robot.tum"), robot.tum.join("\n") + "\n")?;
    std::fs::write(out.join("rig.tum"), fpv.tum.join("\n") + "\n")?;
    let mut stdout = std::io::stdout().lock();
    write!(stdout, "{}", summary(&report))?;
    writeln!(stdout, "  wrote {} (report.json, frames.csv, ar/, plots/, robot.tum, rig.tum)", out.display())?;
    Ok(())
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

fn summary(r: &Report) -> String {
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
        "  compute latency: LIO + detection {:.1} / {:.1} ms (p50 / p99), AR frame {:.1} / {:.1} ms, total {:.1} / {:.1} ms \
         (no link in this path); peak memory {:.0} MiB",
        l.slam_p50,
        l.slam_p99,
        l.viz_p50,
        l.viz_p99,
        l.total_p50,
        l.total_p99,
        r.memory.peak_rss_mib.unwrap_or(f64::NAN)
    );
    o
}

/// The rig's scans over `[end - window, end]`, in the frame at the rig's position at `end` with
/// the odometry's (gravity-aligned) axes; returns the points and that frame (in odometry).
fn rig_window(
    scans: &VecDeque<LioScan>,
    odom: &PoseBuffer,
    end_ns: u64,
    window_ns: u64,
) -> (Vec<Vector3<f64>>, Isometry3<f64>) {
    let Ok(at_end) = odom.at(end_ns) else { return (Vec::new(), Isometry3::identity()) };
    let frame = Isometry3::from_parts(at_end.translation, UnitQuaternion::identity());
    let inv = frame.inverse();
    let from = end_ns.saturating_sub(window_ns);
    let mut out = Vec::new();
    for s in scans.iter().filter(|s| s.end_ns >= from && s.start_ns <= end_ns) {
        for p in s.points.iter().filter(|p| p.t_ns >= from && p.t_ns <= end_ns) {
            let Ok(pose) = odom.at(p.t_ns) else { continue };
            let q = inv * pose * Point3::new(f64::from(p.x_m), f64::from(p.y_m), f64::from(p.z_m));
            if p.x_m * p.x_m + p.y_m * p.y_m + p.z_m * p.z_m > 0.25 {
                out.push(q.coords);
            }
        }
    }
    (out, frame)
}

/// What the rig shows at `t_ns`: every person seen in the last `HOLD_NS` up to `t_ns`, each at
/// their latest sighting (a later detection within 0.7 m of an earlier one replaces it).
fn people_at(shown: &VecDeque<Shown>, t_ns: u64) -> Vec<ArPerson> {
    let mut out: Vec<ArPerson> = Vec::new();
    for s in shown.iter().rev().filter(|s| s.stamp_ns <= t_ns && s.stamp_ns + HOLD_NS >= t_ns) {
        for p in &s.people {
            let Some(b) = p.bbox else { continue };
            let seen = out.iter().any(|q| q.bbox.is_some_and(|c| (c.centre_m - b.centre_m).xy().norm() < 0.7));
            if !seen {
                out.push(ArPerson { age_ns: t_ns - s.stamp_ns, ..p.clone() });
            }
        }
    }
    out
}

struct FrameRow {
    csv: String,
    in_image: usize,
    in_mask: usize,
    /// (in mask, in image) when projected through the true camera pose.
    true_pose: (usize, usize),
    pose_error: Option<(f64, f64)>,
    render_ms: f64,
}

#[allow(clippy::too_many_arguments)]
fn render_frame(
    f: &CameraFrame,
    args: &Args,
    out: &std::path::Path,
    camera: &CameraModel,
    lidar_t_camera: &Isometry3<f64>,
    world: &WorldPose,
    rig_points: &[Vector3<f64>],
    shown: &VecDeque<Shown>,
    lio_t_world: Option<&Isometry3<f64>>,
    gt_fpv: &Trajectory,
    cfg: &RenderConfig,
    dir: &std::path::Path,
    projected: &mut Vec<ProjectedPoint>,
) -> anyhow::Result<FrameRow> {
    let t0 = Instant::now();
    let rig_pose = world.world_pose(f.t_ns).ok().flatten();
    let aligned = rig_pose.is_some();
    let world_t_camera = rig_pose.map_or(Isometry3::identity(), |p| p * lidar_t_camera);
    let people = people_at(shown, f.t_ns);
    let age_ms = people.iter().map(|p| p.age_ns).min().map(|a| a as f64 * 1e-6);
    projected.clear();
    if aligned {
        ar::project_people(camera, &world_t_camera, &people, projected);
    }
    let status = ArStatus {
        aligned,
        detection_age_ms: age_ms,
        link: "offline".into(),
        text: if aligned { String::new() } else { "waiting for the first alignment".into() },
    };
    let frame = ar::render(camera, &world_t_camera, rig_points, &people, &status, cfg);
    let render_ms = t0.elapsed().as_secs_f64() * 1e3;
    if args.frames_every > 0 && f.index.is_multiple_of(args.frames_every) {
        std::fs::write(out.join(format!("ar/{:06}.png", f.index)), frame.to_png()?)?;
    }
    let (mut in_image, mut in_mask, mut true_pose) = (0, 0, (0, 0));
    if aligned && !people.is_empty() {
        let mask_path = dir.join(format!("camera/see_through/{:06}.png", f.index));
        if let Ok(bytes) = std::fs::read(&mask_path) {
            let (w, h, mask) = ar::read_mask_png(&bytes)?;
            (in_mask, in_image) = ar::mask_inlier_ratio(projected, &mask, w, h);
            // The same people through the true camera pose: what detection alone scores.
            if let Some(l_t_w) = lio_t_world {
                let mut with_truth = Vec::new();
                ar::project_people(camera, &(l_t_w * f.world_t_camera), &people, &mut with_truth);
                true_pose = ar::mask_inlier_ratio(&with_truth, &mask, w, h);
            }
        }
    }
    let pose_error = match (rig_pose, lio_t_world) {
        (Some(p), Some(l_t_w)) => Some(pose_error(&p, &(l_t_w * truth::at(gt_fpv, f.t_ns)))),
        _ => None,
    };
    let csv = format!(
        "{},{}.{:09},{},{},{},{},{},{},{},{:.3}",
        f.index,
        f.t_ns / 1_000_000_000,
        f.t_ns % 1_000_000_000,
        aligned,
        people.len(),
        age_ms.map_or(String::new(), |a| format!("{a:.1}")),
        in_image,
        in_mask,
        pose_error.map_or(String::new(), |e| format!("{:.4}", e.0)),
        pose_error.map_or(String::new(), |e| format!("{:.3}", e.1)),
        render_ms
    );
    Ok(FrameRow { csv, in_image, in_mask, true_pose, pose_error, render_ms })
}
