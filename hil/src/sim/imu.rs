//! IMUs that measure the simulated motion: true angular rate and specific force at the IMU's
//! mounting point (from the trajectory's derivatives), plus turn-on bias, bias random walk and
//! white noise from datasheet densities.

use crate::rng::SplitMix64;
use crate::sim::motion::Motion;
use crate::sim::scenario::ImuNoise;
use crate::sim::shapes::V3;
use nalgebra::Isometry3;
use std::sync::Arc;

/// Standard gravity, as the Livox protocol's g.
pub const GRAVITY_M_S2: f64 = 9.80665;
/// Step of the central differences (s): exact to about 1e-5 relative for gait frequencies.
const DIFF_STEP_S: f64 = 1e-3;

/// The true inertial quantities at one instant, in the IMU frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrueInertial {
    pub gyro_rad_s: V3,
    /// Specific force (what an accelerometer at rest reads: +g up).
    pub accel_m_s2: V3,
}

/// The IMU's pose in the world at `t` and its true measurements.
pub fn true_inertial(motion: &dyn Motion, lidar_imu: &Isometry3<f64>, t: f64) -> TrueInertial {
    let pose = |t: f64| motion.lidar_pose(t) * lidar_imu;
    let h = DIFF_STEP_S;
    let (before, now, after) = (pose(t - h), pose(t), pose(t + h));
    let acc_w = (after.translation.vector - 2.0 * now.translation.vector + before.translation.vector) / (h * h);
    let delta = before.rotation.inverse() * after.rotation;
    let gyro = delta.scaled_axis() / (2.0 * h);
    let f_w = acc_w + V3::new(0.0, 0.0, GRAVITY_M_S2);
    TrueInertial { gyro_rad_s: gyro, accel_m_s2: now.rotation.inverse() * f_w }
}

/// A noisy IMU on a moving platform.
pub struct ImuSim {
    motion: Arc<dyn Motion>,
    /// The IMU's pose in the LiDAR frame.
    lidar_imu: Isometry3<f64>,
    noise: ImuNoise,
    rate_hz: f64,
    /// IMU stamp minus true time.
    time_offset_s: f64,
    rng: SplitMix64,
    gyro_bias: V3,
    accel_bias: V3,
    last_t: Option<f64>,
}

/// One measurement.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ImuMeasurement {
    pub gyro_rad_s: V3,
    pub accel_m_s2: V3,
}

impl ImuSim {
    pub fn new(
        motion: Arc<dyn Motion>,
        lidar_imu: Isometry3<f64>,
        noise: ImuNoise,
        rate_hz: f64,
        time_offset_s: f64,
        seed: u64,
    ) -> Self {
        let mut rng = SplitMix64::new(seed);
        let mut draw = |s: f64| V3::new(rng.normal() * s, rng.normal() * s, rng.normal() * s);
        let gyro_bias = draw(noise.gyro_bias_sigma_rad_s);
        let accel_bias = draw(noise.accel_bias_sigma_m_s2);
        Self { motion, lidar_imu, noise, rate_hz, time_offset_s, rng, gyro_bias, accel_bias, last_t: None }
    }

    /// The biases now (ground truth for the LIO's bias estimates).
    pub fn biases(&self) -> (V3, V3) {
        (self.gyro_bias, self.accel_bias)
    }

    /// The measurement stamped `t` (s); calls must come in time order.
    pub fn sample(&mut self, t: f64) -> ImuMeasurement {
        let dt = self.last_t.map_or(0.0, |l| (t - l).max(0.0));
        self.last_t = Some(t);
        let n = self.noise;
        let (gw, aw) = (n.gyro_bias_walk_rad_s2_sqrt_hz * dt.sqrt(), n.accel_bias_walk_m_s3_sqrt_hz * dt.sqrt());
        let walk = |rng: &mut SplitMix64, s: f64| V3::new(rng.normal() * s, rng.normal() * s, rng.normal() * s);
        self.gyro_bias += walk(&mut self.rng, gw);
        self.accel_bias += walk(&mut self.rng, aw);
        let truth = true_inertial(&*self.motion, &self.lidar_imu, t - self.time_offset_s);
        let root_rate = self.rate_hz.sqrt();
        let gyro_noise = walk(&mut self.rng, n.gyro_noise_rad_s_sqrt_hz * root_rate);
        let accel_noise = walk(&mut self.rng, n.accel_noise_m_s2_sqrt_hz * root_rate);
        ImuMeasurement {
            gyro_rad_s: truth.gyro_rad_s + self.gyro_bias + gyro_noise,
            accel_m_s2: truth.accel_m_s2 + self.accel_bias + accel_noise,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::motion::pose_xyz_rpy;

    /// A platform spinning at 0.5 rad/s about z on a circle of radius 2 m.
    struct Carousel;
    impl Motion for Carousel {
        fn lidar_pose(&self, t: f64) -> Isometry3<f64> {
            let a = 0.5 * t;
            pose_xyz_rpy(V3::new(2.0 * a.cos(), 2.0 * a.sin(), 1.0), 0.0, 0.0, a + std::f64::consts::FRAC_PI_2)
        }
    }

    #[test]
    fn rate_and_centripetal_force() {
        let truth = true_inertial(&Carousel, &Isometry3::identity(), 3.0);
        assert!((truth.gyro_rad_s - V3::new(0.0, 0.0, 0.5)).norm() < 1e-6, "{:?}", truth.gyro_rad_s);
        // Centripetal 0.5^2 * 2 = 0.5 m/s^2 towards the centre; facing along the tangent, the
        // centre is to the left (+y).
        assert!((truth.accel_m_s2 - V3::new(0.0, 0.5, GRAVITY_M_S2)).norm() < 1e-5, "{:?}", truth.accel_m_s2);
    }

    #[test]
    fn noise_matches_the_density() {
        struct Still;
        impl Motion for Still {
            fn lidar_pose(&self, _: f64) -> Isometry3<f64> {
                Isometry3::identity()
            }
        }
        let mut noise = ImuNoise::BMI088;
        noise.gyro_bias_walk_rad_s2_sqrt_hz = 0.0;
        noise.accel_bias_walk_m_s3_sqrt_hz = 0.0;
        let mut imu = ImuSim::new(Arc::new(Still), Isometry3::identity(), noise, 200.0, 0.0, 3);
        let (gb, _) = imu.biases();
        let xs: Vec<f64> = (0..20_000).map(|i| imu.sample(i as f64 / 200.0).gyro_rad_s.x - gb.x).collect();
        let sd = (xs.iter().map(|x| x * x).sum::<f64>() / xs.len() as f64).sqrt();
        let want = noise.gyro_noise_rad_s_sqrt_hz * 200f64.sqrt();
        assert!((sd / want - 1.0).abs() < 0.05, "{sd} vs {want}");
    }
}
