//! Small SO(3) helpers: the exponential and logarithm maps and the skew matrix.

use nalgebra::{Matrix3, Rotation3, Vector3};

/// The rotation `exp([w]x)`.
pub fn exp(w: &Vector3<f64>) -> Rotation3<f64> {
    Rotation3::new(*w)
}

/// The rotation vector of `r` (inverse of [`exp`]).
pub fn log(r: &Rotation3<f64>) -> Vector3<f64> {
    r.scaled_axis()
}

/// The matrix of `v x .`.
pub fn skew(v: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exp_log_round_trip_and_skew_is_cross() {
        let w = Vector3::new(0.3, -0.2, 0.1);
        assert!((log(&exp(&w)) - w).norm() < 1e-12);
        let v = Vector3::new(1.0, 2.0, 3.0);
        assert!((skew(&w) * v - w.cross(&v)).norm() < 1e-12);
    }
}
