//! Fine stage: trimmed point-to-plane ICP with a Huber loss, Gauss-Newton on SE(3)
//! (left-multiplied updates), and the quality metrics of the result.

use super::geometry::{exp_se3, Vec3, VoxelIndex};
use super::seen_from::{seen_from_opposite_sides, SeenFrom};
use nalgebra::{Isometry3, Matrix6, Point3, SymmetricEigen, Vector6};

/// The target prepared for ICP: reduced points with normals, indexed by voxel, and where known
/// the mean direction from each towards the sensors that saw it (empty: not known).
pub struct IcpTarget {
    pub index: VoxelIndex,
    pub normals: Vec<Option<Vec3>>,
    pub seen_from: Vec<Vec3>,
}

#[derive(Clone, Copy)]
pub struct IcpParams<'a> {
    pub max_correspondence_m: f64,
    pub trim_ratio: f64,
    pub huber_m: f64,
    pub max_iterations: u32,
    pub converged_update: f64,
    pub inlier_distance_m: f64,
    /// Correspondences within this residual make up the information matrix.
    pub degeneracy_residual_m: f64,
    /// A pair whose surfaces were seen from opposite sides of the target's plane, each at least
    /// this far along its normal, is dropped (0: never; see [`super::seen_from`]).
    pub opposite_min_side: f64,
    /// Which side the source's surfaces were seen from (in the source's frame).
    pub source_seen_from: &'a SeenFrom,
}

pub struct IcpResult {
    pub pose: Isometry3<f64>,
    pub iterations: u32,
    pub rms_residual_m: f64,
    pub inlier_ratio: f64,
    pub update_norm: f64,
    pub degeneracy_index: f64,
    /// The normalised information matrix behind the degeneracy index (target frame, rotations
    /// about `info_centre`, scaled by `info_radius_m`).
    pub information: Matrix6<f64>,
    pub info_centre: Vec3,
    pub info_radius_m: f64,
    pub correspondences: usize,
}

/// One correspondence: moved source point, target normal, signed point-to-plane residual.
struct Pair {
    q: Vec3,
    n: Vec3,
    r: f64,
}

fn correspondences(
    target: &IcpTarget,
    source: &[Vec3],
    source_seen: &[Vec3],
    pose: &Isometry3<f64>,
    p: &IcpParams,
    pairs: &mut Vec<Pair>,
) -> usize {
    pairs.clear();
    let mut inliers = 0;
    for (k, s) in source.iter().enumerate() {
        let q = (pose * Point3::from(*s)).coords;
        // Where both sides are known, the nearest surface seen from the same side: a thin
        // wall's other face, nearer, would pull the fit by the wall's thickness.
        let found = match source_seen.get(k) {
            Some(a) => {
                let a = pose.rotation * a;
                let same_side = |i: usize| match (target.normals.get(i), target.seen_from.get(i)) {
                    (Some(Some(n)), Some(b)) => !seen_from_opposite_sides(n, &a, b, p.opposite_min_side),
                    _ => true,
                };
                target.index.nearest_where(&q, p.max_correspondence_m, same_side)
            }
            None => target.index.nearest(&q, p.max_correspondence_m),
        };
        let Some((i, d2)) = found else { continue };
        if d2 <= p.inlier_distance_m * p.inlier_distance_m {
            inliers += 1;
        }
        let (Some(Some(n)), Some(t)) = (target.normals.get(i), target.index.points.get(i)) else { continue };
        pairs.push(Pair { q, n: *n, r: n.dot(&(q - t)) });
    }
    // Trimming: keep the best share by |residual| (partial overlap leaves the rest unmatched).
    let keep = ((pairs.len() as f64) * p.trim_ratio.clamp(0.0, 1.0)).ceil() as usize;
    if keep < pairs.len() {
        pairs.select_nth_unstable_by(keep, |a, b| a.r.abs().total_cmp(&b.r.abs()));
        pairs.truncate(keep);
    }
    inliers
}

/// Source points with a target point within `within_m` once moved by `pose`.
pub fn explained(target: &IcpTarget, source: &[Vec3], pose: &Isometry3<f64>, within_m: f64) -> usize {
    source.iter().filter(|s| target.index.nearest(&(pose * Point3::from(**s)).coords, within_m).is_some()).count()
}

