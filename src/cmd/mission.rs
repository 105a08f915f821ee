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
use super::lio_input::{internal_imu, lio_scan};
use super::mission_score::{summary, LatencyReport, MemoryReport, Scorer, Truth};
use anyhow::{bail, Context};
use nalgebra::Isometry3;
use starc_hil::sim::truth::tum_line;
use starc_livox::capture;
use starc_livox::data::DataPacket;
use starc_livox::scan::{ScanAssembler, ScanConfig};
use starc_pipeline::ar::RenderConfig;
use starc_pipeline::mission::{
    render_view, AlignVerdict, Overlay, RigCore, RigCoreConfig, RobotCore, RobotCoreConfig, RobotStep,
};
use std::io::Write as _;
use std::net::Ipv4Addr;
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
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let started = Instant::now();
    let dir = &args.dir;
    let out = args.out.clone().unwrap_or_else(|| dir.join("mission"));
    std::fs::create_dir_all(out.join("ar")).with_context(|| format!("creating {}", out.display()))?;
    let mut score = Scorer::new(Truth::load(dir)?);
    let camera = score.truth.mount.camera.clone();
    let lidar_t_camera = score.truth.mount.lidar_t_camera;
    let rig_cfg = RigCoreConfig { start_gate_m: args.start_gate_m, ..RigCoreConfig::default() };

    let mut robot = RobotCore::new(RobotCoreConfig::default())?;
    let mut rig = RigCore::new(rig_cfg)?;
    let mut overlay = Overlay::new(HOLD_NS);
    let mut assemblers = [ScanAssembler::new(ScanConfig::default()), ScanAssembler::new(ScanConfig::default())]
        .map(|a| a.map_err(|e| anyhow::anyhow!("{e}")));
    let [Ok(robot_assembler), Ok(rig_assembler)] = &mut assemblers else { bail!("scan assembler config") };
    let (mut robot_tum, mut rig_tum) = (Vec::new(), Vec::new());
    let (mut slam_ms, mut viz_ms) = (Vec::new(), Vec::new());
    let mut hint_set = false;
    let mut robot_last_ns = 0u64;
    let mut next_frame = 0usize;
    let render_cfg = RenderConfig::default();
    let png_dir = (args.frames_every > 0).then(|| out.join("ar"));

    let (mut robot_steps, mut rig_outs) = (Vec::<RobotStep>::new(), Vec::new());
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
        if let Some(s) = internal_imu(&packet) {
            if is_robot {
                robot.push_imu(s, &mut robot_steps);
            } else {
                rig.push_imu(s, &mut rig_outs);
            }
        } else if !packet.is_imu() {
            let mut done = Vec::new();
            if is_robot { &mut *robot_assembler } else { &mut *rig_assembler }.push(&packet, None, &mut done);
            for scan in done {
                if is_robot {
                    robot.push_scan(lio_scan(&scan), &mut robot_steps);
                } else {
                    rig.push_scan(lio_scan(&scan), &mut rig_outs);
                }
            }
        }
        for step in robot_steps.drain(..) {
            let o = &step.output;
            score.robot_pose(o.end_ns, &o.lidar_pose);
            robot_last_ns = o.end_ns;
            robot_tum.push(tum_line(o.end_ns, &o.lidar_pose));
            let mut ms = o.elapsed_us as f64 * 1e-3;
            if let Some(det) = step.detection {
                ms += det.detect_ms;
                score.detection(&det);
                overlay.push(det.stamp_ns, det.people);
            }
            slam_ms.push(ms);
        }
        for o in rig_outs.drain(..) {
            rig_tum.push(tum_line(o.end_ns, &o.lidar_pose));
            if !hint_set {
                if let (Some(first), Some(l_t_w)) = (rig.first_ns(), score.lio_t_world) {
                    score.rig_started(first);
                    rig.set_start_hint(score.truth.start_hint(&l_t_w, first, args.start_hint_m, args.start_hint_deg));
                    hint_set = true;
                }
            }
            // The robot's map as the rig would hold it from the link's tiles: its newest state.
            if rig.wants_map() && robot.map_len() != rig.map_len() {
                rig.set_map(robot.map_points());
            }
            if let Some(job) = rig.next_job() {
                let end_ns = job.end_ns;
                let outcome = job.run();
                let (world_t_lidar, ms) = outcome
                    .as_ref()
                    .map_or((Isometry3::identity(), f64::NAN), |o| (o.world_t_lidar, o.report.total_ms));
                let verdict = rig.apply(outcome);
                tracing::info!(?verdict, "rig alignment");
                score.alignment(end_ns, &world_t_lidar, ms, matches!(verdict, AlignVerdict::Accepted { .. }));
            }
        }
        // Frames once both devices have passed their time.
        let horizon = robot_last_ns.min(rig.last().map_or(0, |(t, _)| t));
        while let Some(f) = score.truth.frames.get(next_frame).filter(|f| f.t_ns <= horizon).cloned() {
            next_frame += 1;
            rig.world_mut().step_frame();
            let t0 = Instant::now();
            let view = render_view(&camera, &lidar_t_camera, &rig, &overlay, f.t_ns, "offline", &render_cfg);
            let render_ms = t0.elapsed().as_secs_f64() * 1e3;
            viz_ms.push(render_ms);
            let keep = png_dir.as_deref().filter(|_| f.index.is_multiple_of(args.frames_every.max(1)));
            score.frame(&f, &view, render_ms, keep)?;
        }
    }
    if robot_tum.is_empty() || rig.last().is_none() {
        bail!(
            "{}: the LIO produced no poses for {} (did both devices stand still at power-on?)",
            dir.display(),
            if robot_tum.is_empty() { "the robot" } else { "the rig" }
        );
    }
    let viz_p50 = super::mission_score::quantiles(&viz_ms).p50;
    let total: Vec<f64> = slam_ms.iter().map(|s| s + viz_p50).collect();
    let latency = LatencyReport::from_parts(&slam_ms, &[], &viz_ms, &total);
    let memory = MemoryReport { peak_rss_mib: peak_rss_mib(), note: None };
    let report = score.finish("offline", latency, &total, memory, started.elapsed().as_secs_f64(), &out)?;
    std::fs::write(out.join("robot.tum"), robot_tum.join("\n") + "\n")?;
    std::fs::write(out.join("rig.tum"), rig_tum.join("\n") + "\n")?;
    let mut stdout = std::io::stdout().lock();
    write!(stdout, "{}", summary(&report))?;
    writeln!(stdout, "  wrote {} (report.json, frames.csv, ar/, plots/, robot.tum, rig.tum)", out.display())?;
    Ok(())
}
