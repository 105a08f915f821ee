//! `starc mission SIM_DIR [--out DIR] [--frames-every N]`: the see-through mission, offline, on
//! the output of a `starc sim` run, in one process, in time order, through the same robot and rig
//! cores the live nodes run (`starc_pipeline::mission`):
//!
//! - robot: its Avia's packets from the pcap into the LIO; after every scan, the last three,
//!   placed in the robot's world by the LIO, go to the person detector;
//! - rig: its own LIO; its scans over a window aligned to the robot's map with NDT + ICP and yaw
//!   reseeding, then re-registered every few seconds; the world pose composed from the alignment
//!   and the rig's odometry, corrected in bounded steps;
//! - each camera frame: the latest detections' person points projected through the rig's world
//!   pose into the camera, scored against the simulator's see-through mask (the paper's inlier
//!   ratio), and rendered as the responder's AR frame;
//!
//! and writes `report.json` (stable keys, see docs/mission.md), `frames.csv`, the AR frames and
//! both LIO trajectories. No link and no nodes in this path: latencies are compute times.

use super::lio::peak_rss_mib;
use super::mission_input::{self, Input, Side};
use anyhow::{bail, Context};
use nalgebra::Isometry3;
use starc_eval::{quantiles, summary, LatencyReport, MemoryReport, Scorer, Truth};
use starc_hil::sim::truth::tum_line;
use starc_pipeline::ar::{CameraModel, RenderConfig};
use starc_pipeline::mission::{
    render_view, AlignVerdict, Overlay, RigCore, RigCoreConfig, RobotCore, RobotCoreConfig, RobotStep,
};
use std::io::Write as _;
use std::net::Ipv4Addr;
use std::path::Path;
use std::path::PathBuf;
use std::time::Instant;

pub const ROBOT_AVIA: Ipv4Addr = Ipv4Addr::new(192, 168, 1, 101);
pub const FPV_AVIA: Ipv4Addr = Ipv4Addr::new(192, 168, 2, 102);
/// Detections stay on screen this long after the robot last saw them (then expire).
pub const HOLD_NS: u64 = 1_000_000_000;

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
    /// Draw a walker only from this height above the floor up (the robot core's
    /// `walker_min_height_m`, 0.8 by default; 0 draws their legs too).
    #[arg(long)]
    pub walker_min_height_m: Option<f64>,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let truth = Truth::load(&args.dir)?;
    let inputs = mission_input::from_capture(&args.dir.join("avia.pcap"))?;
    let run = Offline {
        out: args.out.clone().unwrap_or_else(|| args.dir.join("mission")),
        frames_every: args.frames_every,
        camera: truth.mount.camera.clone(),
        lidar_t_camera: truth.mount.lidar_t_camera,
        start: Start::FromTruth { hint_m: args.start_hint_m, hint_deg: args.start_hint_deg },
        start_gate_m: args.start_gate_m,
        robot: RobotCoreConfig {
            walker_min_height_m: args.walker_min_height_m.unwrap_or(RobotCoreConfig::default().walker_min_height_m),
            ..RobotCoreConfig::default()
        },
        truth: Some(truth),
    };
    run_offline(inputs, run)
}

/// Where the rig's first alignment is seeded.
pub enum Start {
    /// The rig's true start moved `hint_m` and turned `hint_deg` (a simulated run).
    FromTruth { hint_m: f64, hint_deg: f64 },
    /// A pose in the robot's map (fpv.toml's `expected_start`).
    At(Isometry3<f64>),
}

/// One offline run of both sides.
pub struct Offline {
    pub out: PathBuf,
    pub frames_every: u64,
    pub camera: CameraModel,
    pub lidar_t_camera: Isometry3<f64>,
    pub start: Start,
    pub start_gate_m: f64,
    /// The robot's core (its LIO, detector and the filters on what it sends).
    pub robot: RobotCoreConfig,
    /// With the simulator's truth: the camera frames rendered and scored into report.json.
    /// Without: a frame after every rig scan, and replay.json with what needs no truth.
    pub truth: Option<Truth>,
}

#[derive(serde::Serialize)]
struct ReplayReport {
    mode: &'static str,
    robot_scans: usize,
    rig_scans: usize,
    detection_windows: usize,
    people_detected: usize,
    alignment_attempts: usize,
    alignment_accepted: usize,
    first_accepted_after_s: Option<f64>,
    compute_ms: starc_eval::Quantiles,
    frames: usize,
    peak_rss_mib: Option<f64>,
    wall_s: f64,
}

