//! The LIO's settings as a TOML file (`config/lio.toml`): every key optional, unknown keys refused.
//! [`LioFile::to_config`] turns them into the [`LioConfig`] the filter runs with.

use super::health::HealthConfig;
use super::init::{DEFAULT_MAX_ACC_STD_M_S2, DEFAULT_MAX_GYRO_STD_RAD_S};
use super::odometry::LioConfig;
use super::propagate::ImuNoise;
use super::update::UpdateConfig;
use super::wheel::WheelFusion;
use crate::PipelineError;
use nalgebra::{Rotation3, Vector3};
use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LioFile {
    pub imu: ImuSection,
    pub extrinsics: ExtrinsicsSection,
    pub scan: ScanSection,
    pub update: UpdateSection,
    pub map: MapSection,
    pub health: HealthConfig,
    pub wheels: WheelsSection,
}

/// Which IMU drives the filter and how its samples reach the LiDAR's clock.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ImuSection {
    /// `internal`: the Avia's own IMU packets; `external`: a serial IMU given to `starc lio --imu`.
    pub source: ImuSource,
    /// Added to every IMU time stamp to put it on the LiDAR's clock (an external IMU's latency).
    pub time_offset_ns: i64,
    /// Length of the still window that initialization needs.
    pub init_window_s: f64,
    /// Largest gyro and accelerometer spread (standard deviation) a still window may show.
    pub init_max_gyro_std_rad_s: f64,
    pub init_max_acc_std_m_s2: f64,
    /// A scan too sparse to match while the IMU has been still this long (the same spreads as
    /// the still start) holds the velocity at zero, within `still_sigma_m_s` (0: never;
    /// `lio::still`).
    pub still_window_s: f64,
    pub still_sigma_m_s: f64,
    /// A scan that matched holds the velocity too where the IMU has been still and the world
    /// acceleration the filter sees (gravity and bias taken out) stayed under this RMS over the
    /// still window (0: only scans too sparse to match).
    pub still_max_acc_m_s2: f64,
    /// That limit is widened by this many sigmas of the world acceleration's error the filter
    /// expects from its own attitude, accelerometer bias and gravity (0: not widened): a bias the
    /// still start took for gravity leaks into the world acceleration once the device has turned.
    pub still_acc_sigmas: f64,
    /// How much the world acceleration's change over the still window weighs against its mean
    /// (1: the plain RMS). The filter's own errors are steady over half a second; a walk that
    /// sets off ramps up.
    pub still_change_weight: f64,
    /// The accelerometer's turn-on bias (1 sigma) that a still start takes for gravity: > 0
    /// ties the two in the filter's start (`lio::start`), 0 starts them apart.
    pub acc_bias_sigma_m_s2: f64,
    /// Continuous-time noise densities (per sqrt(s)).
    pub gyro_noise_rad_s: f64,
    pub acc_noise_m_s2: f64,
    pub gyro_bias_walk: f64,
    pub acc_bias_walk: f64,
}

