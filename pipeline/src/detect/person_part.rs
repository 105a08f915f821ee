//! Where in a cluster that holds more than a person the person is.
//!
//! A person standing or sitting against furniture of about their own size is often one cluster
//! with it (development office-96: a child of 1.31 m beside a round table 0.69 m high, one
//! cluster 1.5 x 0.95 m). The scorer takes it for a person, rightly, but its box centre lies
//! between the two, 0.6 m off the person. Whatever stands or sits reaches highest with their
//! head and shoulders, so the cluster's top band says where they are: the box is cut down to the
//! points around it.

use super::features::{box_along, from_frame};
use super::{Detection, FloorModel, PersonPose, WindowPoint};
use nalgebra::{Vector2, Vector3};

/// A footprint longer than this is more than one upright or seated person (a seated person with
/// their knees out is about 0.7 m long).
const MERGED_LENGTH_M: f64 = 0.9;
/// The top this deep is head and shoulders: lower than a seated person's head over a table
/// (0.6 m), higher than a table under a standing child's shoulders.
const HEAD_BAND_M: f64 = 0.4;
/// Only a detection at least this tall has a body under its top band to tell it by (a low,
/// long cluster is all band: development lab-59, a crouching person beside a shelf).
const MIN_HEIGHT_M: f64 = 2.0 * HEAD_BAND_M;
/// A seated or crouching person's head is no higher over the floor than this; a seated
/// detection whose top is higher holds something taller than them, whose top would mislead
/// (development lab-59: a crouching person against a 1.87 m shelf).
const LOW_MAX_TOP_M: f64 = 1.5;
/// The head band must be this compact across to be one person's (two heads are not one).
const HEAD_BAND_MAX_SPREAD_M: f64 = 0.5;
/// Points within this far of the head band's middle, over the floor, are the person's.
const BODY_RADIUS_M: f64 = 0.45;

/// A person's part of a detection: its box (centre over the floor, length along the detection's
/// heading, width) and the window points in it.
#[derive(Clone, Debug, PartialEq)]
struct PersonPart {
    centre_xy: Vector2<f64>,
    length_m: f64,
    width_m: f64,
    points: Vec<u32>,
}

/// Cuts an upright or seated detection whose footprint is longer than one person's down to the
/// person: its box and points become those around its top band. Lying people, person-sized
/// boxes and tops that are not one compact band are left as they are.
pub fn cut_to_person(points: &[WindowPoint], floor: &FloorModel, d: &mut Detection) {
    if d.pose == PersonPose::Lying || d.size_m.x <= MERGED_LENGTH_M || d.size_m.z < MIN_HEIGHT_M {
        return;
    }
    let max_top_m = if d.pose == PersonPose::Low { LOW_MAX_TOP_M } else { f64::INFINITY };
    let Some(part) = person_part(points, floor, d.yaw_rad, &d.point_indices, max_top_m) else { return };
    // The box keeps its height over the floor where it now stands.
    let moved = part.centre_xy - d.centre_m.xy();
    d.centre_m.x = part.centre_xy.x;
    d.centre_m.y = part.centre_xy.y;
    d.centre_m.z += floor.a * moved.x + floor.b * moved.y;
    d.size_m.x = part.length_m;
    d.size_m.y = part.width_m;
    d.point_indices = part.points;
}

