//! The local controller on synthetic floors, in a closed loop: the base moves as commanded
//! (holonomic, exactly), and sees the world's obstacle points inside the Avia's view.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use super::*;

const DT_S: f64 = 0.05;

/// World points in the body frame at `p`.
pub(super) fn in_body(p: &Pose2, world: impl Iterator<Item = [f64; 2]>) -> Vec<[f64; 2]> {
    world.map(|w| p.to_body(w)).collect()
}

/// The world points the Avia sees from `p`: inside its 70.4 deg view, within 15 m; body frame.
pub(super) fn seen(p: &Pose2, world: &[[f64; 2]]) -> Vec<[f64; 2]> {
    in_body(p, world.iter().copied())
        .into_iter()
        .filter(|b| b[1].atan2(b[0]).abs() <= 35.2f64.to_radians() && b[0].hypot(b[1]) <= 15.0)
        .collect()
}

/// Points every 5 cm from `a` to `b`.
fn wall(a: [f64; 2], b: [f64; 2]) -> Vec<[f64; 2]> {
    let n = ((b[0] - a[0]).hypot(b[1] - a[1]) / 0.05).ceil() as usize;
    (0..=n).map(|k| k as f64 / n as f64).map(|f| [a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1])]).collect()
}

/// Every step of a closed-loop run from `start` until the controller arrives or `steps` pass.
fn run(start: Pose2, path: &[[f64; 2]], world: &[[f64; 2]], steps: usize) -> Vec<(Pose2, ControlStep)> {
    run_with(start, path, steps, |p| seen(p, world))
}

/// As [`run`], with the obstacles at each pose from `obstacles` (body frame).
pub(super) fn run_with(
    start: Pose2,
    path: &[[f64; 2]],
    steps: usize,
    obstacles: impl Fn(&Pose2) -> Vec<[f64; 2]>,
) -> Vec<(Pose2, ControlStep)> {
    let mut c = LocalController::new(ControlConfig::default());
    let mut pose = start;
    let mut out = Vec::new();
    for _ in 0..steps {
        let step = c.step(&pose, path, &obstacles(&pose), DT_S);
        out.push((pose, step));
        if step.state == ControlState::Arrived {
            break;
        }
        pose = pose.after(&step.twist, DT_S);
    }
    out
}

fn at(x_m: f64, y_m: f64, yaw_deg: f64) -> Pose2 {
    Pose2 { x_m, y_m, yaw_rad: yaw_deg.to_radians() }
}

#[test]
fn a_straight_path_is_driven_to_its_end_within_the_limits() {
    let cfg = ControlConfig::default();
    let steps = run(at(0.0, 0.0, 0.0), &[[0.0, 0.0], [5.0, 0.0]], &[], 400);
    let (end, last) = steps.last().unwrap();
    assert_eq!(last.state, ControlState::Arrived);
    assert!((end.x_m - 5.0).hypot(end.y_m) <= cfg.goal_tolerance_m, "{end:?}");
    // Full speed on the way, and never more; speeding up and turning up within the limits.
    let top = steps.iter().map(|(_, s)| s.twist.speed_m_s()).fold(0.0, f64::max);
    assert!((top - cfg.max_speed_m_s).abs() < 1e-9, "{top}");
    for pair in steps.windows(2) {
        let (a, b) = (pair[0].1.twist, pair[1].1.twist);
        assert!(b.speed_m_s() - a.speed_m_s() <= cfg.max_accel_m_s2 * DT_S + 1e-9);
        assert!(b.wz_rad_s.abs() - a.wz_rad_s.abs() <= cfg.max_alpha_rad_s2 * DT_S + 1e-9);
    }
    // 5 m at 0.5 m/s with 1 s to speed up and about 1 s to slow down: 11-13 s.
    let t_s = steps.len() as f64 * DT_S;
    assert!((10.0..14.0).contains(&t_s), "{t_s} s");
}

