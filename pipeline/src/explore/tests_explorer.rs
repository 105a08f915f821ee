//! The explorer in a closed loop on a synthetic floor: two 6 x 4 m rooms joined by a doorway,
//! scanned by a 2D stand-in for the Avia (rays every 2 deg over its 70 deg, walls in the body
//! band, floor returns along each ray), the base moving exactly as commanded.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use super::tests_control::in_body;
use super::*;
use nalgebra::Vector3;

const DT_S: f64 = 0.05;
/// A scan every this many control periods (5 Hz).
const SCAN_EVERY: usize = 4;

type Segment = ([f64; 2], [f64; 2]);

/// Rooms A (x 0-6) and B (x 6-12), y 0-4, the doorway between them at y 1.5-2.7.
fn two_rooms() -> Vec<Segment> {
    vec![
        ([0.0, 0.0], [12.0, 0.0]),
        ([12.0, 0.0], [12.0, 4.0]),
        ([12.0, 4.0], [0.0, 4.0]),
        ([0.0, 4.0], [0.0, 0.0]),
        ([6.0, 0.0], [6.0, 1.5]),
        ([6.0, 2.7], [6.0, 4.0]),
    ]
}

/// Where a ray from `o` along `d` (unit) first meets a wall, within 15 m.
fn hit(walls: &[Segment], o: [f64; 2], d: [f64; 2]) -> Option<f64> {
    walls
        .iter()
        .filter_map(|&(a, b)| {
            let e = [b[0] - a[0], b[1] - a[1]];
            let den = d[0] * e[1] - d[1] * e[0];
            if den.abs() < 1e-12 {
                return None;
            }
            let w = [a[0] - o[0], a[1] - o[1]];
            let t = (w[0] * e[1] - w[1] * e[0]) / den;
            let u = (w[0] * d[1] - w[1] * d[0]) / den;
            (t > 0.0 && (0.0..=1.0).contains(&u)).then_some(t)
        })
        .filter(|&t| t <= 15.0)
        .min_by(f64::total_cmp)
}

/// One scan from `p` (sensor 0.5 m up): per ray, floor returns every 0.1 m from 0.7 m out to
/// the wall, and the wall at 0.3, 0.6 and 0.9 m; also the wall hits in the body frame (what
/// the controller gets from the live scan).
fn scan(walls: &[Segment], p: &Pose2) -> (Vec<Vector3<f64>>, Vec<[f64; 2]>) {
    scan_from(walls, p, &Sensor::IDEAL)
}

/// What the LiDAR of a run cannot see.
#[derive(Clone, Copy)]
struct Sensor {
    /// Nothing returns from nearer than this (in the plane).
    min_range_m: f64,
    /// A region (x, y corners) nothing in returns (black, or out of the LiDAR's reach).
    void: Option<([f64; 2], [f64; 2])>,
}

impl Sensor {
    const IDEAL: Sensor = Sensor { min_range_m: 0.0, void: None };

    fn returns_from(&self, x: f64, y: f64) -> bool {
        self.void.is_none_or(|(lo, hi)| !(lo[0]..=hi[0]).contains(&x) || !(lo[1]..=hi[1]).contains(&y))
    }
}

/// [`scan`] by the LiDAR `sensor`.
fn scan_from(walls: &[Segment], p: &Pose2, sensor: &Sensor) -> (Vec<Vector3<f64>>, Vec<[f64; 2]>) {
    let min_range_m = sensor.min_range_m;
    let (mut points, mut seen) = (Vec::new(), Vec::new());
    for k in -17..=17 {
        let bearing = f64::from(k) * 2.0f64.to_radians();
        let a = p.yaw_rad + bearing;
        let d = [a.cos(), a.sin()];
        let Some(t) = hit(walls, [p.x_m, p.y_m], d) else { continue };
        let mut r = 0.7f64.max(min_range_m);
        while r < t {
            let (x, y) = (p.x_m + d[0] * r, p.y_m + d[1] * r);
            if sensor.returns_from(x, y) {
                points.push(Vector3::new(x, y, 0.0));
            }
            r += 0.1;
        }
        if t < min_range_m || !sensor.returns_from(p.x_m + d[0] * t, p.y_m + d[1] * t) {
            continue;
        }
        for z in [0.3, 0.6, 0.9] {
            points.push(Vector3::new(p.x_m + d[0] * t, p.y_m + d[1] * t, z));
        }
        seen.push([t * bearing.cos(), t * bearing.sin()]);
    }
    (points, seen)
}

