//! Acceptance with the robot's coverage: a fit of a view that reaches past the map passes, a
//! fit that puts points where the robot saw through is refused.
#![allow(clippy::unwrap_used)]

use super::*;
use nalgebra::{Isometry3, Point3};
use std::sync::Arc;

/// A wall from `a` to `b` (x, y), 2.5 m high, points 5 cm apart, those with x at most `x_max`.
fn push_wall(pts: &mut Vec<Vec3>, a: (f64, f64), b: (f64, f64), x_max: f64) {
    let n = ((b.0 - a.0).hypot(b.1 - a.1) / 0.05) as usize;
    for i in 0..=n {
        let f = i as f64 / n.max(1) as f64;
        let (x, y) = (a.0 + f * (b.0 - a.0), a.1 + f * (b.1 - a.1));
        if x <= x_max + 1e-9 {
            pts.extend((0..=50).map(|k| Vec3::new(x, y, f64::from(k) * 0.05)));
        }
    }
}

/// The walls of a 20 x 6 m hall, 2.5 m high, split by a wall at `door_x` with a 1.2 m door in
/// its middle; those with x at most `x_max`.
fn push_hall(pts: &mut Vec<Vec3>, door_x: f64, x_max: f64) {
    let mut segment = |a: (f64, f64), b: (f64, f64)| push_wall(pts, a, b, x_max);
    segment((0.0, 0.0), (20.0, 0.0));
    segment((20.0, 0.0), (20.0, 6.0));
    segment((20.0, 6.0), (0.0, 6.0));
    segment((0.0, 6.0), (0.0, 0.0));
    segment((door_x, 0.0), (door_x, 2.4));
    segment((door_x, 3.6), (door_x, 6.0));
}

/// Walls of a 20 x 6 m hall split by a wall at x = 5 with a 1.2 m door; 2.5 m high.
fn walls(x_max: f64) -> Vec<Vec3> {
    let mut pts = Vec::new();
    push_hall(&mut pts, 5.0, x_max);
    let mut segment = |a: (f64, f64), b: (f64, f64)| push_wall(&mut pts, a, b, x_max);
    // A cupboard in the left room, so the fit is not a bare box.
    segment((1.0, 4.0), (2.0, 4.0));
    segment((2.0, 4.0), (2.0, 5.0));
    // The floor.
    for i in 0..=(x_max.min(20.0) / 0.1) as i32 {
        for j in 0..=60 {
            pts.push(Vec3::new(f64::from(i) * 0.1, f64::from(j) * 0.1, 0.0));
        }
    }
    pts
}

/// The robot mapped the left room from (2.5, 3, 1.2): its walls, and the space its rays crossed.
fn robot_map() -> (Vec<Vec3>, Arc<Coverage>) {
    let map = walls(5.0);
    let origin = Vec3::new(2.5, 3.0, 1.2);
    let mut coverage = Coverage::new(0.25);
    for p in map.iter().step_by(3) {
        coverage.add_ray(&origin, p);
    }
    (map, Arc::new(coverage))
}

fn config() -> AlignConfig {
    AlignConfig { reseed_yaw_step_deg: 0.0, ndt_resolutions_m: vec![1.0], seed_levels: 1, ..AlignConfig::default() }
}

#[test]
fn a_view_reaching_past_the_map_passes_on_what_the_robot_covered() {
    let (map, coverage) = robot_map();
    // The rig stands at the door and sees both rooms; the robot mapped only the left one.
    let truth = pose_xyz_yaw(5.5, 3.0, 1.4, 30.0);
    let source: Vec<Vec3> =
        walls(20.0).iter().map(|p| truth.inverse_transform_point(&Point3::from(*p)).coords).collect();
    let start = truth * pose_xyz_yaw(0.15, -0.1, 0.0, 2.0);
    let plain = Aligner::new(&map, config()).unwrap().align(&source, &start);
    let best = plain.best().unwrap();
    assert!(!plain.accepted && best.rejected_because.iter().any(|r| matches!(r, Rejection::InlierRatio { .. })));
    let judged = Aligner::new(&map, config()).unwrap().with_coverage(Arc::clone(&coverage)).align(&source, &start);
    let a = judged.best().unwrap();
    assert!(judged.accepted, "{:?} {:?}", a.rejected_because, a.overlap);
    let o = a.overlap.unwrap();
    assert!(o.ratio() > 0.99 && o.explained_share() < 0.6, "{o:?}");
    let (m, deg) = pose_error(&judged.pose, &truth);
    assert!(m < 0.05 && deg < 0.5, "{m} m {deg} deg");
}