pub fn run_offline(inputs: impl Iterator<Item = anyhow::Result<Input>>, run: Offline) -> anyhow::Result<()> {
    let started = Instant::now();
    let out = &run.out;
    std::fs::create_dir_all(out.join("ar")).with_context(|| format!("creating {}", out.display()))?;
    let mut score = run.truth.map(Scorer::new);
    let rig_cfg = RigCoreConfig { start_gate_m: run.start_gate_m, ..RigCoreConfig::default() };
    let mut robot = RobotCore::new(run.robot.clone())?;
    let mut rig = RigCore::new(rig_cfg)?;
    let mut overlay = Overlay::new(HOLD_NS);
    let (mut robot_tum, mut rig_tum, mut world_tum) = (Vec::new(), Vec::new(), Vec::new());
    let (mut slam_ms, mut viz_ms) = (Vec::new(), Vec::new());
    let (mut lio_ms, mut detect_ms) = (Vec::new(), Vec::new());
    let mut hint_set = false;
    if let Start::At(p) = run.start {
        rig.set_start_hint(p);
        hint_set = true;
    }
    let (mut detection_windows, mut people_detected, mut first_accept_ns) = (0usize, 0usize, None);
    let mut robot_last_ns = 0u64;
    let mut next_frame = 0usize;
    let mut frames = 0usize;
    let render_cfg = RenderConfig::default();
    let png_dir = (run.frames_every > 0).then(|| out.join("ar"));

    let (mut robot_steps, mut rig_outs) = (Vec::<RobotStep>::new(), Vec::new());
    for input in inputs {
        match input? {
            Input::Imu(Side::Robot, s) => robot.push_imu(s, &mut robot_steps),
            Input::Imu(Side::Rig, s) => rig.push_imu(s, &mut rig_outs),
            Input::Scan(Side::Robot, s) => robot.push_scan(s, &mut robot_steps),
            Input::Scan(Side::Rig, s) => rig.push_scan(s, &mut rig_outs),
        }
        for step in robot_steps.drain(..) {
            let o = &step.output;
            if let Some(sc) = score.as_mut() {
                sc.robot_pose(o.end_ns, &o.lidar_pose);
            }
            robot_last_ns = o.end_ns;
            robot_tum.push(tum_line(o.end_ns, &o.lidar_pose));
            let mut ms = o.elapsed_us as f64 * 1e-3;
            lio_ms.push(ms);
            if let Some(det) = step.detection {
                ms += det.detect_ms;
                detect_ms.push(det.detect_ms);
                detection_windows += 1;
                people_detected += det.found.len();
                if let Some(sc) = score.as_mut() {
                    sc.detection(&det);
                }
                overlay.push(det.stamp_ns, det.people);
            }
            slam_ms.push(ms);
        }
        let rig_new = !rig_outs.is_empty();
        for o in rig_outs.drain(..) {
            rig_tum.push(tum_line(o.end_ns, &o.lidar_pose));
            if let (Some(first), Some(sc)) = (rig.first_ns(), score.as_mut()) {
                // Alignment times count from the rig's first pose, however its start is seeded.
                sc.rig_started(first);
                if let (false, Start::FromTruth { hint_m, hint_deg }, Some(l_t_w)) =
                    (hint_set, &run.start, sc.lio_t_world)
                {
                    rig.set_start_hint(sc.truth.start_hint(&l_t_w, first, *hint_m, *hint_deg));
                    hint_set = true;
                }
            }
            // The robot's map as the rig would hold it from the link's tiles: its newest state.
            if rig.wants_map() && robot.map_len() != rig.map_len() {
                rig.set_map(robot.map_points());
            }
            if let Some(job) = rig.next_job(|| overlay.boxes_at(o.end_ns)) {
                let end_ns = job.end_ns;
                let outcome = job.run();
                let (world_t_lidar, ms) = outcome
                    .as_ref()
                    .map_or((Isometry3::identity(), f64::NAN), |o| (o.world_t_lidar, o.report.total_ms));
                let verdict = rig.apply(outcome);
                tracing::info!(?verdict, "rig alignment");
                let accepted = matches!(verdict, AlignVerdict::Accepted { .. });
                if accepted && first_accept_ns.is_none() {
                    first_accept_ns = Some(end_ns.saturating_sub(rig.first_ns().unwrap_or(end_ns)));
                }
                if let Some(sc) = score.as_mut() {
                    sc.alignment(end_ns, &world_t_lidar, ms, accepted);
                }
            }
            if let Ok(Some(w)) = rig.world().world_pose(o.end_ns) {
                world_tum.push(tum_line(o.end_ns, &w));
            }
        }
        match score.as_mut() {
            // The camera frames once both devices have passed their time.
            Some(sc) => {
                let horizon = robot_last_ns.min(rig.last().map_or(0, |(t, _)| t));
                while let Some(f) = sc.truth.frames.get(next_frame).filter(|f| f.t_ns <= horizon).cloned() {
                    next_frame += 1;
                    rig.world_mut().step_frame();
                    let t0 = Instant::now();
                    let view =
                        render_view(&run.camera, &run.lidar_t_camera, &rig, &overlay, f.t_ns, "offline", &render_cfg);
                    let render_ms = t0.elapsed().as_secs_f64() * 1e3;
                    viz_ms.push(render_ms);
                    frames += 1;
                    let keep = png_dir.as_deref().filter(|_| f.index.is_multiple_of(run.frames_every.max(1)));
                    sc.frame(&f, &view, render_ms, keep)?;
                }
            }
            // A frame after every rig scan.
            None if rig_new => {
                let Some((t_ns, _)) = rig.last() else { continue };
                rig.world_mut().step_frame();
                let t0 = Instant::now();
                let view = render_view(&run.camera, &run.lidar_t_camera, &rig, &overlay, t_ns, "replay", &render_cfg);
                viz_ms.push(t0.elapsed().as_secs_f64() * 1e3);
                if let Some(dir) =
                    png_dir.as_deref().filter(|_| frames.is_multiple_of(run.frames_every.max(1) as usize))
                {
                    std::fs::write(dir.join(format!("{frames:06}.png")), view.frame.to_png()?)?;
                }
                frames += 1;
            }
            None => {}
        }
    }
    if robot_tum.is_empty() || rig.last().is_none() {
        bail!(
            "the LIO produced no poses for {} (did both devices stand still at the start?)",
            if robot_tum.is_empty() { "the robot" } else { "the rig" }
        );
    }
    write_tum(out, "robot.tum", &robot_tum)?;
    write_tum(out, "rig.tum", &rig_tum)?;
    write_tum(out, "rig_world.tum", &world_tum)?;
    let viz_p50 = quantiles(&viz_ms).p50;
    let (lq, dq) = (quantiles(&lio_ms), quantiles(&detect_ms));
    tracing::info!(
        lio_p50_ms = lq.p50,
        lio_p99_ms = lq.p99,
        detect_p50_ms = dq.p50,
        detect_p99_ms = dq.p99,
        "robot: L_SLAM's parts"
    );
    let total: Vec<f64> = slam_ms.iter().map(|s| s + viz_p50).collect();
    let mut stdout = std::io::stdout().lock();
    if let Some(sc) = score {
        let latency = LatencyReport::from_parts(&slam_ms, &[], &viz_ms, &total);
        let memory = MemoryReport { peak_rss_mib: peak_rss_mib(), note: None };
        let report = sc.finish("offline", latency, &total, memory, started.elapsed().as_secs_f64(), out)?;
        write!(stdout, "{}", summary(&report))?;
        writeln!(
            stdout,
            "  wrote {} (report.json, frames.csv, ar/, plots/, robot.tum, rig.tum, rig_world.tum)",
            out.display()
        )?;
    } else {
        let r = ReplayReport {
            mode: "replay",
            robot_scans: robot_tum.len(),
            rig_scans: rig_tum.len(),
            detection_windows,
            people_detected,
            alignment_attempts: rig.attempts,
            alignment_accepted: rig.accepted,
            first_accepted_after_s: first_accept_ns.map(|ns| ns as f64 * 1e-9),
            compute_ms: quantiles(&total),
            frames,
            peak_rss_mib: peak_rss_mib(),
            wall_s: started.elapsed().as_secs_f64(),
        };
        std::fs::write(out.join("replay.json"), serde_json::to_string_pretty(&r)? + "\n")?;
        writeln!(
            stdout,
            "replay: robot {} scans, {} detection windows ({} people); rig {} scans, {} of {} alignments accepted{}; {} AR frames",
            r.robot_scans,
            r.detection_windows,
            r.people_detected,
            r.rig_scans,
            r.alignment_accepted,
            r.alignment_attempts,
            r.first_accepted_after_s.map_or(String::new(), |t| format!(" (first {t:.1} s after the rig started)")),
            r.frames
        )?;
        writeln!(stdout, "  wrote {} (replay.json, ar/, robot.tum, rig.tum, rig_world.tum)", out.display())?;
    }
    Ok(())
}

fn write_tum(out: &Path, name: &str, lines: &[String]) -> anyhow::Result<()> {
    let path = out.join(name);
    std::fs::write(&path, lines.join("\n") + "\n").with_context(|| format!("writing {}", path.display()))
}
