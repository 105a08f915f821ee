//! Global registration from any start. Both clouds are levelled by their IMUs, so a pose
//! between them is four numbers (x, y, z, yaw). Points where the surface bends (corners,
//! edges, furniture) are described by FPFH-like histograms that use gravity (heights of the
//! neighbours, how vertical their normals are) as well as the usual angles; each window point
//! is matched to the map points of the nearest descriptors, and pairs of matches vote for a
//! pose (two matches fix yaw and translation). The best distinct poses seed the same NDT + ICP
//! attempts and acceptance tests as the yaw grid's seeds: this stage only proposes.

use super::config::AlignConfig;
use super::geometry::{local_shapes, thin, Vec3, VoxelIndex};
use crate::voxel_hash::voxel_downsample;
use nalgebra::{Isometry3, Translation3, UnitQuaternion};

/// Histogram bins of each feature: the angle between the centre's normal and the line to a
/// neighbour, the neighbour's normal and that line, the two normals (all as |cos|: normals of
/// a map have no consistent sign), the neighbour's height above the centre, how vertical the
/// neighbour's normal is; then how vertical the centre's own normal is.
const BINS: [usize; 6] = [5, 5, 5, 8, 3, 3];
pub const DIMS: usize = 29;

/// Neighbours a descriptor or normal is computed from, at most.
const MAX_NEIGHBOURS: usize = 64;

/// A cloud's keypoints and their descriptors.
pub struct Described {
    pub points: Vec<Vec3>,
    pub descriptors: Vec<[f32; DIMS]>,
}

/// One pose the consensus proposes (source into target) and the matches that agree with it.
#[derive(Clone, Debug)]
pub struct Candidate {
    pub pose: Isometry3<f64>,
    pub votes: usize,
}

/// Adds `value` (in [lo, hi]) to `bins` bins starting at `offset`.
fn vote(h: &mut [f32; DIMS], offset: usize, bins: usize, value: f64, lo: f64, hi: f64, weight: f32) {
    let x = ((value - lo) / (hi - lo)).clamp(0.0, 1.0);
    let b = ((x * bins as f64) as usize).min(bins - 1);
    if let Some(slot) = h.get_mut(offset + b) {
        *slot += weight;
    }
}

/// The point-pair histogram of one point over its neighbours (the "simplified" PFH).
fn spfh(p: &Vec3, n: &Vec3, neighbours: &[(Vec3, Vec3)]) -> [f32; DIMS] {
    let mut h = [0.0f32; DIMS];
    if neighbours.is_empty() {
        return h;
    }
    let w = 1.0 / neighbours.len() as f32;
    let radius = neighbours.iter().map(|(q, _)| (q - p).norm()).fold(1e-6, f64::max);
    let offsets: Vec<usize> = BINS.iter().scan(0, |acc, b| Some(std::mem::replace(acc, *acc + b))).collect();
    let at = |k: usize| offsets.get(k).copied().unwrap_or(0);
    for (q, nq) in neighbours {
        let d = q - p;
        let dist = d.norm();
        if dist <= 1e-9 {
            continue;
        }
        let u = d / dist;
        vote(&mut h, at(0), BINS[0], n.dot(&u).abs(), 0.0, 1.0, w);
        vote(&mut h, at(1), BINS[1], nq.dot(&u).abs(), 0.0, 1.0, w);
        vote(&mut h, at(2), BINS[2], n.dot(nq).abs(), 0.0, 1.0, w);
        vote(&mut h, at(3), BINS[3], d.z / radius, -1.0, 1.0, w);
        vote(&mut h, at(4), BINS[4], nq.z.abs(), 0.0, 1.0, w);
    }
    vote(&mut h, at(5), BINS[5], n.z.abs(), 0.0, 1.0, 1.0);
    h
}

