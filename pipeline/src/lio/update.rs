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
use super::plane::{self, Plane};
use super::state::{Cov, ErrVec, State, DIM};
use nalgebra::{Matrix6, SymmetricEigen, Vector3, Vector6, U6};

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
    /// Eigen-directions of the normalised information below this take no update (see the
    /// module's notes); 0 applies every direction, as FAST-LIO2 does. Kept tiny: a weak
    /// direction still holds real information (an aisle's yaw: 0.0002 to 0.003 over ~900
    /// matches), and with it dropped the rest of the update and the prior's correlations move
    /// the yaw freely (docs/lio.md, the auditorium's aisle).
    pub min_direction_info: f64,
    /// A scan whose residual RMS comes out above this is updated again from the prior with its
    /// residual variance grown by the square of the ratio (0: never; see [`update`]).
    pub fit_rms_ref_m: f64,
    /// Neighbours are searched again after a step larger than these (else the planes are kept).
    pub research_rot_rad: f64,
    pub research_pos_m: f64,
}

impl Default for UpdateConfig {
    fn default() -> Self {
        Self {
            max_iterations: 4,
            residual_var_m2: 0.001,
            neighbours: 8,
            max_neighbour_dist_m: 1.5,
            max_plane_dev_m: 0.05,
            converge_rot_rad: 1e-3,
            converge_pos_m: 1e-3,
            min_direction_info: 1e-4,
            fit_rms_ref_m: 0.0,
            research_rot_rad: 0.01,
            research_pos_m: 0.05,
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
    /// Directions of the pose that took no update in the last iteration (0 to 6).
    pub weak_directions: usize,
    /// Which axes those directions mostly lie along: bit k for axis k of the update's error
    /// state (rx, ry, rz: turns; x, y, z: moves) when more than half of that axis lies in the
    /// weak directions (a corridor along x sets bit 3). [`weak_axes_names`] spells it out. The
    /// LIO's output adds the world position axes the filter stays unsure of after the scan
    /// ([`crate::lio::uncertain_axes`]), which no update direction need be weak for.
    pub weak_axes: u8,
}

/// The axes of [`UpdateReport::weak_axes`] by name, joined by `+` ("" when none).
pub fn weak_axes_names(mask: u8) -> String {
    const NAMES: [&str; 6] = ["rx", "ry", "rz", "x", "y", "z"];
    NAMES.iter().enumerate().filter(|(k, _)| mask & (1 << k) != 0).map(|(_, n)| *n).collect::<Vec<_>>().join("+")
}

/// Runs the update. Leaves state and covariance unchanged (and reports 0 matched) when too few
/// points match or the information cannot be inverted.
///
/// Where the scan fits more loosely than `cfg.fit_rms_ref_m` (RMS of its residuals), it is run
/// again from the same prior with the residual variance grown by the square of that ratio: the
/// scan's own residuals say how far its points can be trusted (a quick turn's de-skew errors, a
/// view half new to the map), as KISS-ICP sizes its threshold from its own fits.
pub fn update(
    state: &mut State,
    cov: &mut Cov,
    points: &[Vector3<f64>],
    map: &VoxelMap,
    cfg: &UpdateConfig,
) -> UpdateReport {
    let mut report = UpdateReport::default();
    let Some(inv) = cov.try_inverse() else { return report };
    let prior = Prior { state, cov, inv };
    let mut planes = Planes::new(points.len(), cfg.neighbours);
    let Some(mut fit) = iterate(&prior, points, map, cfg, &mut planes, &mut report) else { return report };
    if cfg.fit_rms_ref_m > 0.0 && report.rms_m > cfg.fit_rms_ref_m {
        let ratio = report.rms_m / cfg.fit_rms_ref_m;
        let loose = UpdateConfig { residual_var_m2: cfg.residual_var_m2 * ratio * ratio, ..*cfg };
        report = UpdateReport::default();
        let Some(refit) = iterate(&prior, points, map, &loose, &mut planes, &mut report) else {
            return report;
        };
        fit = refit;
    }
    let (x, posterior) = fit;
    debug_assert_eq!(posterior.nrows(), DIM);
    *state = x;
    *cov = (posterior + posterior.transpose()) * 0.5;
    report
}

/// The state an update starts from, its covariance and that covariance's inverse.
struct Prior<'a> {
    state: &'a State,
    cov: &'a Cov,
    inv: Cov,
}

/// The iterations of one update from `prior`: the estimate and its covariance, None where too
/// few points match or the information cannot be inverted.
fn iterate(
    prior: &Prior,
    points: &[Vector3<f64>],
    map: &VoxelMap,
    cfg: &UpdateConfig,
    planes: &mut Planes,
    report: &mut UpdateReport,
) -> Option<(State, Cov)> {
    let mut x = prior.state.clone();
    let mut posterior = *prior.cov;
    let mut search = true;
    for it in 0..cfg.max_iterations {
        let mut eq = planes.normal_equations(points, &x, map, cfg, search);
        report.iterations = it + 1;
        report.matched = eq.n_used;
        if eq.n_used < 20 {
            report.matched = 0;
            return None;
        }
        eq.condition(cfg, it, report);
        let (dx, info_inv) = solve(&prior.inv, &x, prior.state, &eq, cfg)?;
        x = x.boxplus(&dx);
        posterior = info_inv;
        let rot_step = dx.fixed_rows::<3>(0).norm();
        let pos_step = dx.fixed_rows::<3>(3).norm();
        search = rot_step > cfg.research_rot_rad || pos_step > cfg.research_pos_m;
        if rot_step < cfg.converge_rot_rad && pos_step < cfg.converge_pos_m {
            report.converged = true;
            break;
        }
    }
    Some((x, posterior))
}

/// Each point's plane in the map, with the scratch space of the neighbour search. Searched
/// again only after a step large enough to change neighbours (the search is most of an
/// iteration's cost); otherwise the planes of the last search are kept.
struct Planes {
    of_point: Vec<Option<Plane>>,
    nn: Vec<(f64, Vector3<f64>)>,
    nbrs: Vec<Vector3<f64>>,
}

/// The point-to-plane normal equations of one iteration over the 6 pose columns (rotation,
/// position): `H^T H` and `H^T z` of the residuals that passed the gate, and their sums.
struct NormalEquations {
    hth: Matrix6<f64>,
    htz: Vector6<f64>,
    n_used: usize,
    sum_sq: f64,
    /// Sum of the matched points' ranges (the lever arm the rotation columns are scaled by).
    sum_range: f64,
}

impl Planes {
    fn new(points: usize, neighbours: usize) -> Self {
        Self {
            of_point: Vec::with_capacity(points),
            nn: Vec::with_capacity(neighbours),
            nbrs: Vec::with_capacity(neighbours),
        }
    }

