//! Wheel odometry: measured wheel rates through the forward kinematics, integrated in the plane.

use crate::kinematics::{Kinematics, Twist};
use serde::Serialize;
use starc_time::Stamp;

/// The pose and velocity at one instant, in the odometry frame (starts at the origin).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct OdometrySample {
    pub stamp: Stamp,
    pub x_m: f64,
    pub y_m: f64,
    pub theta_rad: f64,
    /// Body-frame velocity estimated from the wheels.
    pub twist: Twist,
}

/// Integrates body velocities into a pose.
#[derive(Clone, Debug, Default)]
pub struct Odometry {
    last: Option<OdometrySample>,
}

impl Odometry {
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds measured wheel rates taken at `stamp`; `None` when the rates do not fit the model
    /// or the stamp is on another clock or goes back in time.
    pub fn update(&mut self, kinematics: &Kinematics, wheel_rad_s: &[f64], stamp: Stamp) -> Option<OdometrySample> {
        let twist = kinematics.body_twist(wheel_rad_s)?;
        let sample = match self.last {
            None => OdometrySample { stamp, x_m: 0.0, y_m: 0.0, theta_rad: 0.0, twist },
            Some(prev) => {
                let dt_ns = stamp.since(prev.stamp)?;
                if dt_ns < 0 {
                    return None;
                }
                let dt = dt_ns as f64 * 1e-9;
                // Trapezoid on the body velocity, midpoint heading.
                let vx = 0.5 * (prev.twist.vx_m_s + twist.vx_m_s);
                let vy = 0.5 * (prev.twist.vy_m_s + twist.vy_m_s);
                let wz = 0.5 * (prev.twist.wz_rad_s + twist.wz_rad_s);
                let mid = prev.theta_rad + 0.5 * wz * dt;
                let (s, c) = mid.sin_cos();
                let theta = prev.theta_rad + wz * dt;
                OdometrySample {
                    stamp,
                    x_m: prev.x_m + (c * vx - s * vy) * dt,
                    y_m: prev.y_m + (s * vx + c * vy) * dt,
                    theta_rad: (theta + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI,
                    twist,
                }
            }
        };
        self.last = Some(sample);
        Some(sample)
    }

    pub fn last(&self) -> Option<OdometrySample> {
        self.last
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kinematics::KinematicsConfig;
    use starc_time::Clock;

    #[test]
    fn a_full_circle_comes_home() -> crate::Result<()> {
        let k = Kinematics::new(&KinematicsConfig::Omni3 {
            wheel_radius_m: 0.05,
            center_to_wheel_m: 0.2,
            wheel_angles_deg: None,
        })?;
        let mut odo = Odometry::new();
        // 1 m/s forward while turning at 1 rad/s: a circle of radius 1 m in 2 pi seconds.
        let wheels = k.wheel_rates(Twist::new(1.0, 0.0, 1.0));
        let steps = 6283;
        let mut last = None;
        for i in 0..=steps {
            last = odo.update(&k, &wheels, Stamp::new(i * 1_000_000, Clock::Host));
        }
        let p = last.unwrap_or_else(|| panic!("no sample"));
        assert!(p.x_m.abs() < 2e-3 && p.y_m.abs() < 2e-3, "{p:?}");
        assert!(odo.update(&k, &wheels, Stamp::new(0, Clock::Host)).is_none(), "time went back");
        assert!(odo.update(&k, &wheels, Stamp::new(u64::MAX / 2, Clock::Ptp)).is_none(), "other clock");
        Ok(())
    }
}
