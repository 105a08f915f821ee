//! Wheel odometry of the simulated base: wheel rates from the base's true body velocity through
//! the wheel layout's inverse kinematics, with slip; the odometry integrates the body velocity
//! recovered from the measured rates by the least-squares forward kinematics, as a real base
//! driver does (the same models as drivers/base, kept here to leave hil free of the base crate).

use crate::rng::SplitMix64;
use crate::sim::motion::RobotMotion;
use crate::sim::scenario::WheelLayout;
use nalgebra::{DMatrix, DVector};

/// Default geometry: wheel radius and centre-to-wheel distance (m) of a small omni base;
/// mecanum: half wheelbase lx and half track ly.
const OMNI_RADIUS_M: f64 = 0.05;
const OMNI_ARM_M: f64 = 0.2;
const MECANUM_RADIUS_M: f64 = 0.076;
const MECANUM_LX_M: f64 = 0.2;
const MECANUM_LY_M: f64 = 0.2;
/// Slip: multiplicative (1 sigma) per wheel reading.
const SLIP_SIGMA: f64 = 0.02;

/// A wheel layout's kinematics: wheel rates (rad/s) = `inverse` * (vx, vy, wz).
#[derive(Clone, Debug)]
pub struct Kinematics {
    inverse: DMatrix<f64>,
    forward: DMatrix<f64>,
}

impl Kinematics {
    pub fn new(layout: WheelLayout) -> Self {
        let rows: Vec<[f64; 3]> = match layout {
            WheelLayout::Omni3 | WheelLayout::Omni4 => {
                let n = if layout == WheelLayout::Omni3 { 3 } else { 4 };
                let first = if n == 3 { 90f64 } else { 45.0 };
                (0..n)
                    .map(|i| {
                        let th = (first + 360.0 * i as f64 / n as f64).to_radians();
                        [-th.sin() / OMNI_RADIUS_M, th.cos() / OMNI_RADIUS_M, OMNI_ARM_M / OMNI_RADIUS_M]
                    })
                    .collect()
            }
            WheelLayout::Mecanum => {
                let (r, k) = (MECANUM_RADIUS_M, MECANUM_LX_M + MECANUM_LY_M);
                vec![
                    [1.0 / r, -1.0 / r, -k / r],
                    [1.0 / r, 1.0 / r, k / r],
                    [1.0 / r, 1.0 / r, -k / r],
                    [1.0 / r, -1.0 / r, k / r],
                ]
            }
        };
        let inverse = DMatrix::from_fn(rows.len(), 3, |i, j| rows.get(i).map_or(0.0, |r| r[j]));
        // Least squares: (A^T A)^-1 A^T; A has full column rank for every layout here.
        let forward = (inverse.transpose() * &inverse)
            .try_inverse()
            .map(|m| m * inverse.transpose())
            .unwrap_or_else(|| DMatrix::zeros(3, rows.len()));
        Self { inverse, forward }
    }

    pub fn wheels(&self) -> usize {
        self.inverse.nrows()
    }

    pub fn wheel_rates(&self, body: [f64; 3]) -> Vec<f64> {
        (&self.inverse * DVector::from_row_slice(&body)).iter().copied().collect()
    }

    pub fn body_velocity(&self, rates: &[f64]) -> [f64; 3] {
        let v = &self.forward * DVector::from_row_slice(rates);
        [v[0], v[1], v[2]]
    }
}

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
    pub fn new(layout: WheelLayout, seed: u64) -> Self {
        Self { kinematics: Kinematics::new(layout), rng: SplitMix64::new(seed), pose: [0.0; 3], last_t: None }
    }

    /// The reading at `t` (s); calls in time order.
    pub fn sample(&mut self, motion: &RobotMotion, t: f64) -> WheelReading {
        let h = 1e-3;
        let (a, b) = (motion.route().at(t - h), motion.route().at(t + h));
        let now = motion.route().at(t);
        let (vxw, vyw) = ((b.x - a.x) / (2.0 * h), (b.y - a.y) / (2.0 * h));
        let wz = (b.yaw_rad - a.yaw_rad) / (2.0 * h);
        let (s, c) = now.yaw_rad.sin_cos();
        let body = [c * vxw + s * vyw, -s * vxw + c * vyw, wz];
        let rates: Vec<f64> =
            self.kinematics.wheel_rates(body).into_iter().map(|w| w * (1.0 + SLIP_SIGMA * self.rng.normal())).collect();
        let measured = self.kinematics.body_velocity(&rates);
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
    fn forward_inverts_inverse_for_every_layout() {
        for layout in [WheelLayout::Omni3, WheelLayout::Omni4, WheelLayout::Mecanum] {
            let k = Kinematics::new(layout);
            let body = [0.3, -0.2, 0.5];
            let back = k.body_velocity(&k.wheel_rates(body));
            for i in 0..3 {
                assert!((back[i] - body[i]).abs() < 1e-9, "{layout:?}: {back:?}");
            }
        }
        // Pure forward motion on the 3-wheel base: the front wheel (at 90 deg) spins backwards
        // relative to the others... v_i = -sin(th) vx: wheel 0 (th 90) gets -vx / r.
        let k = Kinematics::new(WheelLayout::Omni3);
        let rates = k.wheel_rates([0.5, 0.0, 0.0]);
        assert!((rates[0] + 0.5 / OMNI_RADIUS_M).abs() < 1e-9, "{rates:?}");
    }
}