    /// Associates every point with its plane at the estimate `x` (searching again when
    /// `search`) and sums the rows of the residuals that pass the gate.
    fn normal_equations(
        &mut self,
        points: &[Vector3<f64>],
        x: &State,
        map: &VoxelMap,
        cfg: &UpdateConfig,
        search: bool,
    ) -> NormalEquations {
        let mut eq =
            NormalEquations { hth: Matrix6::zeros(), htz: Vector6::zeros(), n_used: 0, sum_sq: 0.0, sum_range: 0.0 };
        if search {
            self.of_point.clear();
        }
        for (i, p) in points.iter().enumerate() {
            let q = x.rot_imu_lidar * p + x.pos_imu_lidar;
            let w = x.rot * q + x.pos;
            if search {
                let plane = self.fit_at(&w, map, cfg);
                self.of_point.push(plane);
            }
            let Some(pl) = self.of_point.get(i).copied().flatten() else { continue };
            let r = pl.normal.dot(&w) + pl.offset;
            // FAST-LIO's gate: farther points may sit farther from their plane.
            if r.abs() * 9.0 > p.norm().sqrt() {
                continue;
            }
            let j_rot = q.cross(&(x.rot.inverse() * pl.normal));
            let row = Vector6::new(j_rot.x, j_rot.y, j_rot.z, pl.normal.x, pl.normal.y, pl.normal.z);
            eq.hth += row * row.transpose();
            eq.htz += row * r;
            eq.n_used += 1;
            eq.sum_sq += r * r;
            eq.sum_range += q.norm();
        }
        eq
    }

    /// The plane of the map's nearest points around `w`; None with fewer than `neighbours`
    /// within reach or no plane among them.
    fn fit_at(&mut self, w: &Vector3<f64>, map: &VoxelMap, cfg: &UpdateConfig) -> Option<Plane> {
        map.nearest(w, cfg.neighbours, cfg.max_neighbour_dist_m, &mut self.nn);
        if self.nn.len() < cfg.neighbours {
            return None;
        }
        self.nbrs.clear();
        self.nbrs.extend(self.nn.iter().map(|(_, v)| *v));
        plane::fit(&self.nbrs, cfg.max_plane_dev_m)
    }
}

impl NormalEquations {
    /// Reports the degeneracy index, RMS and weak directions (see the module's notes) and
    /// drops the information along the weak ones, so that they take no update.
    fn condition(&mut self, cfg: &UpdateConfig, it: usize, report: &mut UpdateReport) {
        let n = self.n_used as f64;
        let l = (self.sum_range / n).max(1e-3);
        let mut s = Vector6::repeat(1.0);
        s.fixed_rows_mut::<3>(0).fill(1.0 / l);
        let scaled = Matrix6::from_diagonal(&s) * self.hth * Matrix6::from_diagonal(&s) / n;
        let eigen = SymmetricEigen::new(scaled);
        report.degeneracy_index = eigen.eigenvalues.min();
        report.rms_m = (self.sum_sq / n).sqrt();
        report.weak_directions = eigen.eigenvalues.iter().filter(|&&l| l < cfg.min_direction_info).count();
        if report.weak_directions > 0 && tracing::enabled!(tracing::Level::TRACE) {
            trace_weak_directions(&eigen, cfg, it);
        }
        // The weak subspace's projector: its diagonal says how much of each axis lies in it,
        // whatever basis the eigen-solver picked inside a repeated eigenvalue.
        let mut weak = Matrix6::<f64>::zeros();
        for (l, v) in eigen.eigenvalues.iter().zip(eigen.eigenvectors.column_iter()) {
            if *l < cfg.min_direction_info {
                weak += v * v.transpose();
            }
        }
        report.weak_axes = (0..6).filter(|&k| weak[(k, k)] > 0.5).fold(0u8, |m, k| m | (1 << k));
        if report.weak_directions > 0 {
            self.keep_strong_directions(&eigen, &s, cfg);
        }
    }

