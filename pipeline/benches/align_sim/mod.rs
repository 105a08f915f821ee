//! The simulated lab for the alignment benches: runs `starc_hil::sim` (both Avias through the
//! mock device's packets), decodes the capture as a real one would be, and reads the ground truth.
#![allow(dead_code)]

use nalgebra::{Isometry3, Point3};
use starc_hil::sim::run::{run, SimOptions, FPV_AVIA_IP, ROBOT_AVIA_IP};
use starc_hil::sim::scenario::Scenario;
use starc_hil::tum::{pose_at, read_tum};
use starc_pipeline::align::{Ray, Vec3};
use starc_pipeline::lio::{LioScan, TimedPoint};
use starc_pipeline::voxel_hash::voxel_downsample;
use std::path::PathBuf;

pub use starc_bridge::AviaInputs as Decoded;

/// One Avia's inputs from a simulator capture (panics on a bad capture: benches only).
pub fn decode(pcap: &std::path::Path, avia: std::net::Ipv4Addr) -> Decoded {
    starc_bridge::decode_avia(pcap, avia).unwrap()
}

/// One simulator run's outputs.
pub struct SimRun {
    pub dir: PathBuf,
    pub robot_truth: Vec<(u64, Isometry3<f64>)>,
    pub fpv_truth: Vec<(u64, Isometry3<f64>)>,
    pub robot: Decoded,
    pub fpv: Decoded,
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
        robot_truth: read_tum(&dir.join("gt_robot.tum")).unwrap(),
        fpv_truth: read_tum(&dir.join("gt_fpv.tum")).unwrap(),
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

/// The points of the scans fired within [from_ns, to_ns].
fn fired_within(scans: &[LioScan], from_ns: u64, to_ns: u64) -> impl Iterator<Item = &TimedPoint> {
    scans
        .iter()
        .filter(move |s| s.end_ns >= from_ns && s.start_ns <= to_ns)
        .flat_map(move |s| s.points.iter().filter(move |p| p.t_ns >= from_ns && p.t_ns <= to_ns))
}

fn xyz(p: &TimedPoint) -> Point3<f64> {
    Point3::new(f64::from(p.x_m), f64::from(p.y_m), f64::from(p.z_m))
}

/// Points of the scans within [from_ns, to_ns], each moved by the pose `pose_at(t)` of its own
/// firing time (into the world, or into any frame the poses are in).
pub fn accumulate(scans: &[LioScan], from_ns: u64, to_ns: u64, pose_at: impl Fn(u64) -> Isometry3<f64>) -> Vec<Vec3> {
    fired_within(scans, from_ns, to_ns).map(|p| (pose_at(p.t_ns) * xyz(p)).coords).collect()
}

/// Every `stride`-th point of the scans within [from_ns, to_ns] as a ray from the sensor's
/// position at its firing time, both moved by `pose_at(t)`.
pub fn rays(
    scans: &[LioScan],
    from_ns: u64,
    to_ns: u64,
    stride: usize,
    pose_at: impl Fn(u64) -> Isometry3<f64>,
) -> Vec<Ray> {
    fired_within(scans, from_ns, to_ns)
        .step_by(stride.max(1))
        .map(|p| {
            let pose = pose_at(p.t_ns);
            Ray { origin: pose.translation.vector, end: (pose * xyz(p)).coords }
        })
        .collect()
}

/// A registration pair from the simulator, with its truth (maps source points into the target).
pub struct Pair {
    pub source: Vec<Vec3>,
    /// A sample of the source's rays (the free-space check).
    pub rays: Vec<Ray>,
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
    let target =
        voxel_downsample(&accumulate(&sim.robot.scans, 0, u64::MAX, |t| pose_at(&sim.robot_truth, t).unwrap()), 0.05);
    let at_end = pose_at(&sim.fpv_truth, end).unwrap();
    let inv = at_end.inverse();
    let from = end.saturating_sub((window_s * 1e9) as u64);
    let source = accumulate(&sim.fpv.scans, from, end, |t| inv * pose_at(&sim.fpv_truth, t).unwrap());
    let rays = rays(&sim.fpv.scans, from, end, 97, |t| inv * pose_at(&sim.fpv_truth, t).unwrap());
    let describe = format!(
        "`{scenario}`, seed 1, {duration_s} s: robot map of {} scans (5 cm voxels); rig window {window_s} s ending at t = {t_end_s} s (rig at {:.2}, {:.2}, {:.2} m)",
        sim.robot.scans.len(),
        at_end.translation.x,
        at_end.translation.y,
        at_end.translation.z
    );
    Pair { source, rays, target, truth: at_end, describe }
}
