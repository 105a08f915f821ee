//! What the learned scorer sees of a cluster: the features the rules use, a profile of its
//! shape by height (how its points and spread change from feet to head), its shape in absolute
//! terms ([`super::shape`]) and which way its slices lean as the sensor sees them, as one f32
//! vector. The training data (`starc dataset
//! --clusters`) and the detector both build it here.

use super::super::ClusterFeatures;
use super::shape::{shape_inputs, SHAPE_INPUTS};
use nalgebra::Vector3;

/// Height slices of the profile, bottom to top of the cluster.
pub const SLICES: usize = 8;
/// Inputs per slice (see [`Slice`]).
const PER_SLICE: usize = 4;
/// Inputs before the profile.
const BASE: usize = 15;
/// Inputs before the shape inputs.
const PROFILED: usize = BASE + PER_SLICE * SLICES;
/// Inputs before each slice's lean towards the sensor.
const SHAPED: usize = PROFILED + SHAPE_INPUTS;
/// Length of the input vector.
pub const INPUTS: usize = SHAPED + SLICES;

/// A feature that was not measured (a face share never computed) reads as this.
const NOT_MEASURED: f32 = -1.0;

/// The input vector of a cluster: `f`, its points (x, y in the world, z above the floor) and the
/// sensor's position over the floor plan.
pub fn inputs(f: &ClusterFeatures, points: &[Vector3<f64>], sensor_xy: [f64; 2]) -> [f32; INPUTS] {
    let mut v = [0.0f32; INPUTS];
    let measured = |x: f64| if x.is_finite() { x as f32 } else { NOT_MEASURED };
    let base = [
        (f.points.max(1) as f64).ln(),
        (f.voxels.max(1) as f64).ln(),
        f.size.x,
        f.size.y,
        f.size.z,
        f.bottom_m,
        f.top_m,
        f.face_share,
        f.top_share,
        f.linearity,
        f.planarity,
        f.thickness_m,
        f.range_m,
        f.points as f64 * f.range_m * f.range_m / 1000.0,
        centroid_height_share(f, points),
    ];
    for (slot, x) in v.iter_mut().zip(base) {
        *slot = measured(x);
    }
    for (i, s) in profile(f, points, sensor_xy).into_iter().enumerate() {
        let at = BASE + PER_SLICE * i;
        v[at] = s.share as f32;
        v[at + 1] = s.spread_length_m as f32;
        v[at + 2] = s.spread_width_m as f32;
        v[at + 3] = s.offset_from_top_m as f32;
        v[SHAPED + i] = s.lean_to_sensor_m as f32;
    }
    v[PROFILED..SHAPED].copy_from_slice(&shape_inputs(f, points));
    v
}

/// The height slice of the profile a point `z` over the floor falls in.
fn slice_of(f: &ClusterFeatures, z: f64) -> usize {
    let span = (f.top_m - f.bottom_m).max(1e-6);
    (((z - f.bottom_m) / span * SLICES as f64).floor().max(0.0) as usize).min(SLICES - 1)
}

/// Where the points' mean height lies between the cluster's bottom (0) and top (1): a person's
/// mass sits mid-body, a table's at its top, a chair's low.
fn centroid_height_share(f: &ClusterFeatures, points: &[Vector3<f64>]) -> f64 {
    if points.is_empty() || f.top_m - f.bottom_m < 1e-6 {
        return 0.5;
    }
    let mean = points.iter().map(|p| p.z).sum::<f64>() / points.len() as f64;
    ((mean - f.bottom_m) / (f.top_m - f.bottom_m)).clamp(0.0, 1.0)
}

/// One height slice: its share of the points, their standard deviation along the box's length
/// and across it, how far their middle lies from the top slice's over the floor (a seated
/// body's knees stick out from under its head, a chair's seat from its back; a pole's do not),
/// and how much nearer the sensor, along its horizontal line of sight to the cluster, that
/// middle lies than the top slice's (the knees towards it or away; 0 for an empty slice).
#[derive(Clone, Copy, Default)]
struct Slice {
    share: f64,
    spread_length_m: f64,
    spread_width_m: f64,
    offset_from_top_m: f64,
    lean_to_sensor_m: f64,
}

