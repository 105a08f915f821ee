//! The robot's side of the mission, sans-IO: its LiDAR's IMU samples and scans in, the LIO pose
//! of every scan, person detections over a short window of placed scans, and the map the rig
//! aligns to (kept as one point per voxel, handed out as changed map tiles) out.

use super::person_motion::{PersonMotion, WALKING_MPS};
use super::place::ScanPlacer;
use super::robot_map::{MapScan, RobotMap, RobotMapConfig};
use crate::align::Coverage;
use crate::ar::{ArPerson, OrientedBox};
use crate::detect::{
    make_detector, DetectConfig, DetectWindow, Detection, Detector, FloorModel, PersonPose, WindowPoint,
};
use crate::explore::{OccupancyConfig, OccupancyGrid};
use crate::lio::{ImuNoise, ImuSample, Lio, LioConfig, LioScan, ScanOutput, UpdateConfig, WheelFusion, WheelSample};
use crate::timing::Stopwatch;
use crate::PipelineError;
use nalgebra::Vector3;
use starc_time::{Clock, Stamp};
use std::collections::VecDeque;
use std::sync::Arc;

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
    /// A person (not lying) walking at least `walker_speed_mps` (fitted to their detections of the
    /// last `motion_span_ns`, over at least `motion_min_baseline_ns`) is drawn without their
    /// returns lower than `walker_min_height_m` above the floor: a walker's legs swing (a foot at
    /// two to three times their pace, a knee at up to twice it), so where the scan saw them is not
    /// where they are. The default, 0.8 m, is just under an adult's hips (about half their
    /// height); 0 draws them whole.
    pub walker_speed_mps: f64,
    pub walker_min_height_m: f64,
    pub motion_span_ns: u64,
    pub motion_min_baseline_ns: u64,
    /// The clock of the detector's compute time.
    pub stopwatch: Stopwatch,
    /// An occupancy grid of the floor grown from every placed scan, the ray of every this many
    /// points (0: none), from the detector's first floor on: what exploration will plan on, and
    /// the explored floor area the scorer reports (`exploration`, docs/explore.md).
    pub floor_grid_ray_stride: usize,
}

/// The robot's coverage (space its rays crossed) in voxels of this size, from every this many
/// points' rays: a quarter metre tells a room's free middle from its walls, and one ray in 16
/// covers a room within a few scans.
pub const COVERAGE_VOXEL_M: f64 = 0.25;
pub const COVERAGE_RAY_STRIDE: usize = 16;
/// The tiles carry voxels crossed this often: the rig's `overlap_min_crossings` (a voxel crossed
/// once may be a grazing ray's).
pub const COVERAGE_MIN_CROSSINGS: u16 = 2;

/// The robot's gyro noise density for its LIO (rad/s per sqrt(Hz); config/lio_robot.toml): a
/// wheeled base on a floor turns smoothly, so its attitude is left to its gyro between scans far
/// more than a walker's helmet can be. The LIO's generic 0.1 let a scan that sees little but new
/// geometry, in a turn, tilt it by up to a degree; 0.005 still let a stretch of scans turn the
/// heading by a few tenths of a degree, which a long drive turns into centimetres. 0.001 is four
/// times the BMI088's density (docs/lio.md, "The robot's gyro noise").
pub const ROBOT_GYRO_NOISE_RAD_S: f64 = 0.001;
/// The robot's accelerometer bias (1 sigma, m/s^2; config/lio_robot.toml) that its still start
/// takes for gravity, tied to the gravity in the filter's start (`lio::start`), as the rig's: its
/// map keeps the start's lean, and gravity leans with it, instead of the attitude being turned
/// level under a map already built (docs/lio.md, "The rig's accelerometer bias").
pub const ROBOT_ACC_BIAS_SIGMA_M_S2: f64 = 0.05;
/// The variance the robot's LIO gives one point-to-plane residual (m^2; config/lio_robot.toml).
/// The generic 0.001 (3 cm) takes a scan's thousand centroids as independent. They are not:
/// each is matched to a plane fitted to a map the same poses built, so one scan's errors move
/// together, and a scan outweighed the gyro and the wheels. 0.01 (10 cm) was measured on 120
/// development buildings (docs/lio.md, "How much one scan weighs").
pub const ROBOT_RESIDUAL_VAR_M2: f64 = 0.01;
/// The robot's scan and map voxels for its LIO (config/lio_robot.toml): indoors, a wheeled
/// base's scans reduced to 0.15 m and matched against a map kept at one point per 0.1 m voxel
/// fit planes from the wall in front of it rather than from half a metre around; measured on
/// development buildings (docs/lio.md, "The robot's voxels").
pub const ROBOT_SCAN_VOXEL_M: f64 = 0.15;
pub const ROBOT_MAP_VOXEL_M: f64 = 0.1;
/// The floor grid's ray stride in scored offline runs (`starc mission`, `starc eval`): one ray
/// in 8 fills a room's floor within a few scans at a few milliseconds a scan.
pub const FLOOR_GRID_RAY_STRIDE: usize = 8;
/// The base's ground point in the Avia IMU's frame: the Avia 0.45 m above the floor, level, over
/// the base's centre (the Avia's IMU sits at (0.04165, 0.02326, -0.0284) m in its LiDAR's
/// frame). Only the horizontal part matters much: it turns the base's yaw rate into velocity.
pub const ROBOT_IMU_T_BASE_M: [f64; 3] = [0.04165, 0.02326, -0.4784];

