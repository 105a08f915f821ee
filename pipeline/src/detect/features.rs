//! Geometry of one cluster: its oriented box (minimum-area rectangle over the floor, height
//! above it), shape of its voxel covariance, and how many of its points lie on the box's faces.

use super::cluster::Grid;
use nalgebra::{Matrix3, SymmetricEigen, Vector3};

/// What the scorer knows about a cluster. Heights are above the floor; x, y in the world.
#[derive(Clone, Debug, PartialEq)]
pub struct ClusterFeatures {
    /// Points of the window in the cluster, and occupied voxels.
    pub points: usize,
    pub voxels: usize,
    /// Box centre (x, y in the world, height above floor), size (length along `yaw_rad` >= width,
    /// height) and heading of the length axis.
    pub centre: Vector3<f64>,
    pub size: Vector3<f64>,
    pub yaw_rad: f64,
    /// Lowest and highest point above the floor.
    pub bottom_m: f64,
    pub top_m: f64,
    /// Share of the points within the face tolerance of a side of the box, turned to the heading
    /// (3 deg steps) that puts the most points there (not the top: the field of view cuts people
    /// seen up close flat at the top). NaN when not measured: no face share could have made the
    /// cluster a person (see [`features`]).
    pub face_share: f64,
    /// Share of the points within the face tolerance of the top alone (a box's flat top).
    pub top_share: f64,
    /// From the eigenvalues l1 >= l2 >= l3 of the voxel centres' covariance.
    pub linearity: f64,
    pub planarity: f64,
    /// Root-mean-square distance of the points to their best-fit plane (the square root of the
    /// smallest eigenvalue of their covariance): a wall strip, table side or box face is a few
    /// centimetres thick (range noise), a body is thicker.
    pub thickness_m: f64,
    /// Horizontal distance from the sensor to the box centre.
    pub range_m: f64,
}

/// Distance of a voxel centre to a side of the rectangle to count as on it (centres sit up to
/// half a voxel inside a face).
const EDGE_TOLERANCE_M: f64 = 0.06;

/// The face share is the largest over headings this far apart around the quarter turn.
const FACE_YAW_STEP_DEG: f64 = 3.0;

/// Variance ratio of the footprint's axes above which its major axis sets the heading.
const ELONGATED_RATIO: f64 = 4.0;

/// Heading of the footprint's major axis and the ratio of its variances (major / minor).
fn major_axis(centres: &[Vector3<f64>]) -> Option<(f64, f64)> {
    let n = centres.len() as f64;
    if centres.len() < 3 {
        return None;
    }
    let (mx, my) = (centres.iter().map(|p| p.x).sum::<f64>() / n, centres.iter().map(|p| p.y).sum::<f64>() / n);
    let (mut sxx, mut syy, mut sxy) = (0.0, 0.0, 0.0);
    for p in centres {
        let (dx, dy) = (p.x - mx, p.y - my);
        sxx += dx * dx;
        syy += dy * dy;
        sxy += dx * dy;
    }
    // Eigenvalues of the 2x2 covariance, and the major axis' direction.
    let half_trace = (sxx + syy) / 2.0;
    let disc = (((sxx - syy) / 2.0).powi(2) + sxy * sxy).sqrt();
    let (major, minor) = (half_trace + disc, half_trace - disc);
    let yaw = 0.5 * (2.0 * sxy).atan2(sxx - syy);
    (minor > 1e-12).then_some((yaw, major / minor)).or(Some((yaw, f64::MAX))).filter(|_| major > 0.0)
}

/// The 2nd and 98th percentiles of `v` (0 when empty).
fn quantiles(mut v: Vec<f64>) -> (f64, f64) {
    let Some(last) = v.len().checked_sub(1) else { return (0.0, 0.0) };
    let mut at = |f: f64| {
        let i = ((last as f64 * f).round() as usize).min(last);
        *v.select_nth_unstable_by(i, f64::total_cmp).1
    };
    (at(0.02), at(0.98))
}

/// How many of `points` lie within `tolerance_m` of a side of their box turned to `yaw`, the
/// sides at the 2nd and 98th percentiles.
fn on_faces(points: &[Vector3<f64>], yaw: f64, tolerance_m: f64) -> usize {
    let (s, c) = yaw.sin_cos();
    let local: Vec<(f64, f64)> = points.iter().map(|p| (c * p.x + s * p.y, -s * p.x + c * p.y)).collect();
    let (x0, x1) = quantiles(local.iter().map(|q| q.0).collect());
    let (y0, y1) = quantiles(local.iter().map(|q| q.1).collect());
    local
        .iter()
        .filter(|(x, y)| (x - x0).abs().min((x1 - x).abs()).min((y - y0).abs()).min((y1 - y).abs()) < tolerance_m)
        .count()
}