/// The cluster cut into [`SLICES`] equal heights between its bottom and top, seen from the
/// sensor at `sensor_xy`.
fn profile(f: &ClusterFeatures, points: &[Vector3<f64>], sensor_xy: [f64; 2]) -> [Slice; SLICES] {
    let mut sums = [[0.0f64; 5]; SLICES]; // n, sum a, sum a^2, sum b, sum b^2
    let (s, c) = f.yaw_rad.sin_cos();
    for p in points {
        let k = slice_of(f, p.z);
        let (dx, dy) = (p.x - f.centre.x, p.y - f.centre.y);
        let (a, b) = (c * dx + s * dy, -s * dx + c * dy);
        let acc = &mut sums[k];
        acc[0] += 1.0;
        acc[1] += a;
        acc[2] += a * a;
        acc[3] += b;
        acc[4] += b * b;
    }
    let total = points.len().max(1) as f64;
    let mean = |acc: &[f64; 5]| if acc[0] > 0.0 { Some((acc[1] / acc[0], acc[3] / acc[0])) } else { None };
    // The highest slice holding points (the top one may be empty when a few points stick up).
    let top = sums.iter().rev().find_map(mean).unwrap_or((0.0, 0.0));
    // The line of sight in the box's frame (none when the sensor is over the centre).
    let (rx, ry) = (f.centre.x - sensor_xy[0], f.centre.y - sensor_xy[1]);
    let norm = rx.hypot(ry);
    let sight = if norm < 1e-6 { (0.0, 0.0) } else { ((c * rx + s * ry) / norm, (-s * rx + c * ry) / norm) };
    let depth = |(a, b): (f64, f64)| a * sight.0 + b * sight.1;
    sums.map(|acc| {
        let [n, sa, saa, sb, sbb] = acc;
        let spread = |sum: f64, sq: f64| if n > 0.0 { (sq / n - (sum / n).powi(2)).max(0.0).sqrt() } else { 0.0 };
        let offset = mean(&acc).map_or(0.0, |(a, b)| (a - top.0).hypot(b - top.1));
        Slice {
            share: n / total,
            spread_length_m: spread(sa, saa),
            spread_width_m: spread(sb, sbb),
            offset_from_top_m: offset,
            lean_to_sensor_m: mean(&acc).map_or(0.0, |m| depth(top) - depth(m)),
        }
    })
}

/// A cluster for tests: its centre over the floor plan, size (length, width, height) and top.
#[cfg(test)]
pub(super) fn cluster(centre: [f64; 2], size: [f64; 3], top: f64) -> ClusterFeatures {
    ClusterFeatures {
        points: 100,
        voxels: 20,
        centre: Vector3::new(centre[0], centre[1], top - size[2] / 2.0),
        size: Vector3::new(size[0], size[1], size[2]),
        yaw_rad: 0.0,
        bottom_m: top - size[2],
        top_m: top,
        face_share: f64::NAN,
        top_share: 0.1,
        linearity: 0.2,
        planarity: 0.3,
        thickness_m: 0.05,
        range_m: 3.0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn features(bottom: f64, top: f64) -> ClusterFeatures {
        cluster([1.0, 2.0], [0.5, 0.3, top - bottom], top)
    }

    #[test]
    fn a_column_wide_at_the_bottom_has_its_points_and_spread_low() {
        let f = features(0.0, 1.6);
        let mut pts = Vec::new();
        for i in 0..40 {
            let a = f64::from(i) / 40.0 - 0.5;
            pts.push(Vector3::new(1.0 + a, 2.0, 0.1)); // wide, low
        }
        for i in 0..10 {
            pts.push(Vector3::new(1.0, 2.0, 1.5 - f64::from(i) * 0.01)); // a thin top
        }
        let v = inputs(&f, &pts, [0.0, 0.0]);
        let slice = |i: usize, k: usize| v[BASE + PER_SLICE * i + k];
        assert!((slice(0, 0) - 0.8).abs() < 1e-6, "bottom slice share {}", slice(0, 0));
        assert!(slice(0, 1) > 0.25, "bottom spread along the length {}", slice(0, 1));
        assert!((slice(SLICES - 1, 0) - 0.2).abs() < 1e-6, "top slice share");
        assert!(slice(SLICES - 1, 1) < 0.01, "the top is thin");
        assert!(slice(0, 3) < 0.05, "the bottom is centred under the top: {}", slice(0, 3));
        assert_eq!(v[7], NOT_MEASURED, "a face share never measured");
        assert!(v.iter().all(|x| x.is_finite()));
    }

    #[test]
    fn knees_nearer_the_sensor_than_the_head_lean_towards_it() {
        let f = cluster([0.0, 0.0], [0.6, 0.4, 1.2], 1.2);
        let mut pts = Vec::new();
        for i in 0..3 {
            for j in 0..5 {
                let (x, y) = (f64::from(i) * 0.05, f64::from(j) * 0.05 - 0.1);
                pts.push(Vector3::new(0.1 + x, y, 1.2)); // head, farther
                pts.push(Vector3::new(-0.3 + x, y, 0.45)); // knees, nearer
            }
        }
        let v = inputs(&f, &pts, [-3.0, 0.0]);
        let lean = &v[SHAPED..];
        assert!((lean[3] - 0.4).abs() < 1e-6, "the knees' slice is 0.4 m nearer: {lean:?}");
        assert_eq!(lean[SLICES - 1], 0.0);
    }

    #[test]
    fn no_points_and_a_flat_cluster_give_finite_inputs() {
        let v = inputs(&features(0.3, 0.3), &[], [0.0, 0.0]);
        assert!(v.iter().all(|x| x.is_finite()));
    }
}