/// The distance from `p` to the nearest wall.
fn to_wall(walls: &[Segment], p: &Pose2) -> f64 {
    walls
        .iter()
        .map(|&(a, b)| {
            let e = [b[0] - a[0], b[1] - a[1]];
            let f = (((p.x_m - a[0]) * e[0] + (p.y_m - a[1]) * e[1]) / (e[0] * e[0] + e[1] * e[1])).clamp(0.0, 1.0);
            (a[0] + f * e[0] - p.x_m).hypot(a[1] + f * e[1] - p.y_m)
        })
        .fold(f64::INFINITY, f64::min)
}

/// A run: each period's pose and step, until the explorer is done or `max_s` passes. `extra`
/// are obstacles only the live scan sees (world x, y): someone standing.
struct Run {
    steps: Vec<(Pose2, ExploreStep)>,
    explorer: Explorer,
}

fn explore(start: Pose2, extra: &[[f64; 2]], max_s: f64) -> Run {
    let cfg = ExploreConfig {
        occupancy: OccupancyConfig { extent_m: 30.0, ..OccupancyConfig::default() },
        ..Default::default()
    };
    explore_with(cfg, Sensor::IDEAL, start, extra, max_s)
}

/// [`explore`] with settings `cfg` and the LiDAR `sensor`.
fn explore_with(cfg: ExploreConfig, sensor: Sensor, start: Pose2, extra: &[[f64; 2]], max_s: f64) -> Run {
    let walls = two_rooms();
    let mut explorer = Explorer::new(cfg, [start.x_m, start.y_m]).unwrap();
    let mut pose = start;
    let mut steps = Vec::new();
    for k in 0..(max_s / DT_S) as usize {
        if k % SCAN_EVERY == 0 {
            let (points, _) = scan_from(&walls, &pose, &sensor);
            explorer.add_scan(&Vector3::new(pose.x_m, pose.y_m, 0.5), &points);
        }
        // The explorer keeps the walls it saw and its grid; the caller adds who stands there.
        let obstacles = in_body(&pose, extra.iter().copied());
        let step = explorer.step(k as f64 * DT_S, &pose, &obstacles, DT_S);
        steps.push((pose, step));
        if step.state == ExploreState::Done {
            break;
        }
        pose = pose.after(&step.twist, DT_S);
    }
    Run { steps, explorer }
}

#[test]
fn two_rooms_are_explored_and_the_base_comes_home_without_touching_a_wall() {
    let start = Pose2 { x_m: 1.5, y_m: 2.0, yaw_rad: 0.0 };
    let run = explore(start, &[], 400.0);
    let (end, last) = run.steps.last().unwrap();
    assert_eq!(last.state, ExploreState::Done, "after {} s at {end:?}", run.steps.len() as f64 * DT_S);
    assert!((end.x_m - 1.5).hypot(end.y_m - 2.0) < 0.2, "home: {end:?}");
    // Both rooms' floor known (48 m², less what the base's radius keeps it from seeing close).
    let area = run.explorer.grid().traversable_area_m2();
    assert!(area > 38.0, "{area} m² of 48");
    let radius = ControlConfig::default().robot_radius_m;
    let (closest, at) = run
        .steps
        .iter()
        .map(|(p, _)| (to_wall(&two_rooms(), p), *p))
        .fold((f64::INFINITY, start), |a, b| if b.0 < a.0 { b } else { a });
    assert!(closest > radius, "{closest} m from a wall at {at:?}");
    // It went well into room B, and was done within a minute and a half.
    assert!(run.steps.iter().any(|(p, _)| p.x_m > 8.0));
    assert!(run.steps.len() as f64 * DT_S < 90.0, "{} s", run.steps.len() as f64 * DT_S);
}

/// What the pilot sets for an Avia 0.5 m up: frontiers looked at from 1.1-2.1 m, rays clearing
/// nothing within 1 m, the start's blind ring taken as floor after the first sweep.
fn blind_config() -> ExploreConfig {
    ExploreConfig {
        occupancy: OccupancyConfig { extent_m: 30.0, min_range_m: 1.0, ..OccupancyConfig::default() },
        view_from_m: (1.1, 2.1),
        blind_radius_m: 1.0,
        ..Default::default()
    }
}