impl Default for ImuSection {
    fn default() -> Self {
        let noise = ImuNoise::default();
        Self {
            source: ImuSource::Internal,
            time_offset_ns: 0,
            init_window_s: 1.0,
            init_max_gyro_std_rad_s: DEFAULT_MAX_GYRO_STD_RAD_S,
            init_max_acc_std_m_s2: DEFAULT_MAX_ACC_STD_M_S2,
            still_window_s: 0.5,
            still_sigma_m_s: 0.05,
            still_max_acc_m_s2: 0.0,
            still_acc_sigmas: 0.0,
            still_change_weight: 1.0,
            acc_bias_sigma_m_s2: 0.0,
            gyro_noise_rad_s: noise.gyro_rad_s,
            acc_noise_m_s2: noise.acc_m_s2,
            gyro_bias_walk: noise.gyro_bias_walk,
            acc_bias_walk: noise.acc_bias_walk,
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ImuSource {
    Internal,
    External,
}

/// `T_imu_lidar`: where the LiDAR sits in the IMU's frame (maps LiDAR points into the IMU frame).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ExtrinsicsSection {
    pub translation_m: [f64; 3],
    /// Roll, pitch, yaw (fixed axes x, then y, then z), degrees.
    pub rotation_rpy_deg: [f64; 3],
}

impl Default for ExtrinsicsSection {
    /// The Avia's internal IMU: axes aligned with the LiDAR, the LiDAR's origin at
    /// (0.04165, 0.02326, -0.0284) m in the IMU frame (Livox's published offset).
    fn default() -> Self {
        Self { translation_m: [0.04165, 0.02326, -0.0284], rotation_rpy_deg: [0.0; 3] }
    }
}

/// The base's wheel odometry as a measurement (used only when wheel samples come: the robot).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct WheelsSection {
    /// The base's frame (x forward, y left, z up, at its centre on the floor) in the IMU's frame.
    pub translation_m: [f64; 3],
    pub rotation_rpy_deg: [f64; 3],
    /// Planar velocity noise, 1 sigma: `sigma_m_s + sigma_rel * speed` (slip grows with speed).
    pub sigma_m_s: f64,
    pub sigma_rel: f64,
    /// Noise of "the base does not move along its own z".
    pub sigma_vz_m_s: f64,
    /// Wheel samples this long before a scan's end are averaged into its measurement.
    pub window_ms: f64,
    /// Huber threshold (normalised innovation) per axis, and the chi-square gate (3 dof) past
    /// which a measurement is not used: slip, a wheel in the air.
    pub huber_k: f64,
    pub gate_chi2: f64,
    /// Noise (1 sigma, per axis, m/s²) of the tilt measured once per scan from the
    /// accelerometer's mean less the base's acceleration from the wheels (`lio::level`); 0: not
    /// measured. Default 0.1.
    pub level_sigma_m_s2: f64,
    /// While the wheels say the base's centre stands (planar speed at most
    /// `hold_max_speed_m_s`, turning in place allowed), hold the centre where it stood with this
    /// noise (1 sigma per axis, m; `lio::stand`); 0: not held.
    pub hold_sigma_m: f64,
    pub hold_max_speed_m_s: f64,
}

impl Default for WheelsSection {
    fn default() -> Self {
        let w = WheelFusion::default();
        Self {
            translation_m: w.pos_imu_base.into(),
            rotation_rpy_deg: [0.0; 3],
            sigma_m_s: w.sigma_m_s,
            sigma_rel: w.sigma_rel,
            sigma_vz_m_s: w.sigma_vz_m_s,
            window_ms: w.window_ns as f64 * 1e-6,
            huber_k: w.huber_k,
            gate_chi2: w.gate_chi2,
            level_sigma_m_s2: w.level_sigma_m_s2,
            hold_sigma_m: w.hold_sigma_m,
            hold_max_speed_m_s: w.hold_max_speed_m_s,
        }
    }
}

impl WheelsSection {
    fn to_fusion(&self) -> Result<WheelFusion, String> {
        for (name, v) in [
            ("wheels.sigma_m_s", self.sigma_m_s),
            ("wheels.sigma_vz_m_s", self.sigma_vz_m_s),
            ("wheels.window_ms", self.window_ms),
            ("wheels.huber_k", self.huber_k),
            ("wheels.gate_chi2", self.gate_chi2),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(format!("{name} must be a positive number, not {v}"));
            }
        }
        for (name, v) in [
            ("wheels.sigma_rel", self.sigma_rel),
            ("wheels.level_sigma_m_s2", self.level_sigma_m_s2),
            ("wheels.hold_sigma_m", self.hold_sigma_m),
            ("wheels.hold_max_speed_m_s", self.hold_max_speed_m_s),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(format!("{name} must be 0 or more, not {v}"));
            }
        }
        let [r, p, y] = self.rotation_rpy_deg.map(f64::to_radians);
        Ok(WheelFusion {
            rot_imu_base: Rotation3::from_euler_angles(r, p, y),
            pos_imu_base: Vector3::from(self.translation_m),
            sigma_m_s: self.sigma_m_s,
            sigma_rel: self.sigma_rel,
            sigma_vz_m_s: self.sigma_vz_m_s,
            window_ns: (self.window_ms * 1e6) as u64,
            huber_k: self.huber_k,
            gate_chi2: self.gate_chi2,
            level_sigma_m_s2: self.level_sigma_m_s2,
            hold_sigma_m: self.hold_sigma_m,
            hold_max_speed_m_s: self.hold_max_speed_m_s,
        })
    }
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ScanSection {
    /// Scan period: points are grouped into scans of this length.
    pub period_ms: f64,
    /// Points closer than this are dropped (the platform itself, the Avia's 1 m blind zone).
    pub blind_m: f64,
    /// Voxel size the de-skewed scan is reduced to (one centroid per voxel) before the update.
    pub voxel_m: f64,
    /// At most this many of those centroids enter the update (evenly spread); 0: all.
    pub max_points: usize,
    /// A scan left with fewer centroids than this is reduced again on voxels half the size, down
    /// to `min_voxel_m`: a small view keeps its few planes (0: never).
    pub min_points: usize,
    pub min_voxel_m: f64,
}

