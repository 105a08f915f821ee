//! The filter's uncertainty when a still start hands it over.
//!
//! A still accelerometer reads gravity plus its bias, `f = R^T (-g) + b_a`, and the start takes
//! all of `f` for gravity. The attitude it then sets defines the world the map is built in, so
//! whatever bias there was stays as a gravity that leans in that world: `g = g_hat + R b_a`, with
//! `b_a` the same unknown. Started as two independent unknowns (a gravity held to 0.01 m/s^2 and
//! a bias to 0.03), a bias the filter later learns (the IMU's readings turn with the device, a
//! lean of the world does not) cannot move the gravity with it, and the mismatch integrates into
//! velocity wherever the scans constrain little (the rig), or a tilt measurement turns the
//! attitude level under a map built leaning (the robot; docs/lio.md, "The rig's accelerometer
//! bias").

use super::init::InitResult;
use super::state::{Cov, BA, BG, GRAV, POS, ROT, VEL};
use nalgebra::{Matrix3, Rotation3};

/// Variances of a start that ties nothing together (the generic default).
const ROT_VAR: f64 = 1e-4;
const POS_VAR: f64 = 1e-6;
const VEL_VAR: f64 = 1e-4;
const ACC_BIAS_VAR: f64 = 1e-3;
const GRAVITY_VAR: f64 = 1e-4;
/// What the gravity keeps of its own besides the tie: the still window's averaging noise.
const GRAVITY_SLACK_VAR: f64 = 1e-6;

/// The error-state covariance after a still start. `acc_bias_sigma_m_s2` > 0 is the spread of the
/// accelerometer's bias the start could not see, tied to gravity as above; 0 starts them apart.
pub fn start_covariance(r: &InitResult, acc_bias_sigma_m_s2: f64) -> Cov {
    let mut cov = Cov::zeros();
    // The gyro bias is as uncertain as the gyro was unsteady while "still".
    let gyro_bias_var = r.gyro_std_rad_s.powi(2).max(1e-6);
    for (at, v) in
        [(ROT, ROT_VAR), (POS, POS_VAR), (VEL, VEL_VAR), (BG, gyro_bias_var), (BA, ACC_BIAS_VAR), (GRAV, GRAVITY_VAR)]
    {
        for i in at..at + 3 {
            cov[(i, i)] = v;
        }
    }
    if acc_bias_sigma_m_s2 > 0.0 {
        tie_gravity_to_acc_bias(&mut cov, &r.rot_world_imu, acc_bias_sigma_m_s2);
    }
    cov
}

/// `d_g = R d_b`, `d_b ~ N(0, sigma^2 I)`: the gravity and bias blocks and their cross terms.
fn tie_gravity_to_acc_bias(cov: &mut Cov, rot_world_imu: &Rotation3<f64>, sigma_m_s2: f64) {
    let var = sigma_m_s2 * sigma_m_s2;
    let r = rot_world_imu.matrix();
    let bias = Matrix3::identity() * var;
    let gravity = r * r.transpose() * var + Matrix3::identity() * GRAVITY_SLACK_VAR;
    let cross = r * var;
    cov.fixed_view_mut::<3, 3>(BA, BA).copy_from(&bias);
    cov.fixed_view_mut::<3, 3>(GRAV, GRAV).copy_from(&gravity);
    cov.fixed_view_mut::<3, 3>(GRAV, BA).copy_from(&cross);
    cov.fixed_view_mut::<3, 3>(BA, GRAV).copy_from(&cross.transpose());
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{SMatrix, Vector3};

    fn tilted_start() -> InitResult {
        InitResult {
            rot_world_imu: Rotation3::from_euler_angles(0.3, -0.2, 1.1),
            gravity_m_s2: 9.81,
            bias_gyro: Vector3::zeros(),
            gyro_std_rad_s: 0.002,
            end_ns: 0,
        }
    }

    /// The still reading `f = R^T (-g) + b_a` as a function of the (bias, gravity) errors.
    fn reading_jacobian(r: &Rotation3<f64>) -> SMatrix<f64, 3, 6> {
        let mut h = SMatrix::<f64, 3, 6>::zeros();
        h.fixed_view_mut::<3, 3>(0, 0).copy_from(&Matrix3::identity());
        h.fixed_view_mut::<3, 3>(0, 3).copy_from(&-r.matrix().transpose());
        h
    }

    /// The bias and gravity blocks and their cross terms (adjacent in the error state).
    fn bias_and_gravity(cov: &Cov) -> SMatrix<f64, 6, 6> {
        assert_eq!(GRAV, BA + 3);
        cov.fixed_view::<6, 6>(BA, BA).into_owned()
    }

    #[test]
    fn a_tied_start_leaves_the_still_reading_explained() {
        let r = tilted_start();
        let cov = start_covariance(&r, 0.05);
        let h = reading_jacobian(&r.rot_world_imu);
        let reading_var = h * bias_and_gravity(&cov) * h.transpose();
        // Only the gravity's own slack is left; the bias alone may be off by 0.05 on each axis.
        assert!(reading_var.trace() < 4.0 * GRAVITY_SLACK_VAR, "{reading_var}");
        assert!((cov[(BA, BA)] - 0.0025).abs() < 1e-12);
        assert!(cov[(GRAV, GRAV)] > 1e-3, "the gravity may lean as far as the bias is unknown");
        assert!((cov - cov.transpose()).abs().max() < 1e-15);
        assert!(cov.symmetric_eigenvalues().min() > -1e-12, "positive semidefinite");
    }

    #[test]
    fn an_untied_start_is_the_diagonal_of_before() {
        let r = tilted_start();
        let cov = start_covariance(&r, 0.0);
        assert_eq!(cov, Cov::from_diagonal(&cov.diagonal()));
        assert_eq!(cov[(BA + 1, BA + 1)], ACC_BIAS_VAR);
        assert_eq!(cov[(GRAV + 2, GRAV + 2)], GRAVITY_VAR);
        assert_eq!(cov[(BG, BG)], 1e-6_f64.max(0.002_f64.powi(2)));
        let h = reading_jacobian(&r.rot_world_imu);
        let reading_var = h * bias_and_gravity(&cov) * h.transpose();
        assert!(reading_var.trace() > 3.0 * ACC_BIAS_VAR, "apart, the reading's two causes add up");
    }
}
