//! The LIO front to back: static init, IMU propagation, de-skew, iterated update, map growth.

use super::deskew::deskew;
use super::health::{pos_sigma_m, uncertain_axes, Health, HealthConfig, HealthMonitor, Refusal, ScanFit, Verdict};
use super::init::{InitResult, InitStatus, StaticInit, DEFAULT_MAX_ACC_STD_M_S2, DEFAULT_MAX_GYRO_STD_RAD_S};
use super::ivox::VoxelMap;
use super::level::{level_update, LevelWindow};
use super::propagate::{step, ImuNoise, Knot};
use super::scan_points::ScanReduction;
use super::stand::{base_position, hold_update, stands};
use super::start::start_covariance;
use super::state::{Cov, State, POS, ROT, VEL};
use super::still::{acc_world_var, zero_velocity_update, StillWindow};
use super::types::{Clock, ImuSample, LioScan};
use super::update::{update, UpdateConfig, UpdateReport};
use super::wheel::{mean_twist, wheel_update, WheelFusion, WheelSample, WheelUse};
use crate::timing::Stopwatch;
use nalgebra::{Isometry3, Rotation3, Vector3};
use std::collections::VecDeque;
use std::sync::Arc;

#[derive(Clone, Debug, PartialEq)]
pub struct LioConfig {
    /// The LiDAR in the IMU frame (`T_imu_lidar`).
    pub rot_imu_lidar: Rotation3<f64>,
    pub pos_imu_lidar: Vector3<f64>,
    pub init_window_ns: u64,
    pub init_max_gyro_std_rad_s: f64,
    pub init_max_acc_std_m_s2: f64,
    /// Zero velocity where a scan cannot be matched and the IMU has been still over the last
    /// `still_window_ns` (`still_sigma_m_s` 0: never; see [`super::still`]).
    pub still_window_ns: u64,
    pub still_sigma_m_s: f64,
    /// Also on scans that matched, where the world acceleration the filter sees stayed under this
    /// RMS over the still window (0: only on unmatched scans; see [`super::still`]).
    pub still_max_acc_m_s2: f64,
    /// That limit is widened by this many sigmas of the world-acceleration error the filter
    /// expects from its own attitude, accelerometer bias and gravity (0: not widened).
    pub still_acc_sigmas: f64,
    /// The weight of the world acceleration's change over the window against its mean (1: RMS).
    pub still_change_weight: f64,
    /// The accelerometer bias's spread that a still start cannot tell from gravity; > 0 ties the
    /// two in the start's uncertainty, 0 starts them apart (see [`super::start`]).
    pub acc_bias_sigma_m_s2: f64,
    pub noise: ImuNoise,
    pub update: UpdateConfig,
    /// Scan downsampling (voxel centroid) before the update.
    pub scan_voxel_m: f64,
    /// Points closer than this to the LiDAR are dropped.
    pub blind_m: f64,
    /// At most this many scan points (voxel centroids) enter the update; 0: no limit.
    pub max_points: usize,
    /// A scan left with fewer points than this is reduced again on voxels half the size, down to
    /// `scan_min_voxel_m` (0: never; see [`super::scan_points`]).
    pub scan_min_points: usize,
    pub scan_min_voxel_m: f64,
    pub map_voxel_m: f64,
    pub map_points_per_voxel: usize,
    pub map_min_spacing_m: f64,
    pub map_radius_m: f64,
    pub health: HealthConfig,
    /// The clock of `ScanOutput::elapsed_us`.
    pub stopwatch: Stopwatch,
    /// The base's wheel odometry, when samples come ([`Lio::push_wheel`]).
    pub wheel: WheelFusion,
}

impl LioConfig {
    /// How each scan is reduced before the update.
    pub fn scan_reduction(&self) -> ScanReduction {
        ScanReduction {
            blind_m: self.blind_m,
            voxel_m: self.scan_voxel_m,
            min_points: self.scan_min_points,
            min_voxel_m: self.scan_min_voxel_m,
            max_points: self.max_points,
        }
    }
}