    /// Keeps only the information along well-constrained directions (projected in the
    /// unit-free coordinates `s` where the eigenvalues were taken, then scaled back).
    fn keep_strong_directions(&mut self, eigen: &SymmetricEigen<f64, U6>, s: &Vector6<f64>, cfg: &UpdateConfig) {
        let mut keep = Matrix6::<f64>::zeros();
        for (i, l) in eigen.eigenvalues.iter().enumerate() {
            if *l >= cfg.min_direction_info {
                let v = eigen.eigenvectors.column(i);
                keep += v * v.transpose();
            }
        }
        let s_inv = Matrix6::from_diagonal(&s.map(|v| 1.0 / v));
        let to = s_inv * keep * Matrix6::from_diagonal(s);
        self.hth = to * self.hth * to.transpose();
        self.htz = to * self.htz;
    }
}

fn trace_weak_directions(eigen: &SymmetricEigen<f64, U6>, cfg: &UpdateConfig, it: usize) {
    for (l, v) in eigen.eigenvalues.iter().zip(eigen.eigenvectors.column_iter()) {
        if *l < cfg.min_direction_info {
            let v: Vec<String> = v.iter().map(|c| format!("{c:+.2}")).collect();
            tracing::trace!(it, info = l, direction = v.join(" "), "left to the IMU (rx ry rz x y z, unit-free)");
        }
    }
}

/// The step of the MAP problem in information form (the module's equation) from the estimate
/// `x`, and the posterior covariance; None when the information cannot be inverted.
fn solve(p_inv: &Cov, x: &State, prior: &State, eq: &NormalEquations, cfg: &UpdateConfig) -> Option<(ErrVec, Cov)> {
    let mut info = *p_inv;
    let mut ff = info.fixed_view_mut::<6, 6>(0, 0);
    ff += eq.hth / cfg.residual_var_m2;
    let e = x.boxminus(prior);
    let mut rhs = -(*p_inv * e);
    let mut top = rhs.fixed_rows_mut::<6>(0);
    top -= eq.htz / cfg.residual_var_m2;
    let info_inv = info.try_inverse()?;
    let dx: ErrVec = info_inv * rhs;
    Some((dx, info_inv))
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Rotation3;

    fn state_at(pos: Vector3<f64>) -> State {
        State { pos, ..State::at_rest() }
    }

    /// A floor alone pins height, roll and pitch; x, y and yaw are left to the IMU.
    #[test]
    fn a_floor_alone_corrects_height_and_leaves_the_unseen_directions() {
        let mut map = VoxelMap::new(0.5, 20, 0.05, 100.0);
        for i in -40..=40 {
            for j in -40..=40 {
                map.insert(Vector3::new(f64::from(i) * 0.1, f64::from(j) * 0.1, 0.0));
            }
        }
        // The sensor 1 m up, believed 1.1 m up and 0.2 m off in x.
        let points: Vec<Vector3<f64>> = (-8..=8)
            .flat_map(|i| (-8..=8).map(move |j| Vector3::new(f64::from(i) * 0.2, f64::from(j) * 0.2, -1.0)))
            .collect();
        let mut state = state_at(Vector3::new(0.2, 0.0, 1.1));
        let mut cov = Cov::identity() * 1e-2;
        let report = update(&mut state, &mut cov, &points, &map, &UpdateConfig::default());
        assert!(report.converged && report.matched > 200, "{report:?}");
        assert!(report.weak_directions >= 3, "{report:?}");
        assert_eq!(weak_axes_names(report.weak_axes), "rz+x+y", "{report:?}");
        assert!(report.degeneracy_index < 1e-6, "{report:?}");
        assert!((state.pos.z - 1.0).abs() < 0.01, "height corrected: {}", state.pos.z);
        assert!((state.pos.x - 0.2).abs() < 1e-6 && state.pos.y.abs() < 1e-6, "x, y kept: {:?}", state.pos);
    }

    /// A floor seen 1 m below, its points scattered by `noise_m` either way.
    fn floor_scan(noise_m: f64) -> (VoxelMap, Vec<Vector3<f64>>) {
        let mut map = VoxelMap::new(0.5, 20, 0.05, 100.0);
        for i in -40..=40 {
            for j in -40..=40 {
                map.insert(Vector3::new(f64::from(i) * 0.1, f64::from(j) * 0.1, 0.0));
            }
        }
        let points = (-8..=8)
            .flat_map(|i| (-8..=8).map(move |j| (i, j)))
            .map(|(i, j)| {
                let sign = if (i + j) % 2 == 0 { 1.0 } else { -1.0 };
                Vector3::new(f64::from(i) * 0.2, f64::from(j) * 0.2, -1.0 + sign * noise_m)
            })
            .collect();
        (map, points)
    }

    #[test]
    fn a_scan_that_fits_loosely_weighs_less_and_a_tight_one_as_before() {
        let cfg = UpdateConfig { fit_rms_ref_m: 0.02, ..UpdateConfig::default() };
        let run = |noise_m: f64, cfg: &UpdateConfig, weighed: bool| {
            let (map, points) = floor_scan(noise_m);
            let mut state = state_at(Vector3::new(0.0, 0.0, 1.05));
            let mut cov = Cov::identity() * 1e-2;
            let cfg = if weighed { *cfg } else { UpdateConfig { fit_rms_ref_m: 0.0, ..*cfg } };
            let report = update(&mut state, &mut cov, &points, &map, &cfg);
            (state.pos.z, cov[(5, 5)], report)
        };
        // Tight: the same as the plain update.
        assert_eq!(run(0.005, &cfg, true), run(0.005, &cfg, false));
        // Loose (6 cm RMS): the height's variance after the scan grows about (0.06 / 0.02)^2 = 9 times.
        let (_, var_plain, plain) = run(0.06, &cfg, false);
        let (_, var_weighed, weighed) = run(0.06, &cfg, true);
        assert!(plain.rms_m > 0.05 && weighed.matched > 200, "{plain:?} {weighed:?}");
        let grown = var_weighed / var_plain;
        assert!((6.0..12.0).contains(&grown), "variance grown {grown:.1} times");
    }

    /// A floor and a narrow far wall seen from 1 m up: yaw is weakly but truly constrained
    /// (the aisle of the auditorium is like this) and a yaw error must be corrected, not left.
    #[test]
    fn a_weak_but_real_yaw_is_corrected() {
        let mut map = VoxelMap::new(0.5, 20, 0.05, 100.0);
        let mut world = Vec::new();
        for i in -30..=30 {
            for j in -30..=30 {
                world.push(Vector3::new(f64::from(i) * 0.1, f64::from(j) * 0.1, 0.0));
            }
        }
        for j in -6..=6 {
            for k in 0..=20 {
                world.push(Vector3::new(10.0, f64::from(j) * 0.1, f64::from(k) * 0.1));
            }
        }
        // A short wall beside the sensor pins y with little lever arm for yaw.
        for i in -5..=5 {
            for k in 0..=15 {
                world.push(Vector3::new(f64::from(i) * 0.1, 2.0, f64::from(k) * 0.1));
            }
        }
        for p in &world {
            map.insert(*p);
        }
        let sensor = Vector3::new(0.0, 0.0, 1.0);
        let points: Vec<Vector3<f64>> = world.iter().step_by(3).map(|p| p - sensor).collect();
        let run = |cfg: &UpdateConfig| {
            let mut state = state_at(sensor);
            state.rot = Rotation3::from_euler_angles(0.0, 0.0, 1f64.to_radians());
            let mut cov = Cov::identity() * 1e-2;
            let report = update(&mut state, &mut cov, &points, &map, cfg);
            (state.rot.euler_angles().2.to_degrees(), report)
        };
        let (yaw_deg, report) = run(&UpdateConfig::default());
        assert!(report.degeneracy_index > 1e-4 && report.degeneracy_index < 5e-3, "{report:?}");
        assert!(report.weak_directions == 0 && yaw_deg.abs() < 0.1, "yaw corrected: {yaw_deg} deg, {report:?}");
        // The former threshold left that yaw to the IMU.
        let (yaw_deg, report) = run(&UpdateConfig { min_direction_info: 0.005, ..UpdateConfig::default() });
        assert!(report.weak_directions == 1 && yaw_deg.abs() > 0.5, "yaw left: {yaw_deg} deg, {report:?}");
    }
}