impl RobotCoreConfig {
    /// The robot's LIO settings: the defaults with [`ROBOT_GYRO_NOISE_RAD_S`] and
    /// [`ROBOT_RESIDUAL_VAR_M2`], and no
    /// zero-velocity update (`lio::still`): a base gliding at a steady speed looks as still to
    /// its IMU as one parked, and its wheels tell the two apart.
    pub fn robot_lio() -> LioConfig {
        LioConfig {
            noise: ImuNoise { gyro_rad_s: ROBOT_GYRO_NOISE_RAD_S, ..ImuNoise::default() },
            still_sigma_m_s: 0.0,
            acc_bias_sigma_m_s2: ROBOT_ACC_BIAS_SIGMA_M_S2,
            wheel: WheelFusion { pos_imu_base: ROBOT_IMU_T_BASE_M.into(), ..WheelFusion::default() },
            scan_voxel_m: ROBOT_SCAN_VOXEL_M,
            map_voxel_m: ROBOT_MAP_VOXEL_M,
            update: UpdateConfig { residual_var_m2: ROBOT_RESIDUAL_VAR_M2, ..UpdateConfig::default() },
            ..LioConfig::default()
        }
    }

    /// These settings with every compute time measured on `stopwatch` (LIO and detector).
    pub fn with_stopwatch(mut self, stopwatch: Stopwatch) -> Self {
        self.stopwatch = stopwatch;
        self.lio.stopwatch = stopwatch;
        self
    }

    /// The map's part of the config.
    pub fn map_config(&self) -> RobotMapConfig {
        RobotMapConfig {
            voxel_m: self.map_voxel_m,
            tile_edge_m: self.tile_edge_m,
            tile_step_m: self.tile_step_m,
            coverage_voxel_m: COVERAGE_VOXEL_M,
            coverage_ray_stride: COVERAGE_RAY_STRIDE,
            tile_coverage_min_crossings: COVERAGE_MIN_CROSSINGS,
        }
    }
}