#[test]
fn a_way_outside_the_view_is_turned_to_before_the_base_moves_along_it() {
    let cfg = ControlConfig::default();
    let path = [[0.0, 0.0], [0.0, 3.0]];
    let steps = run(at(0.0, 0.0, 0.0), &path, &[], 400);
    let first = steps.first().unwrap().1;
    assert_eq!(first.state, ControlState::Turning);
    assert!(first.twist.speed_m_s() < 1e-12 && first.twist.wz_rad_s > 0.0, "{first:?}");
    // Never moving towards more than twice the view's half angle off the heading.
    for (_, s) in &steps {
        if s.twist.speed_m_s() > 1e-9 {
            let off = s.twist.vy_m_s.atan2(s.twist.vx_m_s).abs().to_degrees();
            assert!(off < 2.0 * cfg.view_half_deg, "{off} deg off the heading");
        }
    }
    let (end, last) = steps.last().unwrap();
    assert_eq!(last.state, ControlState::Arrived);
    assert!((end.yaw_rad.to_degrees() - 90.0).abs() < 15.0, "faces the way it came: {end:?}");
}

#[test]
fn a_corner_is_followed_to_the_path_end() {
    let path = [[0.0, 0.0], [3.0, 0.0], [3.0, 3.0]];
    let steps = run(at(0.0, 0.0, 0.0), &path, &[], 600);
    let (end, last) = steps.last().unwrap();
    assert_eq!(last.state, ControlState::Arrived, "{end:?}");
    // It cuts the corner by no more than the lookahead.
    let worst = steps.iter().map(|(p, _)| (p.x_m - 3.0).max(0.0) + (-p.y_m).max(0.0)).fold(0.0, f64::max);
    assert!(worst < 0.1, "{worst} m outside the path's box");
}

#[test]
fn a_wall_across_the_way_stops_the_base_short_of_it() {
    let cfg = ControlConfig::default();
    let world = wall([2.0, -1.5], [2.0, 1.5]);
    let steps = run(at(0.0, 0.0, 0.0), &[[0.0, 0.0], [5.0, 0.0]], &world, 300);
    let (end, last) = steps.last().unwrap();
    assert!(matches!(last.state, ControlState::Blocked { .. }), "{last:?}");
    assert!(last.twist.speed_m_s() < 1e-12);
    // Stopped with the margin kept, and never closer on the way.
    let nearest = steps.iter().map(|(p, _)| 2.0 - p.x_m - cfg.robot_radius_m).fold(f64::INFINITY, f64::min);
    assert!(nearest >= cfg.stop_margin_m - 0.01, "{nearest} m clear");
    assert!(nearest < cfg.stop_margin_m + 0.05, "stops near the margin, not far before it: {end:?}");
}

#[test]
fn slowing_for_an_obstacle_is_not_held_back_by_the_speed_up_limit() {
    let cfg = ControlConfig::default();
    let mut c = LocalController::new(cfg);
    let path = [[0.0, 0.0], [10.0, 0.0]];
    let pose = at(0.0, 0.0, 0.0);
    for _ in 0..40 {
        c.step(&pose, &path, &[], DT_S);
    }
    assert!((c.step(&pose, &path, &[], DT_S).twist.speed_m_s() - cfg.max_speed_m_s).abs() < 1e-9);
    // Someone steps in 0.5 m ahead: 0.1 m of room left, so at most sqrt(2 a 0.1).
    let step = c.step(&pose, &path, &[[0.5, 0.0]], DT_S);
    let cap = (2.0 * cfg.max_accel_m_s2 * 0.1).sqrt();
    assert!(step.twist.speed_m_s() <= cap + 1e-9, "{step:?}");
    assert_eq!(step.state, ControlState::Driving);
    let step = c.step(&pose, &path, &[[0.35, 0.0]], DT_S);
    assert!(matches!(step.state, ControlState::Blocked { .. }) && step.twist.speed_m_s() == 0.0, "{step:?}");
}

