//! The sensor's errors on top of the true motion: a constant bias and white noise per axis.

use crate::imu::source::Motion;
use crate::rng::SplitMix64;
use serde::{Deserialize, Serialize};

/// Bias and noise of the mock's gyro and accelerometer (defaults near a 3DM-GX5's datasheet at
/// 100-200 Hz: 0.005 rad/s and 0.01 m/s^2 of noise per sample).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SensorModel {
    pub gyro_bias_rad_s: [f64; 3],
    pub accel_bias_m_s2: [f64; 3],
    /// Standard deviation of each sample's gyro noise.
    pub gyro_noise_rad_s: f64,
    /// Standard deviation of each sample's accelerometer noise.
    pub accel_noise_m_s2: f64,
}

impl Default for SensorModel {
    fn default() -> Self {
        Self {
            gyro_bias_rad_s: [0.002, -0.001, 0.0005],
            accel_bias_m_s2: [0.02, -0.01, 0.03],
            gyro_noise_rad_s: 0.005,
            accel_noise_m_s2: 0.01,
        }
    }
}

impl SensorModel {
    /// A perfect sensor.
    pub fn ideal() -> Self {
        Self { gyro_bias_rad_s: [0.0; 3], accel_bias_m_s2: [0.0; 3], gyro_noise_rad_s: 0.0, accel_noise_m_s2: 0.0 }
    }

    /// What the sensor reads of `m`.
    pub fn measure(&self, m: &Motion, rng: &mut SplitMix64) -> Motion {
        let mut out = *m;
        for i in 0..3 {
            out.gyro_rad_s[i] += self.gyro_bias_rad_s[i] + self.gyro_noise_rad_s * rng.normal();
            out.accel_m_s2[i] += self.accel_bias_m_s2[i] + self.accel_noise_m_s2 * rng.normal();
        }
        out
    }
}
