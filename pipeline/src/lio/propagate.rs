//! IMU forward propagation of the state and its error covariance (discrete, first order).

use super::so3;
use super::state::{Cov, State, BA, BG, DIM, GRAV, POS, ROT, VEL};
use super::types::ImuSample;
use nalgebra::{Matrix3, Rotation3, SMatrix, Vector3};

/// Continuous-time noise densities (per sqrt(s)); defaults close to FAST-LIO's for the Avia.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ImuNoise {
    pub gyro_rad_s: f64,
    pub acc_m_s2: f64,
    pub gyro_bias_walk: f64,
    pub acc_bias_walk: f64,
}

impl Default for ImuNoise {
    fn default() -> Self {
        Self { gyro_rad_s: 0.1, acc_m_s2: 0.1, gyro_bias_walk: 1e-4, acc_bias_walk: 1e-4 }
    }
}

/// The IMU's motion at one instant, kept so points can be de-skewed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Knot {
    pub t_ns: u64,
    pub rot: Rotation3<f64>,
    pub pos: Vector3<f64>,
    pub vel: Vector3<f64>,
    /// Bias-corrected angular rate (IMU frame) and acceleration (world frame) held until the next knot.
    pub omega: Vector3<f64>,
    pub acc_world: Vector3<f64>,
}

impl Knot {
    /// The IMU pose `dt_s` after this knot, at constant rate and acceleration.
    pub fn pose_after(&self, dt_s: f64) -> (Rotation3<f64>, Vector3<f64>) {
        let rot = self.rot * so3::exp(&(self.omega * dt_s));
        let pos = self.pos + self.vel * dt_s + 0.5 * self.acc_world * dt_s * dt_s;
        (rot, pos)
    }
}

/// How the world acceleration `R (f - b_a) + g` the filter derives from a body acceleration
/// `acc_body` (`f - b_a`) moves with its error state: the attitude, the accelerometer bias and the
/// gravity (the velocity's rows of the propagation's Jacobian, per second).
pub fn acc_world_jacobian(rot: &Rotation3<f64>, acc_body: &Vector3<f64>) -> SMatrix<f64, 3, DIM> {
    let r = rot.matrix();
    let mut j = SMatrix::<f64, 3, DIM>::zeros();
    j.fixed_view_mut::<3, 3>(0, ROT).copy_from(&(-r * so3::skew(acc_body)));
    j.fixed_view_mut::<3, 3>(0, BA).copy_from(&-r);
    j.fixed_view_mut::<3, 3>(0, GRAV).copy_from(&Matrix3::identity());
    j
}

/// Moves `state` and `cov` forward by `dt_s` with the measurement `imu` held over that interval.
/// Returns the knot at the start of the interval.
pub fn step(state: &mut State, cov: &mut Cov, imu: &ImuSample, t_ns: u64, dt_s: f64, noise: &ImuNoise) -> Knot {
    let omega = imu.gyro_rad_s - state.bias_gyro;
    let acc_body = imu.acc_m_s2 - state.bias_acc;
    let acc_world = state.rot * acc_body + state.gravity;
    let knot = Knot { t_ns, rot: state.rot, pos: state.pos, vel: state.vel, omega, acc_world };
    if dt_s <= 0.0 {
        return knot;
    }
    let eye = Matrix3::identity();
    let mut f = Cov::identity();
    f.fixed_view_mut::<3, 3>(ROT, ROT).copy_from(so3::exp(&(-omega * dt_s)).matrix());
    f.fixed_view_mut::<3, 3>(ROT, BG).copy_from(&(-eye * dt_s));
    f.fixed_view_mut::<3, 3>(POS, VEL).copy_from(&(eye * dt_s));
    let mut vel_rows = f.fixed_view_mut::<3, DIM>(VEL, 0);
    vel_rows += acc_world_jacobian(&state.rot, &acc_body) * dt_s;
    let mut q = Cov::zeros();
    let diag = |q: &mut Cov, at: usize, v: f64| {
        for i in at..at + 3 {
            q[(i, i)] = v;
        }
    };
    diag(&mut q, ROT, noise.gyro_rad_s.powi(2) * dt_s);
    diag(&mut q, VEL, noise.acc_m_s2.powi(2) * dt_s);
    diag(&mut q, BG, noise.gyro_bias_walk.powi(2) * dt_s);
    diag(&mut q, BA, noise.acc_bias_walk.powi(2) * dt_s);
    *cov = f * *cov * f.transpose() + q;

    state.pos += state.vel * dt_s + 0.5 * acc_world * dt_s * dt_s;
    state.vel += acc_world * dt_s;
    state.rot *= so3::exp(&(omega * dt_s));
    knot
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn constant_rotation_and_acceleration_integrate_exactly_enough() {
        let mut s = State::at_rest();
        let mut cov = Cov::identity() * 1e-6;
        // At rest with gravity cancelled by the specific force, 0.5 m/s^2 forward, 0.2 rad/s yaw.
        let imu = ImuSample {
            t_ns: 0,
            clock: starc_time::Clock::Ptp,
            gyro_rad_s: Vector3::new(0.0, 0.0, 0.0),
            acc_m_s2: Vector3::new(0.5, 0.0, 9.81),
        };
        for k in 0..200 {
            step(&mut s, &mut cov, &imu, k * 5_000_000, 0.005, &ImuNoise::default());
        }
        assert!((s.pos.x - 0.25).abs() < 1e-9 && (s.vel.x - 0.5).abs() < 1e-9);
        let before = cov[(POS, POS)];
        assert!(before > 1e-6, "position uncertainty grows: {before}");
    }
}