/// Keypoints of `points` (reduced to `global_voxel_m`; those where the surface bends, thinned
/// evenly to `max_keypoints`) and their descriptors: each point's histogram averaged with its
/// neighbours' (weighted by inverse distance), as FPFH does.
pub fn describe(points: &[Vec3], c: &AlignConfig, max_keypoints: usize) -> Described {
    let reduced = voxel_downsample(points, c.global_voxel_m);
    let normal_index = VoxelIndex::new(reduced.clone(), c.global_normal_radius_m);
    let shape: Vec<Option<(Vec3, f64)>> =
        local_shapes(&normal_index, MAX_NEIGHBOURS).into_iter().map(|s| s.map(|s| (s.normal, s.curvature()))).collect();
    let index = VoxelIndex::new(reduced, c.global_radius_m);
    let mut nn = Vec::with_capacity(MAX_NEIGHBOURS);
    let neighbours_of = |i: usize, nn: &mut Vec<(f64, u32)>| -> Vec<usize> {
        let Some(q) = index.points.get(i) else { return Vec::new() };
        index.k_nearest(q, MAX_NEIGHBOURS, nn);
        nn.iter().map(|&(_, j)| j as usize).filter(|&j| j != i).collect()
    };
    let spfhs: Vec<Option<[f32; DIMS]>> = (0..index.points.len())
        .map(|i| {
            let (p_i, (n_i, _)) = (index.points.get(i)?, shape.get(i).copied().flatten()?);
            let near: Vec<(Vec3, Vec3)> = neighbours_of(i, &mut nn)
                .into_iter()
                .filter_map(|j| Some((*index.points.get(j)?, shape.get(j).copied().flatten()?.0)))
                .collect();
            (near.len() >= 5).then(|| spfh(p_i, &n_i, &near))
        })
        .collect();
    let salient: Vec<usize> = (0..index.points.len())
        .filter(|&i| {
            spfhs.get(i).is_some_and(Option::is_some)
                && shape.get(i).copied().flatten().is_some_and(|(_, k)| k >= c.global_min_curvature)
        })
        .collect();
    let keep = thin(salient, max_keypoints);
    let mut out = Described { points: Vec::with_capacity(keep.len()), descriptors: Vec::with_capacity(keep.len()) };
    for i in keep {
        let (Some(p_i), Some(Some(own))) = (index.points.get(i), spfhs.get(i)) else { continue };
        let mut sum = [0.0f32; DIMS];
        let mut total = 0.0f32;
        for j in neighbours_of(i, &mut nn) {
            let (Some(q), Some(Some(h))) = (index.points.get(j), spfhs.get(j)) else { continue };
            let w = (1.0 / (q - p_i).norm().max(c.global_voxel_m)) as f32;
            for (s, v) in sum.iter_mut().zip(h) {
                *s += w * v;
            }
            total += w;
        }
        let mut d = *own;
        if total > 0.0 {
            for (x, s) in d.iter_mut().zip(sum) {
                *x = 0.5 * *x + 0.5 * s / total;
            }
        }
        out.points.push(*p_i);
        out.descriptors.push(d);
    }
    out
}

fn distance2(a: &[f32; DIMS], b: &[f32; DIMS]) -> f32 {
    a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum()
}

/// For each source keypoint, the target keypoints of its `k` nearest descriptors: (source
/// point, target point) pairs.
pub fn matches(source: &Described, target: &Described, k: usize) -> Vec<(Vec3, Vec3)> {
    let mut out = Vec::with_capacity(source.points.len() * k);
    let mut best: Vec<(f32, usize)> = Vec::with_capacity(k + 1);
    for (s, ds) in source.points.iter().zip(&source.descriptors) {
        best.clear();
        for (j, dt) in target.descriptors.iter().enumerate() {
            let d = distance2(ds, dt);
            if best.len() < k || best.last().is_some_and(|b| d < b.0) {
                let at = best.partition_point(|b| b.0 <= d);
                best.insert(at, (d, j));
                best.truncate(k);
            }
        }
        out.extend(best.iter().filter_map(|&(_, j)| Some((*s, *target.points.get(j)?))));
    }
    out
}