/// Moves `pose` along the unit translation `direction` (target frame) alone, to the least
/// point-to-plane residual of every correspondence (no trimming, Huber weights). Trimmed ICP
/// drops exactly the few pairs that pin a degenerate direction (a corridor's far end, off by a
/// few decimetres, has the largest residuals), so it leaves such a direction where NDT put it.
pub fn settle_along(
    target: &IcpTarget,
    source: &[Vec3],
    pose: &Isometry3<f64>,
    direction: &Vec3,
    p: &IcpParams,
) -> Isometry3<f64> {
    let mut pose = *pose;
    let every = IcpParams { trim_ratio: 1.0, ..*p };
    let seen =
        if target.seen_from.is_empty() { Vec::new() } else { p.source_seen_from.at_each(source, p.opposite_min_side) };
    let mut pairs = Vec::with_capacity(source.len());
    for _ in 0..p.max_iterations {
        correspondences(target, source, &seen, &pose, &every, &mut pairs);
        let (mut num, mut den) = (0.0, 0.0);
        for pair in &pairs {
            let a = pair.n.dot(direction);
            let w = huber_weight(pair.r, p.huber_m);
            num += w * pair.r * a;
            den += w * a * a;
        }
        if den.is_nan() || den <= 1e-9 {
            break;
        }
        // At most half the correspondence distance a step, so pairs are found again.
        let limit = 0.5 * p.max_correspondence_m;
        let step = (-num / den).clamp(-limit, limit);
        pose = nalgebra::Translation3::from(direction * step) * pose;
        if step.abs() < p.converged_update {
            break;
        }
    }
    pose
}

/// The Huber loss's weight of a residual (1 within `huber_m`, falling as 1/|r| beyond).
fn huber_weight(r: f64, huber_m: f64) -> f64 {
    if r.abs() <= huber_m {
        1.0
    } else {
        huber_m / r.abs()
    }
}

/// Point-to-plane Jacobian row: d(nᵀ q)/dxi for q <- exp(xi) q.
fn jacobian(q: &Vec3, n: &Vec3) -> Vector6<f64> {
    let a = q.cross(n);
    Vector6::new(a.x, a.y, a.z, n.x, n.y, n.z)
}

pub fn refine(target: &IcpTarget, source: &[Vec3], pose: Isometry3<f64>, p: &IcpParams) -> IcpResult {
    let mut pose = pose;
    let seen =
        if target.seen_from.is_empty() { Vec::new() } else { p.source_seen_from.at_each(source, p.opposite_min_side) };
    let mut pairs = Vec::with_capacity(source.len());
    let mut iterations = 0;
    let mut update_norm = f64::INFINITY;
    for _ in 0..p.max_iterations {
        iterations += 1;
        correspondences(target, source, &seen, &pose, p, &mut pairs);
        if pairs.len() < 6 {
            break;
        }
        let mut h = Matrix6::zeros();
        let mut g = Vector6::zeros();
        for pair in &pairs {
            let j = jacobian(&pair.q, &pair.n);
            let w = huber_weight(pair.r, p.huber_m);
            h += w * j * j.transpose();
            g += w * pair.r * j;
        }
        let damping = 1e-9 * h.trace().max(1e-12);
        let Some(chol) = (h + Matrix6::identity() * damping).cholesky() else { break };
        let step = -chol.solve(&g);
        update_norm = step.norm();
        pose = exp_se3(&step) * pose;
        if update_norm < p.converged_update {
            break;
        }
    }
    let inliers = correspondences(target, source, &seen, &pose, p, &mut pairs);
    let rms_residual_m = if pairs.is_empty() {
        f64::INFINITY
    } else {
        (pairs.iter().map(|x| x.r * x.r).sum::<f64>() / pairs.len() as f64).sqrt()
    };
    let info = information(&pairs, p.degeneracy_residual_m);
    IcpResult {
        pose,
        iterations,
        rms_residual_m,
        inlier_ratio: if source.is_empty() { 0.0 } else { inliers as f64 / source.len() as f64 },
        update_norm,
        degeneracy_index: info.as_ref().map_or(0.0, |i| SymmetricEigen::new(i.0).eigenvalues.min().max(0.0)),
        information: info.as_ref().map_or_else(Matrix6::zeros, |i| i.0),
        info_centre: info.as_ref().map_or_else(Vec3::zeros, |i| i.1),
        info_radius_m: info.as_ref().map_or(0.0, |i| i.2),
        correspondences: pairs.len(),
    }
}

