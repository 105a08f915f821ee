//! The iterated error-state Kalman update with point-to-plane residuals (as in FAST-LIO2).
//!
//! Each iteration re-associates every point with the plane of its 5 nearest map points at the
//! current estimate and solves the MAP problem of the prior plus those residuals in information
//! form: `(P^-1 + H^T H / s2) dx = -P^-1 (x - x_prior) - H^T z / s2`, until the step is small.
//!
//! **Degeneracy index.** The smallest eigenvalue of `H^T H / N` over the 6 pose columns, with the
//! rotation columns divided by the mean range `L` of the matched points. A point-to-plane row is
//! `[(q x R^T n)^T, n^T]`: the position part is a unit normal (unitless), the rotation part a
//! lever arm in metres, so dividing by `L` makes both unitless and the index comparable between
//! scenes. 1/3 is the best a set of unit normals can give a direction; near 0 the scene does not
//! constrain some direction (a corridor's axis, an open field's yaw).

use super::ivox::VoxelMap;
use super::plane;
use super::state::{Cov, ErrVec, State, DIM};
use nalgebra::{Matrix6, SymmetricEigen, Vector3, Vector6};

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UpdateConfig {
    pub max_iterations: usize,
    /// Variance of a point-to-plane residual (m^2).
    pub residual_var_m2: f64,
    pub neighbours: usize,
    pub max_neighbour_dist_m: f64,
    pub max_plane_dev_m: f64,
    /// Converged when the step is below these.
    pub converge_rot_rad: f64,
    pub converge_pos_m: f64,
}

impl Default for UpdateConfig {
    fn default() -> Self {
        Self {
            max_iterations: 4,
            residual_var_m2: 0.001,
            neighbours: 5,
            max_neighbour_dist_m: 1.5,
            max_plane_dev_m: 0.1,
            converge_rot_rad: 1e-3,
            converge_pos_m: 1e-3,
        }
    }
}

#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct UpdateReport {
    pub iterations: usize,
    pub converged: bool,
    /// Points with a plane residual in the last iteration.
    pub matched: usize,
    pub degeneracy_index: f64,
    /// RMS of the accepted residuals in the last iteration (m).
    pub rms_m: f64,
}

/// Runs the update. Leaves state and covariance unchanged (and reports 0 matched) when too few
/// points match or the information cannot be inverted.
pub fn update(
    state: &mut State,
    cov: &mut Cov,
    points: &[Vector3<f64>],
    map: &VoxelMap,
    cfg: &UpdateConfig,
) -> UpdateReport {
    let mut report = UpdateReport::default();
    let Some(p_inv) = cov.try_inverse() else { return report };
    let prior = state.clone();
    let mut x = state.clone();
    let mut nn = Vec::with_capacity(cfg.neighbours);
    let mut nbrs: Vec<Vector3<f64>> = Vec::with_capacity(cfg.neighbours);
    let mut posterior = *cov;
    for it in 0..cfg.max_iterations {
        let (mut hth, mut htz) = (Matrix6::<f64>::zeros(), Vector6::<f64>::zeros());
        let (mut n_used, mut sum_sq, mut sum_range) = (0usize, 0.0, 0.0);
        let mut scaled = Matrix6::<f64>::zeros();
        for p in points {
            let q = x.rot_imu_lidar * p + x.pos_imu_lidar;
            let w = x.rot * q + x.pos;
            map.nearest(&w, cfg.neighbours, cfg.max_neighbour_dist_m, &mut nn);
            if nn.len() < cfg.neighbours {
                continue;
            }
            nbrs.clear();
            nbrs.extend(nn.iter().map(|(_, v)| *v));
            let Some(pl) = plane::fit(&nbrs, cfg.max_plane_dev_m) else { continue };
            let r = pl.normal.dot(&w) + pl.offset;
            // FAST-LIO's gate: farther points may sit farther from their plane.
            if r.abs() * 9.0 > p.norm().sqrt() {
                continue;
            }
            let j_rot = q.cross(&(x.rot.inverse() * pl.normal));
            let row = Vector6::new(j_rot.x, j_rot.y, j_rot.z, pl.normal.x, pl.normal.y, pl.normal.z);
            hth += row * row.transpose();
            htz += row * r;
            n_used += 1;
            sum_sq += r * r;
            sum_range += q.norm();
        }
        report.iterations = it + 1;
        report.matched = n_used;
        if n_used < 20 {
            report.matched = 0;
            return report;
        }
        let l = (sum_range / n_used as f64).max(1e-3);
        let mut s = Vector6::repeat(1.0);
        s.fixed_rows_mut::<3>(0).fill(1.0 / l);
        scaled.copy_from(&(Matrix6::from_diagonal(&s) * hth * Matrix6::from_diagonal(&s) / n_used as f64));
        report.degeneracy_index = SymmetricEigen::new(scaled).eigenvalues.min();
        report.rms_m = (sum_sq / n_used as f64).sqrt();

        let mut info = p_inv;
        let mut ff = info.fixed_view_mut::<6, 6>(0, 0);
        ff += hth / cfg.residual_var_m2;
        let e = x.boxminus(&prior);
        let mut rhs = -(p_inv * e);
        let mut top = rhs.fixed_rows_mut::<6>(0);
        top -= htz / cfg.residual_var_m2;
        let Some(info_inv) = info.try_inverse() else { return report };
        let dx: ErrVec = info_inv * rhs;
        x = x.boxplus(&dx);
        posterior = info_inv;
        let rot_step = dx.fixed_rows::<3>(0).norm();
        let pos_step = dx.fixed_rows::<3>(3).norm();
        if rot_step < cfg.converge_rot_rad && pos_step < cfg.converge_pos_m {
            report.converged = true;
            break;
        }
    }
    debug_assert_eq!(posterior.nrows(), DIM);
    *state = x;
    *cov = (posterior + posterior.transpose()) * 0.5;
    report
}
