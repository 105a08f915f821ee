//! The robot's side of the mission, sans-IO: its LiDAR's IMU samples and scans in, the LIO pose
//! of every scan, person detections over a short window of placed scans, and the map the rig
//! aligns to (kept as one point per voxel, handed out as changed map tiles) out.

use super::place::ScanPlacer;
use crate::align::encode_tiles;
use crate::ar::{ArPerson, OrientedBox};
use crate::detect::{DetectConfig, DetectWindow, Detection, Detector, GeometricDetector, WindowPoint};
use crate::lio::{ImuSample, Lio, LioConfig, LioScan, ScanOutput};
use crate::voxel_hash::{floor_i32, VoxelHashMap, VoxelHashSet};
use crate::PipelineError;
use nalgebra::Vector3;
use starc_time::{Clock, Stamp};
use std::collections::VecDeque;
use std::sync::Arc;
use std::time::Instant;

/// How the robot's side runs; the defaults are what `starc sim` measures.
#[derive(Clone, Debug)]
pub struct RobotCoreConfig {
    pub lio: LioConfig,
    pub detect: DetectConfig,
    /// Scans per detection window (0.3 s at 10 Hz); the detector runs after every scan.
    pub detect_scans: usize,
    /// The map for alignment keeps one point per voxel of this size.
    pub map_voxel_m: f64,
    /// Only the points of a detection fired this close to its stamp are sent: older ones of a
    /// walking person trail behind them.
    pub fresh_points_ns: u64,
    /// Edge and quantization of the map tiles sent to the rig.
    pub tile_edge_m: f64,
    pub tile_step_m: f64,
    /// Only a person's points this close (in the floor plane) to the median of their points are
    /// drawn: what the cluster took from a chair or a wall beside them is not (0: all).
    pub person_radius_m: f64,
}

impl Default for RobotCoreConfig {
    fn default() -> Self {
        Self {
            lio: LioConfig::default(),
            detect: DetectConfig::default(),
            detect_scans: 3,
            map_voxel_m: 0.1,
            fresh_points_ns: 100_000_000,
            tile_edge_m: 4.0,
            tile_step_m: 0.01,
            person_radius_m: 0.25,
        }
    }
}

/// People found in one window.
#[derive(Clone, Debug)]
pub struct RobotDetection {
    /// End of the window's newest scan (LiDAR clock).
    pub stamp_ns: u64,
    /// What the rig draws: each person's fresh points and box, in the robot's world.
    pub people: Vec<ArPerson>,
    pub scores: Vec<f64>,
    /// The detector's own output and the window it ran on (for scoring).
    pub found: Vec<Detection>,
    pub points: Vec<WindowPoint>,
    pub detect_ms: f64,
}

/// What one LIO output of the robot gave.
#[derive(Clone, Debug)]
pub struct RobotStep {
    pub output: ScanOutput,
    pub detection: Option<RobotDetection>,
}

type VoxelKey = (i32, i32, i32);

pub struct RobotCore {
    cfg: RobotCoreConfig,
    lio: Lio,
    placer: ScanPlacer,
    detector: GeometricDetector,
    window: VecDeque<Arc<Vec<WindowPoint>>>,
    /// Placed scans not yet in the map (shared with the window): they go in when the map is
    /// next asked for, so that growing the map never delays a detection.
    unmapped: Vec<Arc<Vec<WindowPoint>>>,
    /// Occupied voxels of the map, and each tile's points (one per voxel).
    voxels: VoxelHashSet<VoxelKey>,
    tiles: VoxelHashMap<VoxelKey, Vec<Vector3<f64>>>,
    dirty_tiles: VoxelHashSet<VoxelKey>,
    tile_version: u32,
    outs: Vec<ScanOutput>,
}

impl RobotCore {
    pub fn new(cfg: RobotCoreConfig) -> Result<Self, PipelineError> {
        if !(cfg.map_voxel_m > 0.0 && cfg.tile_edge_m > cfg.map_voxel_m && cfg.detect_scans > 0) {
            return Err(PipelineError::BadFile {
                format: "robot config",
                reason: "map_voxel_m, tile_edge_m and detect_scans must be positive, tiles larger than voxels".into(),
            });
        }
        Ok(Self {
            lio: Lio::new(cfg.lio.clone()),
            detector: GeometricDetector::new(cfg.detect.clone())?,
            placer: ScanPlacer::default(),
            window: VecDeque::new(),
            unmapped: Vec::new(),
            voxels: VoxelHashSet::default(),
            tiles: VoxelHashMap::default(),
            dirty_tiles: VoxelHashSet::default(),
            tile_version: 0,
            outs: Vec::new(),
            cfg,
        })
    }

    pub fn push_imu(&mut self, sample: ImuSample, out: &mut Vec<RobotStep>) {
        self.lio.push_imu(sample, &mut self.outs);
        self.drain(out);
    }

    pub fn push_scan(&mut self, scan: LioScan, out: &mut Vec<RobotStep>) {
        let shared = Arc::new(scan);
        self.placer.pending(Arc::clone(&shared));
        self.lio.push_scan(shared, &mut self.outs);
        self.drain(out);
    }

