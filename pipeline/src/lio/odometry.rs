//! The LIO front to back: static init, IMU propagation, de-skew, iterated update, map growth.

use super::deskew::deskew;
use super::init::{InitResult, InitStatus, StaticInit};
use super::ivox::VoxelMap;
use super::propagate::{step, ImuNoise, Knot};
use super::state::{Cov, State, BA, BG, GRAV, POS, ROT, VEL};
use super::types::{ImuSample, LioScan};
use super::update::{update, UpdateConfig, UpdateReport};
use nalgebra::{Isometry3, Rotation3, Vector3};
use std::collections::{HashMap, VecDeque};
use std::time::Instant;

#[derive(Clone, Debug, PartialEq)]
pub struct LioConfig {
    /// The LiDAR in the IMU frame (`T_imu_lidar`).
    pub rot_imu_lidar: Rotation3<f64>,
    pub pos_imu_lidar: Vector3<f64>,
    pub init_window_ns: u64,
    pub noise: ImuNoise,
    pub update: UpdateConfig,
    /// Scan downsampling (voxel centroid) before the update.
    pub scan_voxel_m: f64,
    pub map_voxel_m: f64,
    pub map_points_per_voxel: usize,
    pub map_min_spacing_m: f64,
    pub map_radius_m: f64,
}

