//! A wall seen from its other side: the robot mapped a thin wall from outside, the rig stands
//! inside the room; the two faces, 0.14 m apart, must not be paired.
#![allow(clippy::unwrap_used)]

use super::*;
use nalgebra::{Isometry3, Point3};

const THICKNESS_M: f64 = 0.14;

/// A wall face at `y`, from x = 0 to 10, 2.5 m high, 5 cm apart.
fn face_y(y: f64) -> Vec<Vec3> {
    (0..=200).flat_map(|i| (0..=50).map(move |k| Vec3::new(f64::from(i) * 0.05, y, f64::from(k) * 0.05))).collect()
}

/// A wall face at `x`, from y = 0 to 6.
fn face_x(x: f64) -> Vec<Vec3> {
    (0..=120).flat_map(|j| (0..=50).map(move |k| Vec3::new(x, f64::from(j) * 0.05, f64::from(k) * 0.05))).collect()
}

fn floor() -> Vec<Vec3> {
    (0..=100).flat_map(|i| (0..=60).map(move |j| Vec3::new(f64::from(i) * 0.1, f64::from(j) * 0.1, 0.0))).collect()
}

/// The robot's map with the direction from each point towards the robot: the wall's outer face
/// seen from outside (y < 0); the room's end walls and floor, and with `far_wall` its far wall
/// (y = 6), seen from inside.
fn robot_map(far_wall: bool) -> (Vec<Vec3>, Vec<Vec3>) {
    let (outside, inside) = (Vec3::new(5.0, -3.0, 0.5), Vec3::new(5.0, 3.0, 0.5));
    let mut pts = Vec::new();
    let mut towards = Vec::new();
    let mut add = |ps: Vec<Vec3>, from: Vec3| {
        towards.extend(ps.iter().map(|p| from - p));
        pts.extend(ps);
    };
    add(face_y(-THICKNESS_M / 2.0), outside);
    let mut room = [face_x(0.0), face_x(10.0), floor()].concat();
    if far_wall {
        room.extend(face_y(6.0));
    }
    add(room, inside);
    (pts, towards)
}

/// The rig's view from inside the room (the wall's inner face, the end walls, the floor and the
/// far wall), in its frame at `truth`, with a ray to every point.
fn rig_view(truth: &Isometry3<f64>) -> (Vec<Vec3>, Vec<Ray>) {
    let world = [face_y(THICKNESS_M / 2.0), face_x(0.0), face_x(10.0), floor(), face_y(6.0)].concat();
    let source: Vec<Vec3> = world.iter().map(|p| truth.inverse_transform_point(&Point3::from(*p)).coords).collect();
    let rays = source.iter().map(|p| Ray { origin: Vec3::zeros(), end: *p }).collect();
    (source, rays)
}

fn config() -> AlignConfig {
    AlignConfig { reseed_yaw_step_deg: 0.0, ndt_resolutions_m: vec![1.0], seed_levels: 1, ..AlignConfig::default() }
}

fn y_error(report: &AlignReport, truth: &Isometry3<f64>) -> f64 {
    let best = report.best().unwrap();
    (best.pose.translation.vector - truth.translation.vector).y
}

#[test]
fn a_wall_mapped_from_outside_does_not_pull_the_rig_inside_onto_its_outer_face() {
    let truth = pose_xyz_yaw(5.0, 3.0, 1.5, 80.0);
    let (source, rays) = rig_view(&truth);
    let start = truth * pose_xyz_yaw(0.02, -0.03, 0.0, 0.5);
    // Only the wall holds the rig across the room: paired with its outer face, the view settles
    // a wall's thickness off, and fits well there.
    let (map, towards) = robot_map(false);
    let plain = Aligner::new(&map, config()).unwrap().align_with_rays(&source, &rays, &start);
    assert!((y_error(&plain, &truth) + THICKNESS_M).abs() < 0.03, "{}", y_error(&plain, &truth));
    let sided = Aligner::new_seen_from(&map, &towards, config()).unwrap().align_with_rays(&source, &rays, &start);
    let off = y_error(&sided, &truth).abs();
    assert!(!(sided.accepted && off > 0.05), "accepted {off} m off");
    // With the far wall mapped too, the rig settles on the truth.
    let (map, towards) = robot_map(true);
    let sided = Aligner::new_seen_from(&map, &towards, config()).unwrap().align_with_rays(&source, &rays, &start);
    assert!(y_error(&sided, &truth).abs() < 0.02, "{}", y_error(&sided, &truth));
    // Off, the same as without sides.
    let off_cfg = AlignConfig { icp_opposite_min_side: 0.0, ..config() };
    let (map, towards) = robot_map(false);
    let unsided = Aligner::new_seen_from(&map, &towards, off_cfg).unwrap().align_with_rays(&source, &rays, &start);
    assert_eq!(unsided.best().unwrap().pose, plain.best().unwrap().pose);
}
