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
//! both LIO trajectories. No link and no nodes in this path: latencies are compute times. The
//! run itself is `starc_eval::offline` over `starc_pipeline::mission::OfflineMission`.

use starc_eval::offline::{self, Offline, Start};
use starc_eval::Truth;
use starc_hil::sim::run::{FPV_AVIA_IP, ROBOT_AVIA_IP};
use starc_pipeline::mission::{RobotCoreConfig, FLOOR_GRID_RAY_STRIDE};
use std::path::PathBuf;

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
    /// Give the rig a start hint from the simulator's truth, standing for a marked entry point
    /// or a hand-off next to the robot: the first alignment is seeded this far off the rig's
    /// true start, in metres (and `--start-hint-deg` degrees), and a result farther than
    /// `--start-gate-m` from it is refused. Such a run reads the truth: not a scored figure.
    /// Without it (the default) the responder may start anywhere the robot has mapped.
    #[arg(long)]
    pub start_hint_m: Option<f64>,
    #[arg(long, default_value_t = 20.0)]
    pub start_hint_deg: f64,
    #[arg(long, default_value_t = 2.0)]
    pub start_gate_m: f64,
    /// Apply the rig's first alignment once searches have found it again over this long (s;
    /// 0: the first accepted one at once, as before 2026-11-27).
    #[arg(long, default_value_t = starc_pipeline::mission::CONFIRM_FIRST_S)]
    pub confirm_first_s: f64,
    /// Draw a walker only from this height above the floor up (the robot core's
    /// `walker_min_height_m`, 0.8 by default; 0 draws their legs too).
    #[arg(long)]
    pub walker_min_height_m: Option<f64>,
    /// Judge the rig's alignments on its whole window instead of the part the robot's coverage
    /// can judge (to measure what coverage brings).
    #[arg(long)]
    pub no_coverage: bool,
    /// Leave the base's wheel odometry (the run's robot_can.log) out of the robot's LIO.
    #[arg(long)]
    pub no_wheels: bool,
    /// The rig's first-alignment search settings (TOML, as config/align.toml; every key
    /// optional): to measure a setting on the generated buildings.
    #[arg(long)]
    pub align_config: Option<PathBuf>,
    /// The rig's LIO settings (TOML, as config/lio.toml; every key optional).
    #[arg(long)]
    pub rig_lio_config: Option<PathBuf>,
    #[command(flatten)]
    pub detector: super::detector_arg::DetectorArgs,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let truth = Truth::load(&args.dir)?;
    let mut inputs = starc_bridge::from_capture(&args.dir.join("avia.pcap"), ROBOT_AVIA_IP, FPV_AVIA_IP)?;
    if !args.no_wheels {
        inputs = starc_bridge::wheels::with_wheels(inputs, super::sim::run_wheel_samples(&args.dir)?);
    }
    let run = Offline {
        out: args.out.clone().unwrap_or_else(|| args.dir.join("mission")),
        frames_every: args.frames_every,
        camera: truth.mount.camera.clone(),
        lidar_t_camera: truth.mount.lidar_t_camera,
        start: match args.start_hint_m {
            Some(hint_m) => Start::FromTruth { hint_m, hint_deg: args.start_hint_deg },
            None => Start::Anywhere,
        },
        start_gate_m: args.start_gate_m,
        confirm_first_s: args.confirm_first_s,
        coverage: !args.no_coverage,
        robot: RobotCoreConfig {
            walker_min_height_m: args.walker_min_height_m.unwrap_or(RobotCoreConfig::default().walker_min_height_m),
            detect: args.detector.config()?,
            floor_grid_ray_stride: FLOOR_GRID_RAY_STRIDE,
            ..RobotCoreConfig::default()
        },
        rig_align: super::align::rig_align_config(args.align_config.as_deref())?,
        rig_lio: super::lio::rig_lio_config(args.rig_lio_config.as_deref())?,
        truth: Some(truth),
        wall_timing: true,
        align: true,
    };
    print!("{}", offline::run(inputs, run)?);
    Ok(())
}