#[test]
fn clearance_counts_only_what_lies_on_the_way() {
    let ahead = [1.0, 0.0];
    assert!((clearance_m(&[[1.0, 0.0]], ahead, 0.3) - 0.7).abs() < 1e-12);
    assert!((clearance_m(&[[1.0, 0.18]], ahead, 0.3) - 0.76).abs() < 1e-12, "off the centre line");
    assert_eq!(clearance_m(&[[1.0, 0.5]], ahead, 0.3), f64::INFINITY, "beside the way");
    assert_eq!(clearance_m(&[[-0.2, 0.0], [-3.0, 0.0]], ahead, 0.3), f64::INFINITY, "behind");
    assert_eq!(clearance_m(&[[0.1, 0.1]], ahead, 0.3), 0.0, "touching already");
    assert_eq!(clearance_m(&[[f64::NAN, 0.0]], ahead, 0.3), f64::INFINITY);
    // Sideways: the wall ahead does not matter, the one to the left does.
    assert_eq!(clearance_m(&[[1.0, 0.0]], [0.0, 1.0], 0.3), f64::INFINITY);
    assert!((clearance_m(&[[0.0, 2.0]], [0.0, 1.0], 0.3) - 1.7).abs() < 1e-12);
}

#[test]
fn bad_input_leaves_the_base_standing() {
    let mut c = LocalController::new(ControlConfig::default());
    let path = [[0.0, 0.0], [5.0, 0.0]];
    let good = at(0.0, 0.0, 0.0);
    for step in [
        c.step(&good, &[], &[], DT_S),
        c.step(&at(f64::NAN, 0.0, 0.0), &path, &[], DT_S),
        c.step(&good, &[[0.0, 0.0], [f64::INFINITY, 0.0]], &[], DT_S),
        c.step(&good, &path, &[], 0.0),
        c.step(&good, &path, &[], f64::NAN),
    ] {
        assert_eq!(step, ControlStep { twist: BodyTwist::ZERO, state: ControlState::Idle });
    }
    // A NaN obstacle is ignored, not a reason to stop or to move wildly.
    let step = c.step(&good, &path, &[[f64::NAN, f64::NAN]], DT_S);
    assert_eq!(step.state, ControlState::Driving);
    assert!(step.twist.speed_m_s() <= ControlConfig::default().max_accel_m_s2 * DT_S + 1e-12);
}

#[test]
fn a_post_on_the_path_stops_the_base_and_the_way_round_it_is_driven() {
    let cfg = ControlConfig::default();
    // A post 10 cm across on the path, held by the grid once out of the view.
    let post: Vec<[f64; 2]> = wall([2.45, -0.05], [2.55, 0.05]);
    let near = |p: &Pose2| {
        let close = post.iter().filter(|o| (o[0] - p.x_m).hypot(o[1] - p.y_m) < 2.0).copied();
        in_body(p, close)
    };
    let kept = cfg.robot_radius_m + cfg.stop_margin_m;
    let nearest = |steps: &[(Pose2, ControlStep)]| {
        steps
            .iter()
            .flat_map(|(p, _)| post.iter().map(move |o| (o[0] - p.x_m).hypot(o[1] - p.y_m)))
            .fold(f64::INFINITY, f64::min)
    };
    let steps = run_with(at(0.0, 0.0, 0.0), &[[0.0, 0.0], [5.0, 0.0]], 300, near);
    let (stop, last) = *steps.last().unwrap();
    assert!(matches!(last.state, ControlState::Blocked { .. }), "{last:?}");
    assert!(nearest(&steps) > kept - 0.02, "{} m from the post", nearest(&steps));
    // Planned again with the post in the grid: round it, 0.8 m off the line.
    let round = [[stop.x_m, stop.y_m], [2.0, 0.8], [3.0, 0.8], [5.0, 0.0]];
    let steps = run_with(stop, &round, 600, near);
    let (end, last) = steps.last().unwrap();
    assert_eq!(last.state, ControlState::Arrived, "{end:?}");
    assert!(nearest(&steps) > kept - 0.02, "{} m from the post", nearest(&steps));
}