#[test]
fn points_where_the_robot_saw_through_refuse_a_fit() {
    let (map, coverage) = robot_map();
    // The left room as mapped, plus a wall across its middle that the robot's rays crossed:
    // whatever the rig saw, it was not this room.
    let mut seen = walls(5.0);
    for i in 0..=60 {
        for k in 0..=50 {
            seen.push(Vec3::new(1.0 + f64::from(i) * 0.05, 2.0, f64::from(k) * 0.05));
        }
    }
    let judged = Aligner::new(&map, config()).unwrap().with_coverage(coverage).align(&seen, &Isometry3::identity());
    let a = judged.best().unwrap();
    assert!(!judged.accepted);
    assert!(a.rejected_because.iter().any(|r| matches!(r, Rejection::Contradicted { .. })), "{:?}", a.rejected_because);
}

/// Two closed rooms alike, 6 x 5 m with a cupboard, 10 m apart: a view of either fits both.
fn twin_rooms() -> Vec<Vec3> {
    let mut pts = Vec::new();
    for x0 in [0.0, 10.0] {
        let mut segment =
            |a: (f64, f64), b: (f64, f64)| push_wall(&mut pts, (x0 + a.0, a.1), (x0 + b.0, b.1), f64::MAX);
        segment((0.0, 0.0), (6.0, 0.0));
        segment((6.0, 0.0), (6.0, 5.0));
        segment((6.0, 5.0), (0.0, 5.0));
        segment((0.0, 5.0), (0.0, 0.0));
        segment((1.0, 3.5), (2.5, 3.5));
        segment((2.5, 3.5), (2.5, 4.2));
        for i in 0..=60 {
            for j in 0..=50 {
                pts.push(Vec3::new(x0 + f64::from(i) * 0.1, f64::from(j) * 0.1, 0.0));
            }
        }
    }
    pts
}

#[test]
fn a_view_that_fits_two_places_on_the_map_is_refused() {
    let map = twin_rooms();
    let truth = pose_xyz_yaw(3.5, 2.0, 1.4, 40.0);
    let source: Vec<Vec3> =
        map.iter().filter(|p| p.x < 7.0).map(|p| truth.inverse_transform_point(&Point3::from(*p)).coords).collect();
    // The ambiguity check of seeds is off, so the correlative stage's test alone is judged.
    let searched = AlignConfig { ambiguity_seeds: 0, ..AlignConfig::default() };
    let report = Aligner::new(&map, searched.clone()).unwrap().align(&source, &Isometry3::identity());
    assert!(!report.accepted);
    let why: Vec<&Rejection> = report.attempts.iter().flat_map(|a| &a.rejected_because).collect();
    assert!(
        why.iter().any(|r| matches!(r, Rejection::ElsewhereAsGood { off_m, .. } if (*off_m - 10.0).abs() < 0.5)),
        "{why:?}"
    );
    // Without the stage the first fit found is taken: one of the two rooms.
    let blind = AlignConfig { correlative_seeds: 0, ..searched };
    let report = Aligner::new(&map, blind).unwrap().align(&source, &Isometry3::identity());
    assert!(report.accepted, "{:?}", report.best().map(|a| &a.rejected_because));
}

/// A 20 x 6 m hall of two rooms split at x = 10 by a wall with a door, the same turned 180 deg
/// about its centre (a cupboard in each, where the turn puts it), 2.5 m high, with a floor.
fn twin_halves() -> Vec<Vec3> {
    let mut pts = Vec::new();
    push_hall(&mut pts, 10.0, f64::MAX);
    let mut segment = |a: (f64, f64), b: (f64, f64)| push_wall(&mut pts, a, b, f64::MAX);
    for (x0, y0, s) in [(2.0, 4.0, 1.0), (18.0, 2.0, -1.0)] {
        segment((x0, y0), (x0 + s, y0));
        segment((x0 + s, y0), (x0 + s, y0 + s));
    }
    for i in 0..=200 {
        for j in 0..=60 {
            pts.push(Vec3::new(f64::from(i) * 0.1, f64::from(j) * 0.1, 0.0));
        }
    }
    pts
}

