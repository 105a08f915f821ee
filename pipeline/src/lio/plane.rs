//! Plane fitting to a handful of neighbours.

use nalgebra::{Matrix3, SymmetricEigen, Vector3};

/// A plane `normal . x + offset = 0` with a unit normal.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Plane {
    pub normal: Vector3<f64>,
    pub offset: f64,
}

/// Fits a plane to `points` (at least 3) by their covariance's weakest direction; `None` when
/// any point is farther than `max_dev_m` from it (not a plane) or the points are degenerate.
pub fn fit(points: &[Vector3<f64>], max_dev_m: f64) -> Option<Plane> {
    if points.len() < 3 {
        return None;
    }
    let n = points.len() as f64;
    let mean = points.iter().sum::<Vector3<f64>>() / n;
    let cov = points.iter().fold(Matrix3::zeros(), |c, p| {
        let d = p - mean;
        c + d * d.transpose()
    }) / n;
    let eig = SymmetricEigen::new(cov);
    let (i, _) = eig.eigenvalues.argmin();
    let normal: Vector3<f64> = eig.eigenvectors.column(i).into_owned();
    let len = normal.norm();
    if len.is_nan() || len < 0.5 {
        return None;
    }
    let normal = normal / len;
    let offset = -normal.dot(&mean);
    points.iter().all(|p| (normal.dot(p) + offset).abs() <= max_dev_m).then_some(Plane { normal, offset })
}

#[cfg(test)]
#[allow(clippy::expect_used)]
mod tests {
    use super::*;

    #[test]
    fn fits_a_tilted_plane_and_rejects_a_corner() {
        let pts: Vec<Vector3<f64>> = [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0), (0.5, 0.3)]
            .iter()
            .map(|&(x, y)| Vector3::new(x, y, 0.5 * x + 2.0))
            .collect();
        let p = fit(&pts, 0.01).expect("a plane");
        for q in &pts {
            assert!((p.normal.dot(q) + p.offset).abs() < 1e-9);
        }
        let corner = [
            Vector3::new(0.0, 0.0, 0.0),
            Vector3::new(1.0, 0.0, 0.0),
            Vector3::new(0.0, 1.0, 0.0),
            Vector3::new(0.0, 0.0, 1.0),
            Vector3::new(0.0, 0.0, 2.0),
        ];
        assert!(fit(&corner, 0.1).is_none());
    }
}