impl Default for LioConfig {
    fn default() -> Self {
        Self {
            // The Avia's internal IMU (see config/lio.toml).
            rot_imu_lidar: Rotation3::identity(),
            pos_imu_lidar: Vector3::new(0.04165, 0.02326, -0.0284),
            init_window_ns: 1_000_000_000,
            init_max_gyro_std_rad_s: DEFAULT_MAX_GYRO_STD_RAD_S,
            init_max_acc_std_m_s2: DEFAULT_MAX_ACC_STD_M_S2,
            still_window_ns: 500_000_000,
            still_sigma_m_s: 0.05,
            still_max_acc_m_s2: 0.0,
            still_acc_sigmas: 0.0,
            still_change_weight: 1.0,
            acc_bias_sigma_m_s2: 0.0,
            noise: ImuNoise::default(),
            update: UpdateConfig::default(),
            scan_voxel_m: 0.5,
            blind_m: 0.5,
            max_points: 1000,
            scan_min_points: 0,
            scan_min_voxel_m: 0.1,
            map_voxel_m: 0.5,
            map_points_per_voxel: 20,
            map_min_spacing_m: 0.1,
            map_radius_m: 100.0,
            health: HealthConfig::default(),
            stopwatch: Stopwatch::Wall,
            wheel: WheelFusion::default(),
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
    pub health: Health,
    /// Why the scan was refused (its update not applied, the scan kept out of the map).
    pub refused: Option<Refusal>,
    /// 1-sigma uncertainty of the LiDAR's position and yaw after the scan.
    pub pos_sigma_m: f64,
    pub yaw_sigma_deg: f64,
    pub points_in: usize,
    pub points_used: usize,
    /// The voxel the scan was reduced on (finer than the configured one where its view was small).
    pub voxel_m: f64,
    pub map_points: usize,
    /// Whether the wheels' twist at the scan's end was used.
    pub wheel: WheelUse,
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
    /// The IMU samples propagated over the last `still_window_ns`.
    still: StillWindow,
    /// Scans whose velocity was held at zero (see [`super::still`]).
    zero_velocity_updates: u64,
    /// The newest IMU stamp seen, and the IMU's sample period (a running mean).
    last_imu_ns: u64,
    imu_period_ns: f64,
    scans: VecDeque<Arc<LioScan>>,
    map: VoxelMap,
    monitor: HealthMonitor,
    /// Scans whose update was applied.
    updates_accepted: u64,
    scans_done: u64,
    knots: Vec<Knot>,
    deskewed: Vec<Vector3<f64>>,
    /// Wheel samples not yet older than the newest scan's window.
    wheels: VecDeque<WheelSample>,
    /// The accelerometer and the wheels since the last scan (the tilt's measurement).
    level: LevelWindow,
    /// Where the base's centre stood since the wheels last said it stopped (`lio::stand`).
    stand_anchor: Option<Vector3<f64>>,
    /// Scans whose tilt was measured (accelerometer less the wheels), and those gated.
    level_updates: (u64, u64),
    /// The clock of the first input; inputs on any other are refused and counted.
    clock: Option<Clock>,
    other_clock_inputs: u64,
    /// IMU samples refused for a non-finite value, and times the filter started over because
    /// its state went non-finite.
    non_finite_inputs: u64,
    resets: u64,
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
            init: StaticInit::with_limits(cfg.init_window_ns, cfg.init_max_gyro_std_rad_s, cfg.init_max_acc_std_m_s2),
            status: LioStatus::Initializing(InitStatus::Collecting),
            state,
            cov: Cov::identity(),
            state_ns: 0,
            held: None,
            imu: VecDeque::new(),
            still: StillWindow::new(cfg.still_window_ns, cfg.init_max_gyro_std_rad_s, cfg.init_max_acc_std_m_s2),
            zero_velocity_updates: 0,
            last_imu_ns: 0,
            imu_period_ns: 0.0,
            scans: VecDeque::new(),
            map,
            monitor: HealthMonitor::default(),
            updates_accepted: 0,
            scans_done: 0,
            knots: Vec::new(),
            deskewed: Vec::new(),
            wheels: VecDeque::new(),
            level: LevelWindow::default(),
            stand_anchor: None,
            level_updates: (0, 0),
            clock: None,
            other_clock_inputs: 0,
            non_finite_inputs: 0,
            resets: 0,
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

    /// Whether an input on `clock` may enter: the first input's clock is the filter's, and a
    /// time on another clock (an IMU stamped by its host, a LiDAR that lost PTP) means nothing
    /// against it.
    fn on_my_clock(&mut self, clock: Clock) -> bool {
        let mine = *self.clock.get_or_insert(clock);
        if mine != clock {
            self.other_clock_inputs += 1;
            if self.other_clock_inputs.is_power_of_two() {
                tracing::warn!(%mine, %clock, refused = self.other_clock_inputs, "LIO: an input on another clock refused");
            }
        }
        mine == clock
    }

    /// Inputs refused for being on another clock than the first input's.
    pub fn other_clock_inputs(&self) -> u64 {
        self.other_clock_inputs
    }

    /// Feeds one IMU sample (in time order); scans waiting for it are processed into `out`.
    pub fn push_imu(&mut self, s: ImuSample, out: &mut Vec<ScanOutput>) {
        if !s.gyro_rad_s.iter().chain(s.acc_m_s2.iter()).all(|v| v.is_finite()) {
            self.non_finite_inputs += 1;
            if self.non_finite_inputs.is_power_of_two() {
                tracing::warn!(refused = self.non_finite_inputs, "LIO: an IMU sample with a non-finite value refused");
            }
            return;
        }
        if !self.on_my_clock(s.clock) {
            return;
        }
        if s.t_ns > self.last_imu_ns {
            let dt_ns = (s.t_ns - self.last_imu_ns) as f64;
            if self.last_imu_ns > 0 && dt_ns < 1e8 {
                self.imu_period_ns = if self.imu_period_ns > 0.0 {
                    self.imu_period_ns + (dt_ns - self.imu_period_ns) / 16.0
                } else {
                    dt_ns
                };
            }
            self.last_imu_ns = s.t_ns;
        }
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

    /// Feeds one wheel sample (in time order, before the scans that end after it).
    pub fn push_wheel(&mut self, s: WheelSample) {
        // The LiDAR and IMU set the filter's clock; wheels before them are of no use yet.
        if self.clock.is_some()
            && self.on_my_clock(s.clock)
            && s.vx_m_s.is_finite()
            && s.vy_m_s.is_finite()
            && s.wz_rad_s.is_finite()
        {
            self.wheels.push_back(s);
        }
    }

    /// Feeds one scan; it is processed once the IMU has passed its end. A shared scan is kept
    /// as is (the mission's cores also place it), not copied.
    pub fn push_scan(&mut self, scan: impl Into<Arc<LioScan>>, out: &mut Vec<ScanOutput>) {
        let scan = scan.into();
        if !self.on_my_clock(scan.clock) || self.status != LioStatus::Running || scan.end_ns <= self.state_ns {
            return;
        }
        self.scans.push_back(scan);
        self.drain(out);
    }

    fn start(&mut self, r: &InitResult, last: ImuSample) {
        self.state.rot = r.rot_world_imu;
        self.state.bias_gyro = r.bias_gyro;
        self.state.gravity = Vector3::new(0.0, 0.0, -r.gravity_m_s2);
        self.cov = start_covariance(r, self.cfg.acc_bias_sigma_m_s2);
        self.state_ns = r.end_ns;
        self.held = Some(last);
        self.status = LioStatus::Running;
    }

    /// A scan is processed once no IMU sample can still come before its end: the propagation
    /// holds each sample until the next, so the one after the end adds nothing, and waiting for
    /// it cost the live robot half an IMU period (2.5 ms at the Avia's 200 Hz) per scan. The next
    /// sample is taken as due 0.9 periods after the last (jitter).
    fn imu_covers(&self, end_ns: u64) -> bool {
        if self.last_imu_ns >= end_ns {
            return true;
        }
        self.imu_period_ns > 0.0 && ((end_ns - self.last_imu_ns) as f64) < 0.9 * self.imu_period_ns
    }

    fn drain(&mut self, out: &mut Vec<ScanOutput>) {
        while let Some(end) = self.scans.front().map(|s| s.end_ns) {
            if !self.imu_covers(end) {
                return;
            }
            if let Some(scan) = self.scans.pop_front() {
                if !self.state.is_finite() {
                    self.start_over();
                    return;
                }
                out.push(self.process(&scan));
            }
        }
    }

    /// The filter starts over from initialisation (it needs the device to stand still again),
    /// keeping its clock and counters: a non-finite state would spread into every later pose
    /// and into the map. Its map goes too: the new filter's world is not the old one.
    fn start_over(&mut self) {
        let (clock, other, non_finite, resets) =
            (self.clock, self.other_clock_inputs, self.non_finite_inputs, self.resets + 1);
        *self = Lio::new(self.cfg.clone());
        (self.clock, self.other_clock_inputs, self.non_finite_inputs, self.resets) = (clock, other, non_finite, resets);
        tracing::error!(resets, "LIO: the state went non-finite; the filter starts over (stand still to initialise)");
    }

    /// IMU samples refused for a non-finite value, and times the filter started over.
    pub fn non_finite_counts(&self) -> (u64, u64) {
        (self.non_finite_inputs, self.resets)
    }

    /// Propagates to `t_ns` with the buffered IMU, recording knots.
    fn propagate_to(&mut self, t_ns: u64) {
        while let Some(s) = self.imu.front().copied() {
            if s.t_ns > t_ns {
                break;
            }
            self.advance(s.t_ns);
            self.held = Some(s);
            self.still.push(&s);
            if self.cfg.still_max_acc_m_s2 > 0.0 {
                let acc_world = self.state.rot * (s.acc_m_s2 - self.state.bias_acc) + self.state.gravity;
                self.still.push_acc_world(s.t_ns, acc_world);
            }
            self.level.push_acc(&s.acc_m_s2);
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
        let started = self.cfg.stopwatch.start();
        self.knots.clear();
        self.propagate_to(scan.end_ns);
        deskew(&scan.points, &self.knots, &self.state, &mut self.deskewed);
        let (wheel, standing) = self.wheel_step(scan.end_ns);
        let (used, voxel_m) = self.cfg.scan_reduction().reduce(&self.deskewed);
        let (mut report, mut verdict) = (UpdateReport::default(), None);
        if !self.map.is_empty() {
            let search_wide = self.monitor.is_lost()
                && (self.cfg.health.blind_ride_widens || self.monitor.contradicted() || wheel != WheelUse::Applied);
            if search_wide {
                self.widen_uncertainty();
            }
            let (prior, prior_cov) = (self.state.clone(), self.cov);
            let mut cfg = self.cfg.update;
            // A surface reduced on finer voxels gives more points, not more independent evidence:
            // its weight stays that of the configured voxels (docs/lio.md, "Fine voxels where
            // the view is small").
            cfg.residual_var_m2 *= (self.cfg.scan_voxel_m / voxel_m).powi(2);
            if search_wide {
                cfg.max_neighbour_dist_m *= 3.0;
                cfg.max_iterations *= 3;
            }
            report = update(&mut self.state, &mut self.cov, &used, &self.map, &cfg);
            let moved = prior.lidar_pose().inverse() * self.state.lidar_pose();
            let fit = ScanFit {
                matched: report.matched,
                used: used.len(),
                converged: report.converged,
                rms_m: report.rms_m,
                correction_m: moved.translation.vector.norm(),
                correction_deg: moved.rotation.angle().to_degrees(),
                weak_directions: report.weak_directions,
            };
            let v = self.monitor.judge(&self.cfg.health, scan.end_ns, &fit);
            // An update that came out non-finite is refused like any other bad scan.
            let v = if self.state.is_finite() { v } else { Verdict { refused: Some(Refusal::NonFinite), ..v } };
            if v.refused.is_some() {
                self.state = prior;
                self.cov = prior_cov;
            }
            verdict = Some(v);
        }
        let refused = verdict.and_then(|v| v.refused);
        // Where the wheels measured the velocity, they know better than the IMU's stillness. A
        // scan that matched holds it only where the filter also sees no acceleration: an IMU
        // cannot tell standing from gliding, and the first steps of a walk read as still.
        let unmatched = refused == Some(Refusal::TooFewMatches);
        if wheel != WheelUse::Applied && (unmatched || self.quiet()) {
            self.hold_if_still(scan.end_ns);
        }
        // A map too thin to match (the first scans, or a lost filter's) grows from the IMU's
        // pose; otherwise the filter would never have anything to find itself in.
        let grow_anyway =
            refused == Some(Refusal::TooFewMatches) && (self.monitor.is_lost() || self.updates_accepted == 0);
        if verdict.is_some() && refused.is_none() {
            self.updates_accepted += 1;
        }
        // The first standing scan's pose, as its update left it, is where the base is held.
        if !standing {
            self.stand_anchor = None;
        } else if self.stand_anchor.is_none() {
            self.stand_anchor = Some(base_position(&self.state, &self.cfg.wheel));
        }
        if refused.is_none() || grow_anyway {
            let (r, t) =
                (self.state.rot * self.state.rot_imu_lidar, self.state.rot * self.state.pos_imu_lidar + self.state.pos);
            for p in &used {
                self.map.insert(r * p + t);
            }
        }
        self.scans_done += 1;
        if self.scans_done.is_multiple_of(10) {
            self.map.trim(&self.state.pos);
        }
        let pos_var = self.cov.fixed_view::<3, 3>(POS, POS).diagonal();
        let yaw_var = {
            // Attitude error is in the IMU frame; world yaw is its projection on world z.
            let z = self.state.rot.inverse() * Vector3::z();
            let c = self.cov.fixed_view::<3, 3>(ROT, ROT);
            (z.transpose() * c * z)[(0, 0)]
        };
        let unsure = uncertain_axes(&self.cfg.health, &pos_var);
        let health = verdict
            .map_or(Health::Tracking, |v| v.health)
            .with_wheels(wheel == WheelUse::Applied)
            .with_uncertainty(unsure.is_some());
        if health == Health::Degenerate {
            report.weak_axes |= unsure.unwrap_or(0);
        }
        ScanOutput {
            end_ns: scan.end_ns,
            lidar_pose: self.state.lidar_pose(),
            update: report,
            health,
            refused,
            pos_sigma_m: pos_sigma_m(&pos_var),
            yaw_sigma_deg: yaw_var.max(0.0).sqrt().to_degrees(),
            points_in: scan.points.len(),
            points_used: used.len(),
            voxel_m,
            map_points: self.map.len(),
            wheel,
            elapsed_us: started.us(),
        }
    }

    /// The wheels' mean twist over the window before `end_ns` into the state (after the
    /// deskew, which used the state the IMU alone gave, and before the scan's update, whose
    /// prior then holds it); older samples are dropped. Also says whether the wheels were
    /// applied and say the base's centre stands (then it is held, [`super::stand`]).
    fn wheel_step(&mut self, end_ns: u64) -> (WheelUse, bool) {
        let window_ns = self.cfg.wheel.window_ns;
        let twist = mean_twist(self.wheels.iter().copied(), end_ns, window_ns);
        while self.wheels.front().is_some_and(|s| s.t_ns + window_ns <= end_ns) {
            self.wheels.pop_front();
        }
        let level = self.level.take(twist);
        let (Some(twist), Some(held)) = (twist, self.held) else { return (WheelUse::None, false) };
        let used = wheel_update(&mut self.state, &mut self.cov, &held.gyro_rad_s, &twist, &self.cfg.wheel);
        if let (WheelUse::Applied, Some((mean_acc, acc_base))) = (used, level) {
            self.level_step(&mean_acc, &acc_base);
        }
        let standing = used == WheelUse::Applied && stands(&twist, &self.cfg.wheel);
        if let (true, Some(anchor)) = (standing, self.stand_anchor) {
            hold_update(&mut self.state, &mut self.cov, &anchor, &self.cfg.wheel);
        }
        (used, standing)
    }

    /// The tilt from the accelerometer's mean less the base's acceleration ([`super::level`]),
    /// where the wheels were just applied (they vouch for the base's acceleration).
    fn level_step(&mut self, mean_acc_m_s2: &Vector3<f64>, acc_base_m_s2: &Vector3<f64>) {
        let w = &self.cfg.wheel;
        if w.level_sigma_m_s2 <= 0.0 {
            return;
        }
        let (state, cov) = (&mut self.state, &mut self.cov);
        if level_update(state, cov, mean_acc_m_s2, acc_base_m_s2, &w.rot_imu_base, w.level_sigma_m_s2, w.gate_chi2) {
            self.level_updates.0 += 1;
        } else {
            self.level_updates.1 += 1;
        }
    }

    /// Scans whose tilt was measured from the accelerometer less the wheels, and those whose
    /// measurement failed the gate.
    pub fn level_counts(&self) -> (u64, u64) {
        self.level_updates
    }

    /// A lost filter no longer trusts its position, velocity or heading much: widen them so the
    /// next update may move the state as far as the map says.
    fn widen_uncertainty(&mut self) {
        for (at, var) in [(POS, 0.25), (VEL, 0.25), (ROT, 1e-3)] {
            for i in at..at + 3 {
                self.cov[(i, i)] = self.cov[(i, i)].max(var);
            }
        }
    }

    /// Whether the world acceleration over the still window stayed within what a still device may
    /// show: the configured limit, widened by what the filter does not know of its attitude
    /// (mostly), accelerometer bias and gravity. After a turn, a bias the still start took for
    /// gravity shows as a steady acceleration of up to twice the bias (development hall-18:
    /// 0.13 m/s^2 standing after a turn on the spot, docs/lio.md).
    fn quiet(&self) -> bool {
        let (limit, k) = (self.cfg.still_max_acc_m_s2, self.cfg.still_acc_sigmas);
        let widened = match self.held {
            Some(held) if limit > 0.0 && k > 0.0 => {
                (limit * limit + k * k * acc_world_var(&self.state, &self.cov, &held.acc_m_s2)).sqrt()
            }
            _ => limit,
        };
        self.still.quiet(widened, self.cfg.still_change_weight)
    }

    /// A scan that could not be matched: where the IMU has been still, the velocity is held at
    /// zero rather than integrated on from the IMU's noise.
    fn hold_if_still(&mut self, end_ns: u64) {
        let sigma = self.cfg.still_sigma_m_s;
        if sigma > 0.0 && self.still.is_still(end_ns) && zero_velocity_update(&mut self.state, &mut self.cov, sigma) {
            self.zero_velocity_updates += 1;
        }
    }

    /// Scans whose velocity was held at zero while still, so far.
    pub fn zero_velocity_updates(&self) -> u64 {
        self.zero_velocity_updates
    }

    /// Refused scans and times lost so far.
    pub fn health_counts(&self) -> (u64, u64) {
        (self.monitor.scans_refused, self.monitor.times_lost)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn inputs_on_another_clock_are_refused() {
        let mut lio = Lio::new(LioConfig::default());
        let mut out = Vec::new();
        let still = |t_ns, clock| ImuSample {
            t_ns,
            clock,
            gyro_rad_s: Vector3::zeros(),
            acc_m_s2: Vector3::new(0.0, 0.0, 9.81),
        };
        lio.push_imu(still(0, Clock::Ptp), &mut out);
        lio.push_imu(still(5_000_000, Clock::Host), &mut out);
        let wheel = WheelSample { t_ns: 6_000_000, clock: Clock::Device, vx_m_s: 0.0, vy_m_s: 0.0, wz_rad_s: 0.0 };
        lio.push_wheel(wheel);
        assert_eq!(lio.other_clock_inputs(), 2);
        lio.push_imu(still(10_000_000, Clock::Ptp), &mut out);
        assert_eq!(lio.other_clock_inputs(), 2, "the filter's own clock still enters");
    }

    #[test]
    fn non_finite_imu_is_refused_and_a_non_finite_state_starts_the_filter_over() {
        let mut lio = Lio::new(LioConfig::default());
        let mut out = Vec::new();
        let still = |t_ns| ImuSample {
            t_ns,
            clock: Clock::Ptp,
            gyro_rad_s: Vector3::zeros(),
            acc_m_s2: Vector3::new(0.0, 0.0, 9.81),
        };
        // Two seconds standing still initialise it.
        for k in 0..=400u64 {
            lio.push_imu(still(k * 5_000_000), &mut out);
        }
        assert_eq!(lio.status(), LioStatus::Running);
        let mut bad = still(2_010_000_000);
        bad.gyro_rad_s.x = f64::NAN;
        lio.push_imu(bad, &mut out);
        bad.acc_m_s2.z = f64::INFINITY;
        lio.push_imu(bad, &mut out);
        assert_eq!(lio.non_finite_counts(), (2, 0));
        assert!(lio.state().is_finite());
        // A state gone non-finite anyway: the next scan starts the filter over, no output.
        lio.state.vel.x = f64::NAN;
        let scan = LioScan { start_ns: 2_000_000_000, end_ns: 2_050_000_000, clock: Clock::Ptp, points: Vec::new() };
        lio.push_scan(scan, &mut out);
        lio.push_imu(still(2_100_000_000), &mut out);
        assert!(out.is_empty(), "{out:?}");
        assert_eq!(lio.non_finite_counts(), (2, 1));
        assert!(matches!(lio.status(), LioStatus::Initializing(_)));
        assert!(lio.state().is_finite());
    }

    /// A device standing 3 m before a wall for 3 s: the scans match and hold the distance to it,
    /// but not a slide along it. Once the scans start, the accelerometer reads `acc_y_m_s2` along
    /// the wall that the still start did not see (its bias shifting, a tilt the wall cannot show).
    /// Returns how far it slid, the holds, and the refusals.
    fn stand_before_a_wall(cfg: LioConfig, acc_y_m_s2: f64) -> (f64, u64, Vec<Refusal>) {
        use super::super::types::TimedPoint;
        let wall = |t_ns: u64| -> Vec<TimedPoint> {
            (0..40)
                .flat_map(|i| (0..20).map(move |k| (i, k)))
                .map(|(i, k)| TimedPoint { x_m: 3.0, y_m: -2.0 + 0.1 * i as f32, z_m: -1.0 + 0.1 * k as f32, t_ns })
                .collect()
        };
        let mut lio = Lio::new(cfg);
        let mut out = Vec::new();
        let mut t_ns = 0u64;
        let mut imu_until = |lio: &mut Lio, end_ns: u64, out: &mut Vec<ScanOutput>| {
            while t_ns <= end_ns {
                let acc_y = if t_ns > 2_000_000_000 { acc_y_m_s2 } else { 0.0 };
                let acc_m_s2 = Vector3::new(0.0, acc_y, 9.81);
                lio.push_imu(ImuSample { t_ns, clock: Clock::Ptp, gyro_rad_s: Vector3::zeros(), acc_m_s2 }, out);
                t_ns += 5_000_000;
            }
        };
        imu_until(&mut lio, 2_000_000_000, &mut out);
        for k in 0..30u64 {
            let start_ns = 2_000_000_000 + k * 100_000_000;
            let end_ns = start_ns + 100_000_000;
            lio.push_scan(
                LioScan { start_ns, end_ns, clock: Clock::Ptp, points: wall(start_ns + 50_000_000) },
                &mut out,
            );
            imu_until(&mut lio, end_ns, &mut out);
        }
        let refused: Vec<_> = out.iter().filter_map(|o| o.refused).collect();
        (lio.state().pos.y.abs(), lio.zero_velocity_updates(), refused)
    }

    #[test]
    fn a_still_device_whose_scans_match_holds_its_velocity_where_the_filter_sees_no_acceleration() {
        let cfg =
            |still_max_acc_m_s2: f64| LioConfig { still_max_acc_m_s2, scan_min_points: 1000, ..LioConfig::default() };
        let (held_m, holds, refused) = stand_before_a_wall(cfg(0.1), 0.08);
        assert!(refused.is_empty(), "every scan matched: {refused:?}");
        assert!(held_m < 0.1 && holds >= 20, "held within {held_m:.3} m, {holds} holds");
        let (slid_m, holds, _) = stand_before_a_wall(cfg(0.0), 0.08);
        assert!(slid_m > 0.25 && holds == 0, "without it the scans let it slide {slid_m:.3} m");
    }

    /// The same stand with a steady 0.13 m/s^2 along the wall, over the 0.1 limit: within what the
    /// filter does not know of its own attitude and bias, so held once the limit is widened by it.
    #[test]
    fn a_steady_acceleration_the_filter_is_unsure_of_is_held_once_the_limit_is_widened() {
        let cfg = |still_acc_sigmas: f64| LioConfig {
            still_max_acc_m_s2: 0.1,
            still_acc_sigmas,
            still_change_weight: 3.0,
            scan_min_points: 1000,
            ..LioConfig::default()
        };
        // The first scan or two may hold: their window still reaches back into the quiet start.
        let (slid_m, holds, _) = stand_before_a_wall(cfg(0.0), 0.13);
        assert!(slid_m > 0.4 && holds <= 2, "not widened: slid {slid_m:.3} m, {holds} holds");
        let (held_m, holds, refused) = stand_before_a_wall(cfg(1.0), 0.13);
        assert!(refused.is_empty(), "every scan matched: {refused:?}");
        assert!(held_m < 0.15 && holds >= 20, "held within {held_m:.3} m, {holds} holds");
    }

    #[test]
    fn a_still_device_with_nothing_to_match_holds_its_position() {
        use super::super::types::TimedPoint;
        // Where it ends after 3 s of empty scans (a wall inside the blind zone), standing still,
        // with a velocity of 0.2 m/s left in the state by the IMU's noise.
        let run = |still_sigma_m_s: f64| {
            let mut lio = Lio::new(LioConfig { still_sigma_m_s, ..LioConfig::default() });
            let mut out = Vec::new();
            let mut t_ns = 0u64;
            let mut imu_until = |lio: &mut Lio, end_ns: u64, out: &mut Vec<ScanOutput>| {
                while t_ns <= end_ns {
                    let s = ImuSample {
                        t_ns,
                        clock: Clock::Ptp,
                        gyro_rad_s: Vector3::zeros(),
                        acc_m_s2: Vector3::new(0.0, 0.0, 9.81),
                    };
                    lio.push_imu(s, out);
                    t_ns += 5_000_000;
                }
            };
            imu_until(&mut lio, 2_000_000_000, &mut out);
            // A wall 3 m ahead starts the map.
            let wall = (0..40)
                .flat_map(|i| (0..20).map(move |k| (i, k)))
                .map(|(i, k)| TimedPoint {
                    x_m: 3.0,
                    y_m: -2.0 + 0.1 * i as f32,
                    z_m: -1.0 + 0.1 * k as f32,
                    t_ns: 2_050_000_000,
                })
                .collect();
            let scan = LioScan { start_ns: 2_000_000_000, end_ns: 2_100_000_000, clock: Clock::Ptp, points: wall };
            lio.push_scan(scan, &mut out);
            imu_until(&mut lio, 2_100_000_000, &mut out);
            lio.state.vel = Vector3::new(0.2, 0.0, 0.0);
            let from = lio.state().pos;
            for k in 1..=30u64 {
                let start_ns = 2_000_000_000 + k * 100_000_000;
                let empty = LioScan { start_ns, end_ns: start_ns + 100_000_000, clock: Clock::Ptp, points: Vec::new() };
                lio.push_scan(empty, &mut out);
                imu_until(&mut lio, start_ns + 100_000_000, &mut out);
            }
            ((lio.state().pos - from).norm(), lio.zero_velocity_updates())
        };
        let (held_m, updates) = run(0.05);
        assert!(held_m < 0.15, "held within {held_m:.3} m");
        assert_eq!(updates, 30, "every empty scan");
        let (ran_m, updates) = run(0.0);
        assert!(ran_m > 0.55, "without it, the velocity carries on: {ran_m:.3} m");
        assert_eq!(updates, 0);
    }
}