impl Default for ScanSection {
    fn default() -> Self {
        let c = LioConfig::default();
        Self {
            period_ms: 100.0,
            blind_m: c.blind_m,
            voxel_m: c.scan_voxel_m,
            max_points: c.max_points,
            min_points: c.scan_min_points,
            min_voxel_m: c.scan_min_voxel_m,
        }
    }
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct UpdateSection {
    pub max_iterations: usize,
    /// Variance of one point-to-plane residual (m^2).
    pub residual_var_m2: f64,
    /// Map points a plane is fitted to, and how far they may be.
    pub neighbours: usize,
    pub max_neighbour_dist_m: f64,
    /// Largest distance of a neighbour from its fitted plane.
    pub max_plane_dev_m: f64,
    /// Eigen-directions of the update's normalised information (the degeneracy index's
    /// eigenvalues, 0 to 1/3) below this take no update: the IMU carries them.
    pub min_direction_info: f64,
    /// A scan whose residual RMS comes out above this is updated again with its residual variance
    /// grown by the square of the ratio (0: never).
    pub fit_rms_ref_m: f64,
}

impl Default for UpdateSection {
    fn default() -> Self {
        let u = UpdateConfig::default();
        Self {
            max_iterations: u.max_iterations,
            residual_var_m2: u.residual_var_m2,
            neighbours: u.neighbours,
            max_neighbour_dist_m: u.max_neighbour_dist_m,
            max_plane_dev_m: u.max_plane_dev_m,
            min_direction_info: u.min_direction_info,
            fit_rms_ref_m: u.fit_rms_ref_m,
        }
    }
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MapSection {
    pub voxel_m: f64,
    pub points_per_voxel: usize,
    /// A new point closer than this to one already in its voxel is not added.
    pub min_spacing_m: f64,
    /// Voxels farther than this from the sensor are dropped.
    pub radius_m: f64,
}

impl Default for MapSection {
    fn default() -> Self {
        let c = LioConfig::default();
        Self {
            voxel_m: c.map_voxel_m,
            points_per_voxel: c.map_points_per_voxel,
            min_spacing_m: c.map_min_spacing_m,
            radius_m: c.map_radius_m,
        }
    }
}

impl LioFile {
    pub fn from_toml(text: &str) -> Result<Self, PipelineError> {
        let file: Self =
            toml::from_str(text).map_err(|e| PipelineError::BadFile { format: "LIO config", reason: e.to_string() })?;
        file.to_config()?;
        Ok(file)
    }