/// The point-to-plane information matrix `Σ JᵀJ / N`, made unit-free: rotations are taken about
/// the centroid of the matched points and scaled by their RMS distance from it, so every column of
/// J is at most 1 in size and its eigenvalues lie in [0, 1/3]. The smallest is the degeneracy
/// index: near 0, some direction (a corridor's axis, a rotation about a lone wall's normal) is
/// not constrained by the geometry; a box-like room gives about 0.05-0.2. Returns the matrix,
/// the centroid and the RMS radius; `None` with fewer than 6 pairs.
///
/// Only pairs with a residual within `tight_m` add to the sum, which is still divided by every
/// pair: misfit points (a wall seen at a slight angle off its place) would otherwise look like
/// constraints, and a result that fits only in part is only partly pinned down.
fn information(pairs: &[Pair], tight_m: f64) -> Option<(Matrix6<f64>, Vec3, f64)> {
    let all = pairs.len() as f64;
    let pairs: Vec<&Pair> = pairs.iter().filter(|p| p.r.abs() <= tight_m).collect();
    if pairs.len() < 6 {
        return None;
    }
    let n = pairs.len() as f64;
    let centroid = pairs.iter().map(|p| p.q).sum::<Vec3>() / n;
    let radius = (pairs.iter().map(|p| (p.q - centroid).norm_squared()).sum::<f64>() / n).sqrt().max(1e-6);
    let mut h = Matrix6::zeros();
    for p in pairs {
        let a = (p.q - centroid).cross(&p.n) / radius;
        let j = Vector6::new(a.x, a.y, a.z, p.n.x, p.n.y, p.n.z);
        h += j * j.transpose();
    }
    h /= all;
    Some((h, centroid, radius))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A corridor along x: walls (normals ±y), floor and ceiling (normals ±z), fitting tightly;
    /// plus a share of misfit points whose nearest planes face along x, far off their residual.
    fn corridor(misfit_residual_m: f64) -> Vec<Pair> {
        let mut rnd = crate::rng::uniform(7);
        let mut pairs = Vec::new();
        for i in 0..400 {
            let q = Vec3::new(rnd() * 20.0 - 10.0, rnd() * 2.0 - 1.0, rnd() * 2.5);
            let n = match i % 4 {
                0 => Vec3::y(),
                1 => -Vec3::y(),
                2 => Vec3::z(),
                _ => -Vec3::z(),
            };
            pairs.push(Pair { q, n, r: (rnd() - 0.5) * 0.02 });
        }
        for _ in 0..60 {
            let q = Vec3::new(rnd() * 20.0 - 10.0, rnd() * 2.0 - 1.0, rnd() * 2.5);
            pairs.push(Pair { q, n: Vec3::x(), r: misfit_residual_m });
        }
        pairs
    }

    fn index(pairs: &[Pair], tight_m: f64) -> f64 {
        information(pairs, tight_m).map_or(0.0, |i| SymmetricEigen::new(i.0).eigenvalues.min())
    }

    #[test]
    fn misfit_points_do_not_pin_a_corridor_down() {
        let misfit = corridor(0.2);
        // Every pair counted: the misfits hold the corridor's axis.
        assert!(index(&misfit, f64::INFINITY) > 0.01, "{}", index(&misfit, f64::INFINITY));
        // Only the pairs that fit: the axis is free.
        assert!(index(&misfit, 0.05) < 1e-6, "{}", index(&misfit, 0.05));
        // Had the same points fitted, they would pin it down with either count.
        let fitting = corridor(0.01);
        assert!(index(&fitting, 0.05) > 0.01);
        assert!((index(&fitting, 0.05) - index(&fitting, f64::INFINITY)).abs() < 1e-12);
    }

    #[test]
    fn a_partial_fit_is_only_partly_pinned_down() {
        // Half the pairs far off: the tight half still spans every direction, at half the weight.
        let mut pairs = corridor(0.01);
        let tight = index(&pairs, 0.05);
        let n = pairs.len();
        pairs.extend((0..n).map(|i| Pair { q: Vec3::new(i as f64 * 0.01, 0.0, 0.0), n: Vec3::y(), r: 0.3 }));
        let half = index(&pairs, 0.05);
        assert!((half - tight / 2.0).abs() < 1e-9, "{half} vs {tight}");
        assert!(information(&pairs[..5], 0.05).is_none());
    }
}