impl Default for LioConfig {
    fn default() -> Self {
        Self {
            rot_imu_lidar: Rotation3::identity(),
            pos_imu_lidar: Vector3::zeros(),
            init_window_ns: 1_000_000_000,
            noise: ImuNoise::default(),
            update: UpdateConfig::default(),
            scan_voxel_m: 0.5,
            map_voxel_m: 0.5,
            map_points_per_voxel: 20,
            map_min_spacing_m: 0.1,
            map_radius_m: 100.0,
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LioStatus {
    Initializing(InitStatus),
    Running,
}

/// What one scan gave.
#[derive(Clone, Debug, PartialEq)]
pub struct ScanOutput {
    pub end_ns: u64,
    /// The LiDAR's pose in the (gravity-aligned) world at the scan's end.
    pub lidar_pose: Isometry3<f64>,
    pub update: UpdateReport,
    pub points_in: usize,
    pub points_used: usize,
    pub map_points: usize,
    /// Wall time spent on the scan (propagation to map insertion).
    pub elapsed_us: u64,
}

pub struct Lio {
    cfg: LioConfig,
    init: StaticInit,
    status: LioStatus,
    state: State,
    cov: Cov,
    state_ns: u64,
    /// The measurement held since `state_ns`.
    held: Option<ImuSample>,
    imu: VecDeque<ImuSample>,
    scans: VecDeque<LioScan>,
    map: VoxelMap,
    scans_done: u64,
    knots: Vec<Knot>,
    deskewed: Vec<Vector3<f64>>,
}

impl Lio {
    pub fn new(cfg: LioConfig) -> Self {
        let state = State {
            rot: Rotation3::identity(),
            pos: Vector3::zeros(),
            vel: Vector3::zeros(),
            bias_gyro: Vector3::zeros(),
            bias_acc: Vector3::zeros(),
            gravity: Vector3::zeros(),
            rot_imu_lidar: cfg.rot_imu_lidar,
            pos_imu_lidar: cfg.pos_imu_lidar,
        };
        let map = VoxelMap::new(cfg.map_voxel_m, cfg.map_points_per_voxel, cfg.map_min_spacing_m, cfg.map_radius_m);
        Self {
            init: StaticInit::new(cfg.init_window_ns),
            status: LioStatus::Initializing(InitStatus::Collecting),
            state,
            cov: Cov::identity(),
            state_ns: 0,
            held: None,
            imu: VecDeque::new(),
            scans: VecDeque::new(),
            map,
            scans_done: 0,
            knots: Vec::new(),
            deskewed: Vec::new(),
            cfg,
        }
    }

    pub fn status(&self) -> LioStatus {
        self.status
    }

    pub fn state(&self) -> &State {
        &self.state
    }

    pub fn map(&self) -> &VoxelMap {
        &self.map
    }

    /// Feeds one IMU sample (in time order); scans waiting for it are processed into `out`.
    pub fn push_imu(&mut self, s: ImuSample, out: &mut Vec<ScanOutput>) {
        if let LioStatus::Initializing(_) = self.status {
            let (st, result) = self.init.push(&s);
            self.status = LioStatus::Initializing(st);
            if let Some(r) = result {
                self.start(&r, s);
            }
            return;
        }
        self.imu.push_back(s);
        self.drain(out);
    }

    /// Feeds one scan; it is processed once the IMU has passed its end.
    pub fn push_scan(&mut self, scan: LioScan, out: &mut Vec<ScanOutput>) {
        if self.status != LioStatus::Running || scan.end_ns <= self.state_ns {
            return;
        }
        self.scans.push_back(scan);
        self.drain(out);
    }

    fn start(&mut self, r: &InitResult, last: ImuSample) {
        self.state.rot = r.rot_world_imu;
        self.state.bias_gyro = r.bias_gyro;
        self.state.gravity = Vector3::new(0.0, 0.0, -r.gravity_m_s2);
        let mut cov = Cov::zeros();
        for (at, v) in [(ROT, 1e-4), (POS, 1e-6), (VEL, 1e-4), (BG, 1e-6), (BA, 1e-3), (GRAV, 1e-4)] {
            for i in at..at + 3 {
                cov[(i, i)] = v;
            }
        }
        self.cov = cov;
        self.state_ns = r.end_ns;
        self.held = Some(last);
        self.status = LioStatus::Running;
    }

    fn drain(&mut self, out: &mut Vec<ScanOutput>) {
        while let Some(end) = self.scans.front().map(|s| s.end_ns) {
            if self.imu.back().is_none_or(|s| s.t_ns < end) {
                return;
            }
            if let Some(scan) = self.scans.pop_front() {
                out.push(self.process(&scan));
            }
        }
    }

    /// Propagates to `t_ns` with the buffered IMU, recording knots.
    fn propagate_to(&mut self, t_ns: u64) {
        while let Some(s) = self.imu.front().copied() {
            if s.t_ns > t_ns {
                break;
            }
            self.advance(s.t_ns);
            self.held = Some(s);
            self.imu.pop_front();
        }
        self.advance(t_ns);
    }

    fn advance(&mut self, t_ns: u64) {
        let Some(held) = self.held else { return };
        let dt_s = t_ns.saturating_sub(self.state_ns) as f64 * 1e-9;
        let knot = step(&mut self.state, &mut self.cov, &held, self.state_ns, dt_s, &self.cfg.noise);
        self.knots.push(knot);
        self.state_ns = self.state_ns.max(t_ns);
    }

    fn process(&mut self, scan: &LioScan) -> ScanOutput {
        let started = Instant::now();
        self.knots.clear();
        self.propagate_to(scan.end_ns);
        deskew(&scan.points, &self.knots, &self.state, &mut self.deskewed);
        let used = voxel_centroids(&self.deskewed, self.cfg.scan_voxel_m);
        let report = if self.map.is_empty() {
            UpdateReport::default()
        } else {
            update(&mut self.state, &mut self.cov, &used, &self.map, &self.cfg.update)
        };
        let (r, t) =
            (self.state.rot * self.state.rot_imu_lidar, self.state.rot * self.state.pos_imu_lidar + self.state.pos);
        for p in &used {
            self.map.insert(r * p + t);
        }
        self.scans_done += 1;
        if self.scans_done.is_multiple_of(10) {
            self.map.trim(&self.state.pos);
        }
        ScanOutput {
            end_ns: scan.end_ns,
            lidar_pose: self.state.lidar_pose(),
            update: report,
            points_in: scan.points.len(),
            points_used: used.len(),
            map_points: self.map.len(),
            elapsed_us: started.elapsed().as_micros() as u64,
        }
    }
}

/// One centroid per occupied voxel.
fn voxel_centroids(points: &[Vector3<f64>], voxel_m: f64) -> Vec<Vector3<f64>> {
    let mut cells: HashMap<(i32, i32, i32), (Vector3<f64>, u32)> = HashMap::with_capacity(points.len() / 4);
    for p in points {
        let k = ((p.x / voxel_m).floor() as i32, (p.y / voxel_m).floor() as i32, (p.z / voxel_m).floor() as i32);
        let e = cells.entry(k).or_insert((Vector3::zeros(), 0));
        e.0 += p;
        e.1 += 1;
    }
    cells.into_values().map(|(s, n)| s / f64::from(n)).collect()
}
