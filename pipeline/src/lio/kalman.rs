//! One Kalman update of the error state with a 3-row measurement: what the wheels' velocity,
//! the still IMU's zero velocity and the level (gravity) measurements share.

use super::state::{Cov, State, DIM};
use nalgebra::{Matrix3, SMatrix, Vector3};

/// A 3-row measurement Jacobian over the error state.
pub type Rows3 = SMatrix<f64, 3, DIM>;

/// Applies `innovation` (measured minus predicted) with Jacobian `h` and noise `r` to `state` and
/// `cov`. Returns false, changing nothing, when the innovation covariance is singular or the
/// innovation's squared Mahalanobis length passes `gate_chi2` (`f64::INFINITY`: no gate).
pub fn update3(
    state: &mut State,
    cov: &mut Cov,
    h: &Rows3,
    innovation: &Vector3<f64>,
    r: &Matrix3<f64>,
    gate_chi2: f64,
) -> bool {
    let Some(s_inv) = (h * *cov * h.transpose() + r).try_inverse() else { return false };
    if (innovation.transpose() * s_inv * innovation)[(0, 0)] > gate_chi2 {
        return false;
    }
    let gain = *cov * h.transpose() * s_inv;
    *state = state.boxplus(&(gain * innovation));
    // Joseph form: stays symmetric and positive with inflated (Huber) noise.
    let a = Cov::identity() - gain * h;
    *cov = a * *cov * a.transpose() + gain * r * gain.transpose();
    true
}
