//! Static initialization: gravity direction and gyro bias from a still start.

use super::types::ImuSample;
use nalgebra::{Rotation3, Vector3};

/// Where initialization stands.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum InitStatus {
    /// Still collecting the static window.
    Collecting,
    /// The IMU moved during the window (its gyro or accelerometer spread was too large); the
    /// window restarts from the next sample. Counts the restarts so far.
    MotionDetected {
        restarts: u32,
    },
    Done,
}

/// What a still start tells: the IMU's attitude against gravity, gravity's magnitude, gyro bias.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InitResult {
    /// Rotation from the IMU frame to a world frame with z up (yaw left as the IMU's).
    pub rot_world_imu: Rotation3<f64>,
    pub gravity_m_s2: f64,
    pub bias_gyro: Vector3<f64>,
    /// The gyro's spread over the window: how far off `bias_gyro` may be (a rig held in hand
    /// turns a little while it counts as still).
    pub gyro_std_rad_s: f64,
    pub end_ns: u64,
}

/// Largest gyro and accelerometer spreads (standard deviations) of a still start, by default: a
/// rig held in hand sways a degree or two (about 0.04 rad/s) and counts; walking does not.
pub const DEFAULT_MAX_GYRO_STD_RAD_S: f64 = 0.06;
pub const DEFAULT_MAX_ACC_STD_M_S2: f64 = 0.2;

/// Means and spreads (standard deviations about the means) of IMU samples.
pub(super) struct Spread {
    pub mean_gyro: Vector3<f64>,
    pub mean_acc: Vector3<f64>,
    pub gyro_std: f64,
    pub acc_std: f64,
}

/// The means and spreads of `samples` (zeros for none).
pub(super) fn spread<'a>(samples: impl IntoIterator<Item = &'a ImuSample> + Copy) -> Spread {
    let n = samples.into_iter().count().max(1) as f64;
    let mean_gyro = samples.into_iter().map(|s| s.gyro_rad_s).sum::<Vector3<f64>>() / n;
    let mean_acc = samples.into_iter().map(|s| s.acc_m_s2).sum::<Vector3<f64>>() / n;
    let std = |f: fn(&ImuSample) -> Vector3<f64>, m: &Vector3<f64>| {
        (samples.into_iter().map(|s| (f(s) - m).norm_squared()).sum::<f64>() / n).sqrt()
    };
    Spread { gyro_std: std(|s| s.gyro_rad_s, &mean_gyro), acc_std: std(|s| s.acc_m_s2, &mean_acc), mean_gyro, mean_acc }
}

/// Gathers the first `window_ns` of IMU data and checks it was static.
#[derive(Clone, Debug)]
pub struct StaticInit {
    window_ns: u64,
    /// Largest allowed standard deviations within the window.
    max_gyro_std_rad_s: f64,
    max_acc_std_m_s2: f64,
    samples: Vec<ImuSample>,
    restarts: u32,
}

impl StaticInit {
    pub fn new(window_ns: u64) -> Self {
        Self::with_limits(window_ns, DEFAULT_MAX_GYRO_STD_RAD_S, DEFAULT_MAX_ACC_STD_M_S2)
    }

    /// A window that counts as still while the gyro and accelerometer spreads (standard
    /// deviations) stay within these.
    pub fn with_limits(window_ns: u64, max_gyro_std_rad_s: f64, max_acc_std_m_s2: f64) -> Self {
        Self { window_ns, max_gyro_std_rad_s, max_acc_std_m_s2, samples: Vec::new(), restarts: 0 }
    }

    /// Adds one sample; returns the result once a static window is complete.
    pub fn push(&mut self, imu: &ImuSample) -> (InitStatus, Option<InitResult>) {
        self.samples.push(*imu);
        let first = self.samples.first().map_or(imu.t_ns, |s| s.t_ns);
        if imu.t_ns.saturating_sub(first) < self.window_ns {
            return (self.status(), None);
        }
        let Spread { mean_gyro: mean_g, mean_acc: mean_a, gyro_std, acc_std } = spread(&self.samples);
        if gyro_std > self.max_gyro_std_rad_s || acc_std > self.max_acc_std_m_s2 || mean_a.norm() < 1.0 {
            self.restarts += 1;
            self.samples.clear();
            return (self.status(), None);
        }
        let rot_world_imu = Rotation3::rotation_between(&mean_a, &Vector3::z()).unwrap_or_else(|| {
            // Upside down: any half turn about a horizontal axis.
            Rotation3::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI)
        });
        let result = InitResult {
            rot_world_imu,
            gravity_m_s2: mean_a.norm(),
            bias_gyro: mean_g,
            gyro_std_rad_s: gyro_std,
            end_ns: imu.t_ns,
        };
        (InitStatus::Done, Some(result))
    }

    fn status(&self) -> InitStatus {
        if self.restarts == 0 {
            InitStatus::Collecting
        } else {
            InitStatus::MotionDetected { restarts: self.restarts }
        }
    }
}

#[cfg(test)]
#[allow(clippy::expect_used)]
mod tests {
    use super::*;

    fn sample(t_ns: u64, gyro: f64) -> ImuSample {
        ImuSample {
            t_ns,
            clock: starc_time::Clock::Ptp,
            gyro_rad_s: Vector3::new(0.01, gyro, 0.0),
            acc_m_s2: Vector3::new(0.0, 9.81 * 0.6, 9.81 * 0.8),
        }
    }

    #[test]
    fn still_start_gives_gravity_and_bias_and_motion_is_reported() {
        let mut init = StaticInit::new(1_000_000_000);
        let mut out = None;
        for k in 0..600u64 {
            // Shaking for the first 100 samples, then still.
            let gyro = if k < 100 && k % 2 == 0 { 0.5 } else { 0.0 };
            let (status, r) = init.push(&sample(k * 5_000_000, gyro));
            if k == 250 {
                assert_eq!(status, InitStatus::MotionDetected { restarts: 1 });
            }
            if r.is_some() {
                out = r;
                break;
            }
        }
        let r = out.expect("initializes once still");
        assert!((r.gravity_m_s2 - 9.81).abs() < 1e-9);
        assert!((r.bias_gyro - Vector3::new(0.01, 0.0, 0.0)).norm() < 1e-9);
        let up = r.rot_world_imu * Vector3::new(0.0, 0.6, 0.8);
        assert!((up - Vector3::z()).norm() < 1e-9);
    }
}
