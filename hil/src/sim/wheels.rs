//! Wheel odometry of the simulated base: wheel rates from the base's true body velocity through
//! the base driver's own kinematics (`starc_base::kinematics`), with slip; the odometry
//! integrates the body velocity the forward kinematics recovers from the measured rates, as the
//! real base driver does.

use crate::error::{HilError, Result};
use crate::rng::SplitMix64;
use crate::sim::motion::RobotMotion;
use crate::sim::scenario::WheelLayout;
use starc_base::kinematics::{Kinematics, KinematicsConfig, Twist};

/// Default geometry of each layout: a small omni base (0.05 m wheels on a 0.2 m arm) and a
/// mecanum base (0.076 m wheels, lx = ly = 0.2 m).
pub fn default_geometry(layout: WheelLayout) -> KinematicsConfig {
    match layout {
        WheelLayout::Omni3 => {
            KinematicsConfig::Omni3 { wheel_radius_m: 0.05, center_to_wheel_m: 0.2, wheel_angles_deg: None }
        }
        WheelLayout::Omni4 => {
            KinematicsConfig::Omni4 { wheel_radius_m: 0.05, center_to_wheel_m: 0.2, wheel_angles_deg: None }
        }
        WheelLayout::Mecanum => {
            KinematicsConfig::Mecanum { wheel_radius_m: 0.076, half_length_m: 0.2, half_width_m: 0.2 }
        }
    }
}

/// Slip: multiplicative (1 sigma) per wheel reading.
const SLIP_SIGMA: f64 = 0.02;

/// Integrates the base's wheel odometry.
pub struct WheelOdometry {
    kinematics: Kinematics,
    rng: SplitMix64,
    pose: [f64; 3],
    last_t: Option<f64>,
}

/// One odometry reading.
#[derive(Clone, Debug, PartialEq)]
pub struct WheelReading {
    pub wheel_rad_s: Vec<f64>,
    /// Body velocity from the measured rates (vx, vy m/s; wz rad/s).
    pub body: [f64; 3],
    /// Integrated pose (x, y, yaw) in the odometry frame (the start pose is the origin).
    pub pose: [f64; 3],
}

impl WheelOdometry {
    pub fn new(layout: WheelLayout, seed: u64) -> Result<Self> {
        let kinematics =
            Kinematics::new(&default_geometry(layout)).map_err(|e| HilError::config("robot.wheels", e.to_string()))?;
        Ok(Self { kinematics, rng: SplitMix64::new(seed), pose: [0.0; 3], last_t: None })
    }

    pub fn wheels(&self) -> usize {
        self.kinematics.wheel_count()
    }

    /// The reading at `t` (s); calls in time order.
    pub fn sample(&mut self, motion: &RobotMotion, t: f64) -> WheelReading {
        let h = 1e-3;
        let (a, b) = (motion.state_at(t - h), motion.state_at(t + h));
        let now = motion.state_at(t);
        let (vxw, vyw) = ((b.x - a.x) / (2.0 * h), (b.y - a.y) / (2.0 * h));
        let wz = (b.yaw_rad - a.yaw_rad) / (2.0 * h);
        let (s, c) = now.yaw_rad.sin_cos();
        let body = [c * vxw + s * vyw, -s * vxw + c * vyw, wz];
        let rates: Vec<f64> = self
            .kinematics
            .wheel_rates(Twist::new(body[0], body[1], body[2]))
            .into_iter()
            .map(|w| w * (1.0 + SLIP_SIGMA * self.rng.normal()))
            .collect();
        let measured = self.kinematics.body_twist(&rates).map_or([0.0; 3], |t| [t.vx_m_s, t.vy_m_s, t.wz_rad_s]);
        let dt = self.last_t.map_or(0.0, |l| t - l);
        self.last_t = Some(t);
        // Midpoint integration of the planar motion.
        let yaw_mid = self.pose[2] + 0.5 * measured[2] * dt;
        let (sm, cm) = yaw_mid.sin_cos();
        self.pose[0] += (cm * measured[0] - sm * measured[1]) * dt;
        self.pose[1] += (sm * measured[0] + cm * measured[1]) * dt;
        self.pose[2] += measured[2] * dt;
        WheelReading { wheel_rad_s: rates, body: measured, pose: self.pose }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_layout_builds_and_the_front_omni_wheel_turns_backwards() {
        for layout in [WheelLayout::Omni3, WheelLayout::Omni4, WheelLayout::Mecanum] {
            assert!(WheelOdometry::new(layout, 1).is_ok(), "{layout:?}");
        }
        // v_i = -sin(th_i) vx: wheel 0 of the 3-wheel base (th 90 deg) gets -vx / r.
        let k = Kinematics::new(&default_geometry(WheelLayout::Omni3)).map_err(|e| e.to_string());
        let rates = k.map(|k| k.wheel_rates(Twist::new(0.5, 0.0, 0.0)));
        assert!(matches!(rates.as_deref(), Ok([w0, _, _]) if (w0 + 0.5 / 0.05).abs() < 1e-9), "{rates:?}");
    }
}