/// The part of `idx` around its top band, boxed along `yaw_rad`; None where the top is higher
/// than `max_top_m` over the floor.
fn person_part(
    points: &[WindowPoint],
    floor: &FloorModel,
    yaw_rad: f64,
    idx: &[u32],
    max_top_m: f64,
) -> Option<PersonPart> {
    // Each point once: its index, where it is over the floor, and how high over it.
    let seen: Vec<(u32, Vector2<f64>, f64)> = idx
        .iter()
        .filter_map(|&i| {
            let p = points.get(i as usize)?;
            let (x, y, z) = (f64::from(p.x_m), f64::from(p.y_m), f64::from(p.z_m));
            Some((i, Vector2::new(x, y), floor.height(x, y, z)))
        })
        .collect();
    let top_m = seen.iter().map(|s| s.2).fold(f64::MIN, f64::max);
    if top_m > max_top_m {
        return None;
    }
    let head: Vec<Vector2<f64>> = seen.iter().filter(|s| s.2 >= top_m - HEAD_BAND_M).map(|s| s.1).collect();
    if head.is_empty() {
        return None;
    }
    let middle = head.iter().sum::<Vector2<f64>>() / head.len() as f64;
    if head.iter().any(|xy| (xy - middle).norm() > HEAD_BAND_MAX_SPREAD_M) {
        return None;
    }
    let body: Vec<&(u32, Vector2<f64>, f64)> = seen.iter().filter(|s| (s.1 - middle).norm() <= BODY_RADIUS_M).collect();
    if body.is_empty() {
        return None;
    }
    let (lo, hi) = box_along(yaw_rad, body.iter().map(|s| Vector3::new(s.1.x, s.1.y, 0.0)));
    Some(PersonPart {
        centre_xy: from_frame(yaw_rad, (lo + hi) / 2.0).xy(),
        length_m: hi.x - lo.x,
        width_m: hi.y - lo.y,
        points: body.iter().map(|s| s.0).collect(),
    })
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use starc_time::{Clock, Stamp};

    fn pt(x: f64, y: f64, z: f64) -> WindowPoint {
        WindowPoint { x_m: x as f32, y_m: y as f32, z_m: z as f32, t_ns: 0 }
    }

    /// A body 0.3 m across at x = 2 up to `top_m`, and a table top 1 m across at 0.7 m beside
    /// it, along x.
    fn child_and_table(top_m: f64) -> Vec<WindowPoint> {
        let mut v = Vec::new();
        for k in 0..40 {
            let h = top_m * f64::from(k) / 39.0;
            for d in [-0.15, 0.0, 0.15] {
                v.push(pt(2.0 + d, 0.1 * d, h));
            }
        }
        v.extend((0..30).map(|k| pt(2.3 + f64::from(k) / 29.0, 0.0, 0.7)));
        v
    }

    /// The detection a cluster of all of `points` gives: its box along x.
    fn detection_of(points: &[WindowPoint], pose: PersonPose) -> Detection {
        let (lo, hi) = points.iter().fold((f64::MAX, f64::MIN), |(a, b), p| (a.min(p.x_m.into()), b.max(p.x_m.into())));
        let top = points.iter().map(|p| f64::from(p.z_m)).fold(f64::MIN, f64::max);
        Detection {
            stamp: Stamp::new(1, Clock::Ptp),
            centre_m: Vector3::new((lo + hi) / 2.0, 0.0, top / 2.0),
            size_m: Vector3::new(hi - lo, 0.3, top),
            yaw_rad: 0.0,
            score: 0.9,
            pose,
            point_indices: (0..points.len() as u32).collect(),
        }
    }

    /// Whether the detection of all of `points` in `pose` comes out of the cut as it went in.
    fn keeps_its_box(points: &[WindowPoint], pose: PersonPose) -> bool {
        let before = detection_of(points, pose);
        let mut d = before.clone();
        cut_to_person(points, &FloorModel::flat(0.0), &mut d);
        d == before
    }

    #[test]
    fn a_child_merged_with_a_table_is_boxed_where_the_child_stands() {
        let points = child_and_table(1.3);
        let mut d = detection_of(&points, PersonPose::Low);
        assert!((d.centre_m.x - 2.0).abs() > 0.5, "the cluster's own centre is off the child");
        cut_to_person(&points, &FloorModel::flat(0.0), &mut d);
        assert!((d.centre_m.xy() - Vector2::new(2.0, 0.0)).norm() < 0.25, "{d:?}");
        assert!(d.size_m.x < 0.8 && (d.size_m.z - 1.3).abs() < 1e-6, "{d:?}");
        assert!(d.point_indices.len() < points.len() && d.point_indices.len() >= 120);
    }

    #[test]
    fn person_sized_and_lying_detections_keep_their_box() {
        let upright: Vec<WindowPoint> = child_and_table(1.7).into_iter().filter(|p| p.x_m < 2.3).collect();
        assert!(keeps_its_box(&upright, PersonPose::Upright));
        assert!(keeps_its_box(&child_and_table(1.3), PersonPose::Lying));
    }

    #[test]
    fn a_seated_detection_under_a_taller_top_keeps_its_box() {
        let mut points = child_and_table(1.2);
        points.extend((0..20).map(|k| pt(3.2, 0.0, 1.5 + 0.3 * f64::from(k) / 19.0)));
        assert!(keeps_its_box(&points, PersonPose::Low));
        let mut upright = detection_of(&points, PersonPose::Upright);
        cut_to_person(&points, &FloorModel::flat(0.0), &mut upright);
        assert!((upright.centre_m.x - 3.2).abs() < 0.3, "an upright one is cut to its top: {upright:?}");
    }

    #[test]
    fn a_low_long_detection_keeps_its_box() {
        let points: Vec<WindowPoint> =
            (0..60).map(|k| pt(1.0 + f64::from(k) / 59.0, 0.0, 0.5 + 0.004 * f64::from(k))).collect();
        assert!(keeps_its_box(&points, PersonPose::Low));
    }

    #[test]
    fn two_heads_apart_are_not_one_person() {
        let mut points = child_and_table(1.3);
        points.extend((0..20).map(|k| pt(3.2, 0.0, 1.0 + 0.3 * f64::from(k) / 19.0)));
        assert!(keeps_its_box(&points, PersonPose::Upright));
    }
}