impl Default for RobotCoreConfig {
    fn default() -> Self {
        Self {
            lio: Self::robot_lio(),
            detect: DetectConfig::default(),
            detect_scans: 3,
            map_voxel_m: 0.1,
            fresh_points_ns: 100_000_000,
            tile_edge_m: 4.0,
            tile_step_m: 0.01,
            person_radius_m: 0.25,
            walker_speed_mps: WALKING_MPS,
            walker_min_height_m: 0.8,
            motion_span_ns: 500_000_000,
            motion_min_baseline_ns: 200_000_000,
            stopwatch: Stopwatch::Wall,
            floor_grid_ray_stride: 0,
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

pub struct RobotCore {
    cfg: RobotCoreConfig,
    lio: Lio,
    placer: ScanPlacer,
    detector: Box<dyn Detector + Send>,
    window: VecDeque<Arc<Vec<WindowPoint>>>,
    /// Placed scans not yet in the map (shared with the window): they go in when the map is
    /// next asked for, so that growing the map never delays a detection (or a node takes them
    /// to grow its own map elsewhere: [`Self::take_unmapped`]).
    unmapped: Vec<MapScan>,
    map: RobotMap,
    motion: PersonMotion,
    outs: Vec<ScanOutput>,
    floor_grid: Option<OccupancyGrid>,
}

impl RobotCore {
    pub fn new(cfg: RobotCoreConfig) -> Result<Self, PipelineError> {
        if cfg.detect_scans == 0 {
            return Err(PipelineError::BadFile {
                format: "robot config",
                reason: "detect_scans must be positive".into(),
            });
        }
        Ok(Self {
            lio: Lio::new(cfg.lio.clone()),
            detector: make_detector(&cfg.detect)?,
            placer: ScanPlacer::default(),
            window: VecDeque::new(),
            unmapped: Vec::new(),
            map: RobotMap::new(cfg.map_config())?,
            motion: PersonMotion::new(cfg.motion_span_ns, cfg.motion_min_baseline_ns),
            outs: Vec::new(),
            floor_grid: None,
            cfg,
        })
    }

    pub fn push_imu(&mut self, sample: ImuSample, out: &mut Vec<RobotStep>) {
        self.lio.push_imu(sample, &mut self.outs);
        self.drain(out);
    }

    /// The base's wheel odometry, in time order before the scans that end after it.
    pub fn push_wheel(&mut self, sample: WheelSample) {
        self.lio.push_wheel(sample);
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
            self.grow_floor_grid(&o.lidar_pose.translation.vector, &placed);
            self.unmapped.push(MapScan { origin_m: o.lidar_pose.translation.vector, points: Arc::clone(&placed) });
            self.window.push_back(placed);
            if self.window.len() > self.cfg.detect_scans {
                self.window.pop_front();
            }
            let detection = (self.window.len() == self.cfg.detect_scans).then(|| self.detect(&o));
            out.push(RobotStep { output: o, detection });
        }
    }

    /// The floor grid (`floor_grid_ray_stride` > 0), once the detector has found a floor.
    pub fn floor_grid(&self) -> Option<&OccupancyGrid> {
        self.floor_grid.as_ref()
    }

    /// Adds a placed scan to the floor grid, made around the sensor at the floor the detector
    /// found under it the first time it found one.
    fn grow_floor_grid(&mut self, origin: &Vector3<f64>, placed: &[WindowPoint]) {
        let stride = self.cfg.floor_grid_ray_stride;
        if stride == 0 {
            return;
        }
        if self.floor_grid.is_none() {
            let Some(floor) = self.detector.last_floor() else { return };
            // The floor's height under the sensor: a point at z = 0 there is this far above it.
            let floor_z_m = -floor.height(origin.x, origin.y, 0.0);
            let cfg = OccupancyConfig { floor_z_m, ..OccupancyConfig::default() };
            self.floor_grid = OccupancyGrid::new(cfg, [origin.x, origin.y]);
        }
        if let Some(grid) = self.floor_grid.as_mut() {
            let points: Vec<Vector3<f64>> = placed.iter().step_by(stride).map(|p| p.xyz()).collect();
            grid.add_scan(origin, &points);
        }
    }

    fn flush_map(&mut self) {
        for scan in std::mem::take(&mut self.unmapped) {
            self.map.add_scan(&scan);
        }
    }

    /// The placed scans not yet in this core's map, for a map grown elsewhere (a
    /// [`RobotMap`] made from [`RobotCoreConfig::map_config`]); this core's own map then never
    /// sees them.
    pub fn take_unmapped(&mut self) -> Vec<MapScan> {
        std::mem::take(&mut self.unmapped)
    }

    fn detect(&mut self, o: &ScanOutput) -> RobotDetection {
        let points: Vec<WindowPoint> = self.window.iter().flat_map(|s| s.iter()).copied().collect();
        let t0 = self.cfg.stopwatch.start();
        let w = DetectWindow { stamp: Stamp::new(o.end_ns, Clock::Ptp), sensor_pose: o.lidar_pose, points: &points };
        let mut found = Vec::new();
        self.detector.detect(&w, &mut found);
        let detect_ms = t0.ms();
        let fresh_from = o.end_ns.saturating_sub(self.cfg.fresh_points_ns);
        let floor = self.detector.last_floor();
        let people = found
            .iter()
            .map(|det| {
                let fresh =
                    det.point_indices.iter().filter_map(|&i| points.get(i as usize)).filter(|p| p.t_ns >= fresh_from);
                // Anyone but a lying person: a walker seen in part (a sliver past a door's edge)
                // is judged sitting or crouching by their shape alone.
                let walking = det.pose != PersonPose::Lying
                    && self.cfg.walker_min_height_m > 0.0
                    && self.motion.velocity(o.end_ns, &det.centre_m).norm() >= self.cfg.walker_speed_mps;
                let min_height_m = if walking { self.cfg.walker_min_height_m } else { f64::MIN };
                ArPerson {
                    points_world: core_points(
                        above_floor(fresh, floor.as_ref(), min_height_m),
                        self.cfg.person_radius_m,
                    ),
                    bbox: Some(OrientedBox { centre_m: det.centre_m, size_m: det.size_m, yaw_rad: det.yaw_rad }),
                    age_ns: 0,
                    pose: Some(det.pose),
                }
            })
            .collect();
        self.motion.push(o.end_ns, found.iter().map(|d| d.centre_m).collect());
        let scores = found.iter().map(|d| d.score).collect();
        RobotDetection { stamp_ns: o.end_ns, people, scores, found, points, detect_ms }
    }

    /// The whole map for alignment (one point per voxel), in the robot's world.
    pub fn map_points(&mut self) -> Vec<Vector3<f64>> {
        self.flush_map();
        self.map.points()
    }

    /// [`Self::map_points`] and, for each, the direction towards the sensor that first saw it
    /// (see [`RobotMap::points_seen_from`]).
    pub fn map_points_seen_from(&mut self) -> (Vec<Vector3<f64>>, Vec<Vector3<f64>>) {
        self.flush_map();
        self.map.points_seen_from()
    }

    /// The space the robot's rays crossed so far (see [`crate::align::coverage`]).
    pub fn map_coverage(&mut self) -> Arc<Coverage> {
        self.flush_map();
        self.map.coverage()
    }

    pub fn map_len(&mut self) -> usize {
        self.flush_map();
        self.map.len()
    }

    /// The map tiles changed since the last call, encoded (see [`RobotMap::take_changed_tiles`]).
    pub fn take_changed_tiles(&mut self) -> Result<Vec<Vec<u8>>, PipelineError> {
        self.flush_map();
        self.map.take_changed_tiles()
    }
}

/// The points at least `min_height_m` above the floor, or all of them when none is (a person
/// seen only below it is still drawn) or the floor is not known.
fn above_floor<'a>(
    points: impl Iterator<Item = &'a WindowPoint>,
    floor: Option<&FloorModel>,
    min_height_m: f64,
) -> Vec<Vector3<f64>> {
    let (high, low): (Vec<&WindowPoint>, Vec<&WindowPoint>) = points.partition(|p| {
        floor.is_none_or(|f| f.height(f64::from(p.x_m), f64::from(p.y_m), f64::from(p.z_m)) >= min_height_m)
    });
    let kept = if high.is_empty() { low } else { high };
    kept.into_iter().map(WindowPoint::xyz).collect()
}

/// The points within `radius_m` (horizontally) of their per-axis median; all when `radius_m` is 0.
fn core_points(all: Vec<Vector3<f64>>, radius_m: f64) -> Vec<Vector3<f64>> {
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

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn the_shipped_robot_lio_config_is_the_robots_defaults() {
        let file = crate::lio::LioFile::from_toml(include_str!("../../../config/lio_robot.toml")).unwrap();
        assert_eq!(file.to_config().unwrap(), RobotCoreConfig::robot_lio());
        assert_eq!(RobotCoreConfig::default().lio.noise.gyro_rad_s, ROBOT_GYRO_NOISE_RAD_S);
        // Everything else is the LIO's generic default.
        let generic = LioConfig::default();
        let robot = RobotCoreConfig::robot_lio();
        assert_eq!(robot.wheel.pos_imu_base, nalgebra::Vector3::from(ROBOT_IMU_T_BASE_M));
        assert_eq!(robot.still_sigma_m_s, 0.0);
        assert_eq!(robot.acc_bias_sigma_m_s2, ROBOT_ACC_BIAS_SIGMA_M_S2);
        assert_eq!(robot.update, UpdateConfig { residual_var_m2: ROBOT_RESIDUAL_VAR_M2, ..generic.update });
        assert_eq!(
            LioConfig {
                noise: generic.noise,
                wheel: generic.wheel.clone(),
                still_sigma_m_s: generic.still_sigma_m_s,
                acc_bias_sigma_m_s2: generic.acc_bias_sigma_m_s2,
                scan_voxel_m: generic.scan_voxel_m,
                map_voxel_m: generic.map_voxel_m,
                update: generic.update,
                ..robot
            },
            generic
        );
    }

    fn point(z_m: f32) -> WindowPoint {
        WindowPoint { x_m: 1.0, y_m: 2.0, z_m, t_ns: 0 }
    }

    #[test]
    fn a_walkers_lower_legs_are_left_out_but_never_the_whole_person() {
        // The floor 0.5 m below the world's origin.
        let floor = FloorModel::flat(-0.5);
        let body = [point(-0.45), point(-0.2), point(0.0), point(0.8)];
        let z = |v: Vec<Vector3<f64>>| v.iter().map(|p| (p.z * 100.0).round()).collect::<Vec<_>>();
        assert_eq!(z(above_floor(body.iter(), Some(&floor), 0.4)), [0.0, 80.0]);
        assert_eq!(z(above_floor(body.iter(), Some(&floor), f64::MIN)).len(), 4);
        // No floor: nothing is known to be low.
        assert_eq!(z(above_floor(body.iter(), None, 0.4)).len(), 4);
        // Seen only below the cut (legs under a table): all of it.
        let legs = [point(-0.45), point(-0.2)];
        assert_eq!(z(above_floor(legs.iter(), Some(&floor), 0.4)).len(), 2);
    }
}