/// The 4-DoF pose two matches imply, when they agree on distances (horizontal and vertical)
/// and lie far enough apart horizontally to fix the yaw.
fn pose_from_pair(a: &(Vec3, Vec3), b: &(Vec3, Vec3), tolerance_m: f64) -> Option<(f64, Vec3)> {
    let (s, t) = (b.0 - a.0, b.1 - a.1);
    let (hs, ht) = (s.xy().norm(), t.xy().norm());
    if hs < 1.0 || (hs - ht).abs() > tolerance_m || (s.z - t.z).abs() > tolerance_m {
        return None;
    }
    let yaw = t.y.atan2(t.x) - s.y.atan2(s.x);
    let rot = UnitQuaternion::from_euler_angles(0.0, 0.0, yaw);
    let translation = (a.1 + b.1) / 2.0 - rot * ((a.0 + b.0) / 2.0);
    Some((yaw, translation))
}

fn votes(pairs: &[(Vec3, Vec3)], rot: &UnitQuaternion<f64>, translation: &Vec3, inlier_m: f64) -> usize {
    let r2 = inlier_m * inlier_m;
    pairs.iter().filter(|(s, t)| (rot * s + translation - t).norm_squared() <= r2).count()
}

/// The 4-DoF least-squares pose of the matches that agree with a hypothesis (yaw from the
/// horizontal cross-covariance, translation from the centroids).
fn refit(pairs: &[(Vec3, Vec3)], rot: &UnitQuaternion<f64>, translation: &Vec3, inlier_m: f64) -> Option<(f64, Vec3)> {
    let r2 = inlier_m * inlier_m;
    let agree: Vec<&(Vec3, Vec3)> =
        pairs.iter().filter(|(s, t)| (rot * s + translation - t).norm_squared() <= r2).collect();
    if agree.len() < 3 {
        return None;
    }
    let n = agree.len() as f64;
    let cs = agree.iter().map(|p| p.0).sum::<Vec3>() / n;
    let ct = agree.iter().map(|p| p.1).sum::<Vec3>() / n;
    let (mut sin, mut cos) = (0.0, 0.0);
    for (s, t) in &agree {
        let (a, b) = (s - cs, t - ct);
        cos += a.x * b.x + a.y * b.y;
        sin += a.x * b.y - a.y * b.x;
    }
    let yaw = sin.atan2(cos);
    let r = UnitQuaternion::from_euler_angles(0.0, 0.0, yaw);
    Some((yaw, ct - r * cs))
}