#[test]
fn a_view_of_the_half_the_robot_glimpsed_is_not_placed_in_its_mapped_twin() {
    let hall = twin_halves();
    // The robot mapped the left room from (5, 3) and, through the door, glimpsed the right one:
    // the walls within 3 m of the door, and the air beyond (returns too sparse to map).
    let map: Vec<Vec3> = hall.iter().filter(|p| p.x <= 15.0).copied().collect();
    let mut coverage = Coverage::new(0.25);
    for p in map.iter().filter(|p| p.x <= 10.0).step_by(3) {
        coverage.add_ray(&Vec3::new(5.0, 3.0, 1.2), p);
    }
    for (i, k) in (0..=20).flat_map(|i| (0..=6).map(move |k| (i, k))) {
        let end = Vec3::new(17.0, 1.0 + f64::from(i) * 0.2, 0.5 + f64::from(k) * 0.25);
        coverage.add_ray(&Vec3::new(9.0, 3.0, 1.2), &end);
    }
    let coverage = Arc::new(coverage);
    // The rig stands in the right room, which it sees whole.
    let truth = pose_xyz_yaw(13.5, 3.0, 1.4, 200.0);
    let source: Vec<Vec3> =
        hall.iter().filter(|p| p.x >= 10.0).map(|p| truth.inverse_transform_point(&Point3::from(*p)).coords).collect();
    let blind = AlignConfig { correlative_rivals: 0, ..AlignConfig::default() };
    let report =
        Aligner::new(&map, blind).unwrap().with_coverage(Arc::clone(&coverage)).align(&source, &Isometry3::identity());
    let (off_m, _) = pose_error(&report.pose, &truth);
    assert!(report.accepted && off_m > 5.0, "without the rivals the mirror image is taken: {off_m} m");
    let aligner = Aligner::new(&map, AlignConfig::default()).unwrap().with_coverage(coverage);
    let report = aligner.align(&source, &Isometry3::identity());
    let why: Vec<&Rejection> = report.attempts.iter().flat_map(|a| &a.rejected_because).collect();
    assert!(!report.accepted, "{:?}", report.best().map(|a| (&a.rivals, a.known_fit)));
    assert!(why.iter().any(|r| matches!(r, Rejection::PartlyMappedRival { .. })), "{why:?}");
}

/// Every rival that could refuse a place scores at least `rival_min_score` in the rival search,
/// for any mix of structure (1), beside it (0.5) and seen-through space on its known points:
/// the search may stop there without changing a verdict.
#[test]
fn no_rival_that_could_refuse_scores_under_the_rival_search_floor() {
    let c = config();
    let n = 40usize;
    for here in [0.3, 0.5, 0.7, 0.85, 0.95, 1.0] {
        let floor = super::register::rival_min_score(&c, KnownFit { known_share: 1.0, score_on_known: here });
        let mut refusing = 0;
        for known in 1..=n {
            for free in 0..=known {
                for beside in 0..=(known - free) {
                    let on = (known - free - beside) as f64;
                    let base = on + 0.5 * beside as f64 - c.correlative_free_penalty * free as f64;
                    let refuses = known as f64 / n as f64 >= c.correlative_rival_min_known
                        && base / known as f64 >= here - c.correlative_rival_margin;
                    if refuses {
                        refusing += 1;
                        let standing = on + 0.5 * beside as f64 - c.correlative_rival_free_penalty * free as f64;
                        assert!(
                            standing / n as f64 >= floor,
                            "here {here}: {known} known, {free} seen through, {beside} beside"
                        );
                    }
                }
            }
        }
        assert!(refusing > 0);
        assert!(floor > 0.0 || here < 0.8, "here {here}: floor {floor}");
    }
}