    /// The filter's settings; refuses values it cannot run with.
    pub fn to_config(&self) -> Result<LioConfig, PipelineError> {
        let bad = |reason: String| PipelineError::BadFile { format: "LIO config", reason };
        let positive = [
            ("imu.init_window_s", self.imu.init_window_s),
            ("scan.period_ms", self.scan.period_ms),
            ("scan.voxel_m", self.scan.voxel_m),
            ("scan.min_voxel_m", self.scan.min_voxel_m),
            ("update.residual_var_m2", self.update.residual_var_m2),
            ("update.max_neighbour_dist_m", self.update.max_neighbour_dist_m),
            ("map.voxel_m", self.map.voxel_m),
            ("map.radius_m", self.map.radius_m),
            ("imu.still_window_s", self.imu.still_window_s),
        ];
        for (name, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return Err(bad(format!("{name} must be a positive number, not {v}")));
            }
        }
        let info = self.update.min_direction_info;
        if !(info.is_finite() && (0.0..=1.0 / 3.0).contains(&info)) {
            return Err(bad(format!("update.min_direction_info must be between 0 and 1/3, not {info}")));
        }
        if self.update.neighbours < 3 || self.update.max_iterations == 0 || self.map.points_per_voxel == 0 {
            return Err(bad("update.neighbours must be at least 3, update.max_iterations and \
                 map.points_per_voxel at least 1"
                .into()));
        }
        self.health.validate().map_err(bad)?;
        let non_negative = [
            ("imu.still_sigma_m_s", self.imu.still_sigma_m_s),
            ("imu.still_max_acc_m_s2", self.imu.still_max_acc_m_s2),
            ("imu.still_acc_sigmas", self.imu.still_acc_sigmas),
            ("imu.still_change_weight", self.imu.still_change_weight),
            ("update.fit_rms_ref_m", self.update.fit_rms_ref_m),
            ("imu.acc_bias_sigma_m_s2", self.imu.acc_bias_sigma_m_s2),
        ];
        for (name, v) in non_negative {
            if !(v.is_finite() && v >= 0.0) {
                return Err(bad(format!("{name} must be a number >= 0, not {v}")));
            }
        }
        let [r, p, y] = self.extrinsics.rotation_rpy_deg.map(f64::to_radians);
        let noise = ImuNoise {
            gyro_rad_s: self.imu.gyro_noise_rad_s,
            acc_m_s2: self.imu.acc_noise_m_s2,
            gyro_bias_walk: self.imu.gyro_bias_walk,
            acc_bias_walk: self.imu.acc_bias_walk,
        };
        let defaults = UpdateConfig::default();
        Ok(LioConfig {
            rot_imu_lidar: Rotation3::from_euler_angles(r, p, y),
            pos_imu_lidar: Vector3::from(self.extrinsics.translation_m),
            init_window_ns: (self.imu.init_window_s * 1e9) as u64,
            init_max_gyro_std_rad_s: self.imu.init_max_gyro_std_rad_s,
            init_max_acc_std_m_s2: self.imu.init_max_acc_std_m_s2,
            still_window_ns: (self.imu.still_window_s * 1e9) as u64,
            still_sigma_m_s: self.imu.still_sigma_m_s,
            still_max_acc_m_s2: self.imu.still_max_acc_m_s2,
            still_acc_sigmas: self.imu.still_acc_sigmas,
            still_change_weight: self.imu.still_change_weight,
            acc_bias_sigma_m_s2: self.imu.acc_bias_sigma_m_s2,
            noise,
            update: UpdateConfig {
                max_iterations: self.update.max_iterations,
                residual_var_m2: self.update.residual_var_m2,
                neighbours: self.update.neighbours,
                max_neighbour_dist_m: self.update.max_neighbour_dist_m,
                max_plane_dev_m: self.update.max_plane_dev_m,
                min_direction_info: self.update.min_direction_info,
                fit_rms_ref_m: self.update.fit_rms_ref_m,
                ..defaults
            },
            scan_voxel_m: self.scan.voxel_m,
            blind_m: self.scan.blind_m,
            max_points: self.scan.max_points,
            scan_min_points: self.scan.min_points,
            scan_min_voxel_m: self.scan.min_voxel_m,
            map_voxel_m: self.map.voxel_m,
            map_points_per_voxel: self.map.points_per_voxel,
            map_min_spacing_m: self.map.min_spacing_m,
            map_radius_m: self.map.radius_m,
            health: self.health.clone(),
            stopwatch: crate::timing::Stopwatch::Wall,
            wheel: self.wheels.to_fusion().map_err(bad)?,
        })
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn shipped_config_is_the_defaults() {
        let text = include_str!("../../../config/lio.toml");
        let file = LioFile::from_toml(text).unwrap();
        assert_eq!(file, LioFile::default());
        assert_eq!(file.to_config().unwrap(), LioConfig::default());
    }

    #[test]
    fn external_example_loads() {
        let text = include_str!("../../../config/lio_external_imu.toml");
        let file = LioFile::from_toml(text).unwrap();
        assert_eq!(file.imu.source, ImuSource::External);
    }

    #[test]
    fn unknown_keys_and_bad_values_are_refused() {
        assert!(LioFile::from_toml("[map]\nvoxel = 0.5\n").is_err());
        let e = LioFile::from_toml("[scan]\nvoxel_m = -1.0\n").unwrap_err().to_string();
        assert!(e.contains("scan.voxel_m"), "{e}");
        assert!(LioFile::from_toml("[imu]\nsource = \"gps\"\n").is_err());
        let e = LioFile::from_toml("[imu]\nacc_bias_sigma_m_s2 = -0.05\n").unwrap_err().to_string();
        assert!(e.contains("imu.acc_bias_sigma_m_s2"), "{e}");
    }
}