/// The consensus: `global_pair_samples` random pairs of matches each propose a pose, scored by
/// the matches within `global_inlier_m` of it; the best are refitted on their agreeing matches
/// and the `global_candidates` best distinct ones (1 m or 15 deg apart) returned, most votes
/// first. The samples come from a fixed seed: the same matches give the same candidates.
pub fn consensus(pairs: &[(Vec3, Vec3)], c: &AlignConfig) -> Vec<Candidate> {
    if pairs.len() < 2 {
        return Vec::new();
    }
    let mut uniform = crate::rng::uniform(0x9E37_79B9_7F4A_7C15);
    let mut pick = || ((uniform() * pairs.len() as f64) as usize).min(pairs.len() - 1);
    let inlier_m = c.global_inlier_m;
    let mut found: Vec<(usize, f64, Vec3)> = Vec::new();
    for _ in 0..c.global_pair_samples {
        let (i, j) = (pick(), pick());
        let (Some(a), Some(b)) = (pairs.get(i), pairs.get(j)) else { continue };
        let Some((yaw, translation)) = pose_from_pair(a, b, 0.5 * inlier_m) else { continue };
        let rot = UnitQuaternion::from_euler_angles(0.0, 0.0, yaw);
        let v = votes(pairs, &rot, &translation, inlier_m);
        if v >= 3 {
            found.push((v, yaw, translation));
        }
    }
    found.sort_by_key(|f| std::cmp::Reverse(f.0));
    let mut out: Vec<Candidate> = Vec::new();
    for (_, yaw, translation) in found.into_iter().take(20 * c.global_candidates.max(1)) {
        let rot = UnitQuaternion::from_euler_angles(0.0, 0.0, yaw);
        let (yaw, translation) = refit(pairs, &rot, &translation, inlier_m).unwrap_or((yaw, translation));
        let rot = UnitQuaternion::from_euler_angles(0.0, 0.0, yaw);
        let pose = Isometry3::from_parts(Translation3::from(translation), rot);
        let distinct = |c: &Candidate| {
            let (dt, da) = super::geometry::pose_error(&c.pose, &pose);
            dt >= 1.0 || da >= 15.0
        };
        if out.iter().all(distinct) {
            out.push(Candidate { pose, votes: votes(pairs, &rot, &translation, inlier_m) });
        }
    }
    out.sort_by_key(|c| std::cmp::Reverse(c.votes));
    out.truncate(c.global_candidates);
    out
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use crate::align::geometry::pose_xyz_yaw;

    fn params() -> AlignConfig {
        AlignConfig { global_candidates: 8, ..AlignConfig::default() }
    }

    /// An L-shaped set of rooms with a few boxes (furniture) on the floor: enough structure
    /// that a corner of it is recognised.
    fn building() -> Vec<Vec3> {
        let mut pts = Vec::new();
        let step = 0.1;
        let wall = |pts: &mut Vec<Vec3>, a: (f64, f64), b: (f64, f64)| {
            let len = ((b.0 - a.0).powi(2) + (b.1 - a.1).powi(2)).sqrt();
            let n = (len / step) as usize;
            for i in 0..=n {
                let f = i as f64 / n as f64;
                for k in 0..=27 {
                    pts.push(Vec3::new(a.0 + f * (b.0 - a.0), a.1 + f * (b.1 - a.1), k as f64 * step));
                }
            }
        };
        for (a, b) in [
            ((0.0, 0.0), (12.0, 0.0)),
            ((12.0, 0.0), (12.0, 5.0)),
            ((12.0, 5.0), (5.0, 5.0)),
            ((5.0, 5.0), (5.0, 12.0)),
            ((5.0, 12.0), (0.0, 12.0)),
            ((0.0, 12.0), (0.0, 0.0)),
            ((3.0, 0.0), (3.0, 2.0)),
            ((8.0, 5.0), (8.0, 3.5)),
        ] {
            wall(&mut pts, a, b);
        }
        for (cx, cy, sx, sy, h) in [(2.0, 9.0, 1.2, 0.6, 0.8), (9.5, 1.0, 0.5, 0.5, 1.1), (1.0, 4.0, 0.8, 1.6, 0.45)] {
            let mut x = cx - sx / 2.0;
            while x <= cx + sx / 2.0 {
                let mut y = cy - sy / 2.0;
                while y <= cy + sy / 2.0 {
                    pts.push(Vec3::new(x, y, h));
                    let mut z = 0.0;
                    while z < h {
                        if (x - (cx - sx / 2.0)).abs() < 1e-9 || (y - (cy - sy / 2.0)).abs() < 1e-9 {
                            pts.push(Vec3::new(x, y, z));
                        }
                        z += step;
                    }
                    y += step;
                }
                x += step;
            }
        }
        pts
    }

    #[test]
    fn a_window_of_part_of_the_building_is_found_from_far_away() {
        let map = building();
        let p = params();
        // The window: what lies within 6 m of (3, 8), seen from a frame 20 m away and turned 130 deg.
        let truth = pose_xyz_yaw(3.0, 8.0, 1.5, 130.0);
        let window: Vec<Vec3> = map
            .iter()
            .filter(|q| (q.xy() - nalgebra::Vector2::new(3.0, 8.0)).norm() < 6.0)
            .map(|q| truth.inverse_transform_point(&nalgebra::Point3::from(*q)).coords)
            .collect();
        let target = describe(&map, &p, p.global_target_keypoints);
        let source = describe(&window, &p, p.global_source_keypoints);
        assert!(source.points.len() > 30 && target.points.len() > source.points.len());
        let cands = consensus(&matches(&source, &target, p.global_matches_per_point), &p);
        let (dt, da) = crate::align::geometry::pose_error(&cands[0].pose, &truth);
        assert!(dt < 0.3 && da < 3.0, "best candidate {dt:.2} m / {da:.1} deg off; {cands:?}");
    }

    #[test]
    fn too_few_matches_propose_nothing() {
        assert!(consensus(&[], &params()).is_empty());
        let one = [(Vec3::zeros(), Vec3::zeros())];
        assert!(consensus(&one, &params()).is_empty());
    }
}
