//! The simulated lab for the alignment benches: runs `starc_hil::sim` (both Avias through the
//! mock device's packets), decodes the capture as a real one would be, and reads the ground truth.
#![allow(dead_code)]

use nalgebra::{Isometry3, Point3, Vector3};
use starc_hil::sim::run::{run, SimOptions, FPV_AVIA_IP, ROBOT_AVIA_IP};
use starc_hil::sim::scenario::Scenario;
use starc_livox::capture;
use starc_livox::data::DataPacket;
use starc_livox::scan::{ScanAssembler, ScanConfig};
use starc_pipeline::align::{voxel_downsample, Vec3};
use starc_pipeline::lio::{ImuSample, LioScan, TimedPoint};
use std::net::Ipv4Addr;
use std::path::{Path, PathBuf};

#[path = "../../../tests/support/tum.rs"]
mod tum;
pub use tum::{read_tum, truth_at};

/// One simulator run's outputs.
pub struct SimRun {
    pub dir: PathBuf,
    pub robot_truth: Vec<(u64, Isometry3<f64>)>,
    pub fpv_truth: Vec<(u64, Isometry3<f64>)>,
    pub robot: Decoded,
    pub fpv: Decoded,
}

/// One Avia's IMU samples and 100 ms scans (points in the LiDAR frame, per-point PTP times).
pub struct Decoded {
    pub imu: Vec<ImuSample>,
    pub scans: Vec<LioScan>,
}

/// Runs `scenario` for `duration_s` (seed 1, no camera) into a fresh directory under the temp dir.
pub fn simulate(scenario: &str, duration_s: f64, tag: &str) -> SimRun {
    let dir = std::env::temp_dir().join(format!("starc_align_{tag}_{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    // Scenarios shipped with these benches (beside this file) by name, else the simulator's.
    let local = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(format!("benches/align_sim/{scenario}.toml"));
    let name = if local.exists() { local.to_string_lossy().into_owned() } else { scenario.to_string() };
    let (sc, text) = Scenario::load(&name).unwrap();
    let opts = SimOptions { out: dir.clone(), duration_s: Some(duration_s), seed: 1, realtime: false, camera: false };
    run(&sc, &text, &opts, &mut |_, _| {}).unwrap();
    let pcap = dir.join("avia.pcap");
    SimRun {
        robot_truth: read_tum(&dir.join("gt_robot.tum")),
        fpv_truth: read_tum(&dir.join("gt_fpv.tum")),
        robot: decode(&pcap, ROBOT_AVIA_IP),
        fpv: decode(&pcap, FPV_AVIA_IP),
        dir,
    }
}

impl Drop for SimRun {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

/// The IMU samples and scans of the Avia at `avia`, decoded from the capture.
pub fn decode(pcap: &Path, avia: Ipv4Addr) -> Decoded {
    let mut assembler = ScanAssembler::new(ScanConfig::default()).unwrap();
    let mut imu = Vec::new();
    let mut done = Vec::new();
    for d in capture::open(pcap).unwrap() {
        let d = d.unwrap();
        let (Some(src), Some(dst)) = (d.src, d.dst) else { continue };
        if *src.ip() != avia || src.port() == 65000 || dst.port() == 65000 {
            continue;
        }
        let packet = DataPacket::parse(&d.payload).unwrap();
        if let Some(s) = packet.imu() {
            imu.push(ImuSample {
                t_ns: packet.header.timestamp.ns,
                gyro_rad_s: Vector3::from(s.gyro_rad_s.map(f64::from)),
                acc_m_s2: Vector3::from(s.acc_m_s2().map(f64::from)),
            });
            continue;
        }
        assembler.push(&packet, None, &mut done);
    }
    let scans = done
        .drain(..)
        .map(|s| LioScan {
            start_ns: s.start.ns,
            end_ns: s.end().ns,
            points: s
                .points
                .iter()
                .map(|p| TimedPoint { x_m: p.x_m, y_m: p.y_m, z_m: p.z_m, t_ns: s.start.ns + u64::from(p.offset_ns) })
                .collect(),
        })
        .collect();
    Decoded { imu, scans }
}

/// Points of the scans within [from_ns, to_ns], each moved by the pose `pose_at(t)` of its own
/// firing time (into the world, or into any frame the poses are in).
pub fn accumulate(scans: &[LioScan], from_ns: u64, to_ns: u64, pose_at: impl Fn(u64) -> Isometry3<f64>) -> Vec<Vec3> {
    let mut out = Vec::new();
    for s in scans.iter().filter(|s| s.end_ns >= from_ns && s.start_ns <= to_ns) {
        for p in s.points.iter().filter(|p| p.t_ns >= from_ns && p.t_ns <= to_ns) {
            let q = pose_at(p.t_ns) * Point3::new(f64::from(p.x_m), f64::from(p.y_m), f64::from(p.z_m));
            out.push(q.coords);
        }
    }
    out
}

/// A registration pair from the simulator, with its truth (maps source points into the target).
pub struct Pair {
    pub source: Vec<Vec3>,
    pub target: Vec<Vec3>,
    pub truth: Isometry3<f64>,
    pub describe: String,
}

/// A scenario's pair: the robot's map (every robot scan of the run, placed by the robot's true
/// poses, reduced to 5 cm voxels) against the rig's scans over `window_s` ending at `t_end_s`
/// (placed by the rig's true poses relative to its pose at `t_end_s`), so the truth is the rig's
/// true pose at `t_end_s`.
pub fn sim_pair(scenario: &str, duration_s: f64, t_end_s: f64, window_s: f64) -> Pair {
    let sim = simulate(scenario, duration_s, "grid");
    let t0 = sim.robot_truth.first().map_or(0, |t| t.0);
    let end = t0 + (t_end_s * 1e9) as u64;
    let target = voxel_downsample(&accumulate(&sim.robot.scans, 0, u64::MAX, |t| truth_at(&sim.robot_truth, t)), 0.05);
    let at_end = truth_at(&sim.fpv_truth, end);
    let inv = at_end.inverse();
    let from = end.saturating_sub((window_s * 1e9) as u64);
    let source = accumulate(&sim.fpv.scans, from, end, |t| inv * truth_at(&sim.fpv_truth, t));
    let describe = format!(
        "`{scenario}`, seed 1, {duration_s} s: robot map of {} scans (5 cm voxels); rig window {window_s} s ending at t = {t_end_s} s (rig at {:.2}, {:.2}, {:.2} m)",
        sim.robot.scans.len(),
        at_end.translation.x,
        at_end.translation.y,
        at_end.translation.z
    );
    Pair { source, target, truth: at_end, describe }
}