/// The box along `yaw_rad` (about z) around `points`: their least and greatest coordinates in
/// the frame turned by it.
pub(super) fn box_along(yaw_rad: f64, points: impl IntoIterator<Item = Vector3<f64>>) -> (Vector3<f64>, Vector3<f64>) {
    let (s, c) = yaw_rad.sin_cos();
    let mut lo = Vector3::repeat(f64::MAX);
    let mut hi = Vector3::repeat(f64::MIN);
    for p in points {
        let q = Vector3::new(c * p.x + s * p.y, -s * p.x + c * p.y, p.z);
        lo = lo.inf(&q);
        hi = hi.sup(&q);
    }
    (lo, hi)
}

/// A point of the frame turned by `yaw_rad` (about z), in the world.
pub(super) fn from_frame(yaw_rad: f64, q: Vector3<f64>) -> Vector3<f64> {
    let (s, c) = yaw_rad.sin_cos();
    Vector3::new(c * q.x - s * q.y, s * q.x + c * q.y, q.z)
}

/// `points` maps a window index to (x, y, height above floor). The face share, the costliest
/// feature (a heading search), is measured only where `worth_faces` says so of the features
/// with a face share of 0 (the best a scorer can see): elsewhere it is left NaN.
pub fn features(
    grid: &Grid,
    cluster: &[u32],
    points: &dyn Fn(u32) -> Option<Vector3<f64>>,
    sensor_xy: [f64; 2],
    face_tolerance_m: f64,
    worth_faces: &dyn Fn(&ClusterFeatures) -> bool,
) -> Option<ClusterFeatures> {
    let centres: Vec<Vector3<f64>> =
        cluster.iter().filter_map(|&v| grid.voxels.get(v as usize)).map(|v| v.centre).collect();
    if centres.is_empty() {
        return None;
    }
    let raw: Vec<Vector3<f64>> = grid.points_of_cluster(cluster).filter_map(points).collect();
    if raw.is_empty() {
        return None;
    }

    // Heading: the rectangle whose sides carry the most voxel centres (a box's faces, seen as
    // an L from a corner, fit only when aligned; the minimum-area rectangle of an L is
    // ambiguous), the smaller area breaking ties. 3 deg steps, then 0.5 deg around the best.
    let support = |yaw: f64| {
        let (s, c) = yaw.sin_cos();
        let (mut a0, mut a1, mut b0, mut b1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
        for p in &centres {
            let (a, b) = (c * p.x + s * p.y, -s * p.x + c * p.y);
            a0 = a0.min(a);
            a1 = a1.max(a);
            b0 = b0.min(b);
            b1 = b1.max(b);
        }
        let on = centres
            .iter()
            .filter(|p| {
                let (a, b) = (c * p.x + s * p.y, -s * p.x + c * p.y);
                (a - a0).min(a1 - a).min(b - b0).min(b1 - b) < EDGE_TOLERANCE_M
            })
            .count();
        on as f64 - (a1 - a0) * (b1 - b0)
    };
    // Each heading's support once (a comparator calling it twice per pair costs double).
    let best_of = |yaws: &mut dyn Iterator<Item = f64>, default: f64| {
        yaws.map(|yaw| (yaw, support(yaw))).max_by(|a, b| a.1.total_cmp(&b.1)).map_or(default, |(yaw, _)| yaw)
    };
    let best = best_of(&mut (0..30).map(|k| f64::from(k).to_radians() * 3.0), 0.0);
    let edge_yaw = best_of(&mut (-6..=6).map(|k| best + f64::from(k).to_radians() * 0.5), best);
    // The box: in the frame of the edges, or of the footprint's major axis when that is
    // elongated (a body lying, a walker mid-stride: the edges of a rounded outline do not give
    // a heading reliably) and the smaller footprint.
    let frame_box = |yaw: f64| {
        let (lo, hi) = box_along(yaw, raw.iter().copied());
        (yaw, lo, hi)
    };
    let area = |b: &(f64, Vector3<f64>, Vector3<f64>)| (b.2.x - b.1.x) * (b.2.y - b.1.y);
    let edge_box = frame_box(edge_yaw);
    let (yaw, lo, hi) = match major_axis(&centres) {
        Some((axis_yaw, ratio)) if ratio >= ELONGATED_RATIO => {
            let axis_box = frame_box(axis_yaw);
            if area(&axis_box) < area(&edge_box) {
                axis_box
            } else {
                edge_box
            }
        }
        _ => edge_box,
    };
    let size = hi - lo;
    let centre = from_frame(yaw, (lo + hi) / 2.0);
    // Points on a side (the top may be the field of view's edge, the bottom is cut by the floor
    // band), against faces placed at the 2nd and 98th percentiles: range noise puts a few points of a flat face centimetres
    // outside it, and the extremes would move the faces off the bulk.
    // The faces are those of the heading that puts the most points on them: a box's own. The
    // edge frame alone is not enough: seen through the LIO's poses, a wall end's L flickered
    // between 0.35 and 0.9 from one window to the next (the tactical house's front door).
    let sample: Vec<Vector3<f64>> = raw.iter().step_by((raw.len() / 600).max(1)).copied().collect();
    let seen = sample.len();
    let (_, z1) = quantiles(sample.iter().map(|p| p.z).collect());
    let on_top = sample.iter().filter(|p| (z1 - p.z).abs() < face_tolerance_m).count();
    // Thickness from the raw points (the voxel centres are smoothed).
    let rn = sample.len().max(1) as f64;
    let rmean = sample.iter().sum::<Vector3<f64>>() / rn;
    let mut rcov = Matrix3::zeros();
    for p in &sample {
        let q = p - rmean;
        rcov += q * q.transpose();
    }
    let thickness_m = SymmetricEigen::new(rcov / rn).eigenvalues.min().max(0.0).sqrt();
    let (length, width, yaw) =
        if size.x >= size.y { (size.x, size.y, yaw) } else { (size.y, size.x, yaw + std::f64::consts::FRAC_PI_2) };

    let n = centres.len() as f64;
    let mean = centres.iter().sum::<Vector3<f64>>() / n;
    let mut cov = Matrix3::zeros();
    for p in &centres {
        let q = p - mean;
        cov += q * q.transpose();
    }
    let mut ev: Vec<f64> = SymmetricEigen::new(cov / n).eigenvalues.iter().map(|e| e.max(0.0)).collect();
    ev.sort_by(|a, b| b.total_cmp(a));
    let (l1, l2, l3) =
        (ev.first().copied().unwrap_or(0.0), ev.get(1).copied().unwrap_or(0.0), ev.get(2).copied().unwrap_or(0.0));
    let (linearity, planarity) = if l1 > 0.0 { ((l1 - l2) / l1, (l2 - l3) / l1) } else { (0.0, 0.0) };

    let mut f = ClusterFeatures {
        points: raw.len(),
        voxels: centres.len(),
        centre,
        size: Vector3::new(length, width, size.z),
        yaw_rad: wrap(yaw),
        bottom_m: lo.z,
        top_m: hi.z,
        face_share: 0.0,
        top_share: on_top as f64 / seen.max(1) as f64,
        linearity,
        planarity,
        thickness_m,
        range_m: (centre.x - sensor_xy[0]).hypot(centre.y - sensor_xy[1]),
    };
    f.face_share = if worth_faces(&f) { face_share(&raw, &sample, edge_yaw, face_tolerance_m) } else { f64::NAN };
    Some(f)
}

/// The share of `sample` on the faces of its box at the heading, in 3 deg steps from
/// `edge_yaw`, that puts the most of `raw` there.
fn face_share(raw: &[Vector3<f64>], sample: &[Vector3<f64>], edge_yaw: f64, tolerance_m: f64) -> f64 {
    // The heading is searched on half the sample (the search on the whole of it cost a third of
    // the detector's time), the share measured on all of it.
    let search: Vec<Vector3<f64>> = raw.iter().step_by((raw.len() / 300).max(1)).copied().collect();
    let steps = (90.0 / FACE_YAW_STEP_DEG).round() as i32;
    let face_yaw = (0..steps)
        .map(|k| edge_yaw + (f64::from(k) * FACE_YAW_STEP_DEG).to_radians())
        .max_by_key(|&yaw| on_faces(&search, yaw, tolerance_m))
        .unwrap_or(edge_yaw);
    on_faces(sample, face_yaw, tolerance_m) as f64 / sample.len().max(1) as f64
}

/// Heading in (-pi/2, pi/2]: a box is the same turned by half a turn.
fn wrap(yaw: f64) -> f64 {
    let pi = std::f64::consts::PI;
    let mut y = yaw.rem_euclid(pi);
    if y > pi / 2.0 {
        y -= pi;
    }
    y
}
