//! The filter state on its manifold and its 18-dimensional error state.
//!
//! Error-state order (each 3 wide): attitude (right perturbation, `R = R_hat * exp(d_theta)`),
//! position, velocity, gyro bias, accelerometer bias, gravity. The LiDAR-IMU extrinsics are held
//! here, fixed from the configuration: estimating them would append six error dimensions.

use super::so3;
use nalgebra::{Isometry3, Rotation3, SMatrix, SVector, Translation3, UnitQuaternion, Vector3};

pub const DIM: usize = 18;
pub type ErrVec = SVector<f64, DIM>;
pub type Cov = SMatrix<f64, DIM, DIM>;

/// Offsets of each block in the error state.
pub const ROT: usize = 0;
pub const POS: usize = 3;
pub const VEL: usize = 6;
pub const BG: usize = 9;
pub const BA: usize = 12;
pub const GRAV: usize = 15;

/// The IMU's state in the world frame (gravity-aligned: z up) plus the LiDAR's mounting.
#[derive(Clone, Debug, PartialEq)]
pub struct State {
    pub rot: Rotation3<f64>,
    pub pos: Vector3<f64>,
    pub vel: Vector3<f64>,
    pub bias_gyro: Vector3<f64>,
    pub bias_acc: Vector3<f64>,
    pub gravity: Vector3<f64>,
    /// The LiDAR in the IMU frame (`T_imu_lidar`), fixed (not part of the error state).
    pub rot_imu_lidar: Rotation3<f64>,
    pub pos_imu_lidar: Vector3<f64>,
}

impl State {
    /// Level, at rest at the origin, no biases, standard gravity, the LiDAR on the IMU (tests).
    #[cfg(test)]
    pub fn at_rest() -> Self {
        Self {
            rot: Rotation3::identity(),
            pos: Vector3::zeros(),
            vel: Vector3::zeros(),
            bias_gyro: Vector3::zeros(),
            bias_acc: Vector3::zeros(),
            gravity: Vector3::new(0.0, 0.0, -9.81),
            rot_imu_lidar: Rotation3::identity(),
            pos_imu_lidar: Vector3::zeros(),
        }
    }

    /// Whether every part of the state is a finite number (a NaN that got in would spread
    /// through every later scan and into the map).
    pub fn is_finite(&self) -> bool {
        let vectors = [self.pos, self.vel, self.bias_gyro, self.bias_acc, self.gravity];
        vectors.iter().all(|v| v.iter().all(|x| x.is_finite())) && self.rot.matrix().iter().all(|x| x.is_finite())
    }

    /// `self [+] dx`.
    pub fn boxplus(&self, dx: &ErrVec) -> Self {
        let mut s = self.clone();
        s.rot = self.rot * so3::exp(&block(dx, ROT));
        s.pos += block(dx, POS);
        s.vel += block(dx, VEL);
        s.bias_gyro += block(dx, BG);
        s.bias_acc += block(dx, BA);
        s.gravity += block(dx, GRAV);
        s
    }

    /// `self [-] other`: the error that takes `other` to `self`.
    pub fn boxminus(&self, other: &Self) -> ErrVec {
        let mut dx = ErrVec::zeros();
        dx.fixed_rows_mut::<3>(ROT).copy_from(&so3::log(&(other.rot.transpose() * self.rot)));
        dx.fixed_rows_mut::<3>(POS).copy_from(&(self.pos - other.pos));
        dx.fixed_rows_mut::<3>(VEL).copy_from(&(self.vel - other.vel));
        dx.fixed_rows_mut::<3>(BG).copy_from(&(self.bias_gyro - other.bias_gyro));
        dx.fixed_rows_mut::<3>(BA).copy_from(&(self.bias_acc - other.bias_acc));
        dx.fixed_rows_mut::<3>(GRAV).copy_from(&(self.gravity - other.gravity));
        dx
    }

    /// The LiDAR's pose in the world (`T_world_lidar`).
    pub fn lidar_pose(&self) -> Isometry3<f64> {
        let rot = self.rot * self.rot_imu_lidar;
        let pos = self.rot * self.pos_imu_lidar + self.pos;
        Isometry3::from_parts(Translation3::from(pos), UnitQuaternion::from_rotation_matrix(&rot))
    }
}

/// The 3-vector at `at` in `dx`.
pub fn block(dx: &ErrVec, at: usize) -> Vector3<f64> {
    dx.fixed_rows::<3>(at).into_owned()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn boxplus_then_boxminus_returns_the_error() {
        let s = State {
            rot: so3::exp(&Vector3::new(0.1, 0.2, -0.3)),
            pos: Vector3::new(1.0, 2.0, 3.0),
            ..State::at_rest()
        };
        let dx = ErrVec::from_fn(|i, _| (i as f64 + 1.0) * 0.01);
        assert!((s.boxplus(&dx).boxminus(&s) - dx).norm() < 1e-12);
    }
}