#[test]
fn a_frontier_that_looking_does_not_resolve_is_given_up_once_looked_at() {
    // Room B's far end returns nothing: the unknown there stays whatever the base does.
    let sensor = Sensor { min_range_m: 1.0, void: Some(([9.0, -1.0], [13.0, 5.0])) };
    let start = Pose2 { x_m: 1.5, y_m: 2.0, yaw_rad: 0.0 };
    let run = explore_with(blind_config(), sensor, start, &[], 400.0);
    let (end, last) = run.steps.last().unwrap();
    assert_eq!(last.state, ExploreState::Done, "after {} s at {end:?}", run.steps.len() as f64 * DT_S);
    assert!(run.explorer.blacklist().iter().any(|b| (8.5..=9.5).contains(&b[0])), "{:?}", run.explorer.blacklist());
    assert!(run.steps.iter().any(|(p, _)| p.x_m > 7.0), "into room B");
    // Where each sweep began: never twice running at the same place (looking again from
    // where it has just looked would change nothing).
    let starts: Vec<Pose2> = run
        .steps
        .windows(2)
        .filter(|w| {
            !matches!(w[0].1.state, ExploreState::Sweeping { .. })
                && matches!(w[1].1.state, ExploreState::Sweeping { .. })
        })
        .map(|w| w[1].0)
        .collect();
    assert!(starts.len() > 2, "{starts:?}");
    for w in starts.windows(2) {
        assert!((w[0].x_m - w[1].x_m).hypot(w[0].y_m - w[1].y_m) > 0.25, "swept twice at {:?}", w[1]);
    }
}

#[test]
fn a_lidar_blind_within_a_metre_still_explores_both_rooms_by_looking_at_frontiers_from_afar() {
    let start = Pose2 { x_m: 1.5, y_m: 2.0, yaw_rad: 0.0 };
    let run = explore_with(blind_config(), Sensor { min_range_m: 1.0, void: None }, start, &[], 400.0);
    let (end, last) = run.steps.last().unwrap();
    assert_eq!(last.state, ExploreState::Done, "after {} s at {end:?}", run.steps.len() as f64 * DT_S);
    assert!((end.x_m - 1.5).hypot(end.y_m - 2.0) < 0.2, "home: {end:?}");
    let area = run.explorer.grid().traversable_area_m2();
    assert!(area > 34.0, "{area} m² of 48");
    assert!(run.steps.iter().any(|(p, _)| p.x_m > 7.5), "into room B");
    let closest = run.steps.iter().map(|(p, _)| to_wall(&two_rooms(), p)).fold(f64::INFINITY, f64::min);
    assert!(closest > ControlConfig::default().robot_radius_m, "{closest} m from a wall");
}

#[test]
fn a_goal_behind_someone_in_the_doorway_is_given_up_and_the_base_comes_home() {
    let start = Pose2 { x_m: 1.5, y_m: 2.0, yaw_rad: 0.0 };
    // Someone stands in the doorway; the grid is given the walls alone.
    let person: Vec<[f64; 2]> = (0..12).map(|k| [6.0, 1.55 + f64::from(k) * 0.1]).collect();
    let run = explore(start, &person, 400.0);
    let (end, last) = run.steps.last().unwrap();
    assert_eq!(last.state, ExploreState::Done, "{end:?}");
    assert!(!run.explorer.blacklist().is_empty());
    assert!(run.steps.iter().all(|(p, _)| p.x_m < 6.0), "never through the doorway");
    assert!((end.x_m - 1.5).hypot(end.y_m - 2.0) < 0.2, "home: {end:?}");
}

#[test]
fn the_operators_stop_holds_the_base_until_released() {
    let walls = two_rooms();
    let start = Pose2 { x_m: 1.5, y_m: 2.0, yaw_rad: 0.0 };
    let mut e = Explorer::new(ExploreConfig::default(), [1.5, 2.0]).unwrap();
    let (points, seen) = scan(&walls, &start);
    e.add_scan(&Vector3::new(1.5, 2.0, 0.5), &points);
    let first = e.step(0.0, &start, &seen, DT_S);
    assert!(matches!(first.state, ExploreState::Sweeping { .. }) && first.twist.wz_rad_s > 0.0);
    e.hold();
    for k in 1..20 {
        let s = e.step(f64::from(k) * DT_S, &start, &seen, DT_S);
        assert_eq!((s.twist, s.state), (BodyTwist::ZERO, ExploreState::Stopped));
    }
    assert_eq!(e.state(), ExploreState::Stopped);
    e.release();
    let s = e.step(1.0, &start, &seen, DT_S);
    assert!(matches!(s.state, ExploreState::Sweeping { .. }) && s.twist.wz_rad_s > 0.0, "{s:?}");
}