    fn drain(&mut self, out: &mut Vec<RobotStep>) {
        let outs = std::mem::take(&mut self.outs);
        for o in outs {
            let placed = Arc::new(self.placer.place(&o));
            self.unmapped.push(Arc::clone(&placed));
            self.window.push_back(placed);
            if self.window.len() > self.cfg.detect_scans {
                self.window.pop_front();
            }
            let detection = (self.window.len() == self.cfg.detect_scans).then(|| self.detect(&o));
            out.push(RobotStep { output: o, detection });
        }
    }

    fn flush_map(&mut self) {
        let per_tile = self.voxels_per_tile();
        for placed in std::mem::take(&mut self.unmapped) {
            for p in placed.iter() {
                let v = p.xyz() / self.cfg.map_voxel_m;
                let key = (floor_i32(v.x), floor_i32(v.y), floor_i32(v.z));
                if self.voxels.insert(key) {
                    let tile = (key.0.div_euclid(per_tile), key.1.div_euclid(per_tile), key.2.div_euclid(per_tile));
                    self.tiles.entry(tile).or_default().push(p.xyz());
                    self.dirty_tiles.insert(tile);
                }
            }
        }
    }

    fn voxels_per_tile(&self) -> i32 {
        (self.cfg.tile_edge_m / self.cfg.map_voxel_m).round().max(1.0) as i32
    }

    fn detect(&mut self, o: &ScanOutput) -> RobotDetection {
        let points: Vec<WindowPoint> = self.window.iter().flat_map(|s| s.iter()).copied().collect();
        let t0 = Instant::now();
        let w = DetectWindow { stamp: Stamp::new(o.end_ns, Clock::Ptp), sensor_pose: o.lidar_pose, points: &points };
        let mut found = Vec::new();
        self.detector.detect(&w, &mut found);
        let detect_ms = t0.elapsed().as_secs_f64() * 1e3;
        let fresh_from = o.end_ns.saturating_sub(self.cfg.fresh_points_ns);
        let people = found
            .iter()
            .map(|det| ArPerson {
                points_world: core_points(
                    det.point_indices
                        .iter()
                        .filter_map(|&i| points.get(i as usize))
                        .filter(|p| p.t_ns >= fresh_from)
                        .map(WindowPoint::xyz),
                    self.cfg.person_radius_m,
                ),
                bbox: Some(OrientedBox { centre_m: det.centre_m, size_m: det.size_m, yaw_rad: det.yaw_rad }),
                age_ns: 0,
            })
            .collect();
        let scores = found.iter().map(|d| d.score).collect();
        RobotDetection { stamp_ns: o.end_ns, people, scores, found, points, detect_ms }
    }

    /// The whole map for alignment (one point per voxel), in the robot's world.
    pub fn map_points(&mut self) -> Vec<Vector3<f64>> {
        self.flush_map();
        self.tiles.values().flatten().copied().collect()
    }

    pub fn map_len(&mut self) -> usize {
        self.flush_map();
        self.voxels.len()
    }

    /// The map tiles changed since the last call, encoded (see [`crate::align::tiles`]); every
    /// call that sends anything bumps the version, so a rig keeps the newest of each tile.
    pub fn take_changed_tiles(&mut self) -> Result<Vec<Vec<u8>>, PipelineError> {
        self.flush_map();
        if self.dirty_tiles.is_empty() {
            return Ok(Vec::new());
        }
        let per_tile = self.voxels_per_tile();
        let dirty = std::mem::take(&mut self.dirty_tiles);
        let points: Vec<Vector3<f64>> = dirty.iter().filter_map(|t| self.tiles.get(t)).flatten().copied().collect();
        self.tile_version = self.tile_version.wrapping_add(1);
        let edge_m = f64::from(per_tile) * self.cfg.map_voxel_m;
        let normals = vec![None; points.len()];
        let tiles = encode_tiles(&points, &normals, edge_m, self.cfg.tile_step_m, self.tile_version)?;
        Ok(tiles.into_iter().map(|(_, bytes)| bytes).collect())
    }
}

/// The points within `radius_m` (horizontally) of their per-axis median; all when `radius_m` is 0.
fn core_points(points: impl Iterator<Item = Vector3<f64>>, radius_m: f64) -> Vec<Vector3<f64>> {
    let all: Vec<Vector3<f64>> = points.collect();
    if radius_m <= 0.0 || all.is_empty() {
        return all;
    }
    let median = |f: fn(&Vector3<f64>) -> f64| {
        let mut v: Vec<f64> = all.iter().map(f).collect();
        v.sort_by(f64::total_cmp);
        v.get(v.len() / 2).copied().unwrap_or(0.0)
    };
    let (mx, my) = (median(|p| p.x), median(|p| p.y));
    let r2 = radius_m * radius_m;
    all.into_iter().filter(|p| (p.x - mx).powi(2) + (p.y - my).powi(2) <= r2).collect()
}
