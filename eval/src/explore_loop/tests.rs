#![allow(clippy::unwrap_used, clippy::expect_used)]
use super::*;
use starc_hil::sim::run::{run_driven, SimOptions};

const BASE_TOML: &str = include_str!("../../../config/base.toml");

/// The shipped lab, its robot driven by the explorer (or, `scripted`, on its waypoints) for
/// `duration_s`, sensors only.
fn loop_lab(duration_s: f64, dir: &std::path::Path, scripted: bool) -> ExploreLoop {
    let (scenario, text) = Scenario::load("lab").unwrap();
    let template = BaseConfig::from_toml(BASE_TOML).unwrap();
    let cfg = LoopConfig { scripted, ..LoopConfig::for_robot(scenario.robot.get_ref(), template, 1) };
    let mut driver = ExploreLoop::new(&scenario, cfg).unwrap();
    let opts = SimOptions { out: dir.into(), duration_s: Some(duration_s), seed: 1, realtime: false, camera: false };
    run_driven(&scenario, &text, &opts, Some(&mut driver as &mut dyn RobotDriver), &mut |_, _| {}).unwrap();
    driver
}

#[test]
fn the_explorer_drives_the_simulated_base_over_slcan_on_its_own_lio() {
    let dir = tempfile::tempdir().unwrap();
    let driver = loop_lab(14.0, dir.path(), false);
    let r = driver.report();
    // It swept (about 7 s from the LIO's start) and then drove off to look at a frontier.
    assert!(r.distance_m > 0.5, "{r:?}");
    assert_eq!((r.contacts, r.base_faults), (0, 0), "{r:?}");
    assert!(r.final_area_m2 > 20.0 && r.timeline.windows(2).all(|w| w[0].0 < w[1].0), "{r:?}");
    // The lab's reachable floor (truth), and the share of it known, growing from the first pose.
    assert!(r.reachable_m2 > 30.0 && r.coverage.len() >= 10, "{r:?}");
    let (first, last) = (r.coverage[0].1, r.coverage[r.coverage.len() - 1].1);
    assert!(first > 0.1 && last > first && last <= 1.0, "{:?}", r.coverage);
    // Every 10 ms a command frame went out, and the three ESCs answered at 1 kHz.
    assert!(r.bus.frames_sent >= 1390 && r.bus.feedback_frames >= 3 * 13_900, "{:?}", r.bus);
    assert_eq!(r.bus.motors.adapter.refused, 0);
    // The simulator moved the robot along the track the motors drove: its truth file ends
    // where the track does.
    let truth = std::fs::read_to_string(dir.path().join("gt_robot.tum")).unwrap();
    let last: Vec<f64> = truth.lines().last().unwrap().split(' ').map(|v| v.parse().unwrap()).collect();
    let end = driver.body.truth_at(14.0);
    assert!((last[1] - end.x).abs() < 0.01 && (last[2] - end.y).abs() < 0.01, "{last:?} {end:?}");
    // The pilot's pose (the LIO's, carried by the wheels) moved as the truth did, from the start.
    let start = driver.body.truth_at(0.0);
    let pose = driver.pilot.pose_at(14_000_000_000u64.saturating_add_signed(AviaLink::ptp_offset_ns())).unwrap();
    let true_moved = (end.x - start.x).hypot(end.y - start.y);
    let home = driver.pilot.explorer().unwrap().home();
    let lio_moved = (pose.x_m - home[0]).hypot(pose.y_m - home[1]);
    assert!(true_moved > 0.5 && (lio_moved - true_moved).abs() < 0.05, "{lio_moved} m against {true_moved} m");
}

#[test]
fn the_scripted_route_is_measured_the_same_way_and_nothing_drives_the_robot() {
    let dir = tempfile::tempdir().unwrap();
    let driver = loop_lab(12.0, dir.path(), true);
    let r = driver.report();
    assert_eq!((r.mode, r.bus.frames_sent, r.contacts), ("scripted", 0, 0), "{r:?}");
    assert!(r.distance_m > 1.0 && r.step_ms.n == 0, "{r:?}");
    assert!(r.reachable_m2 > 30.0 && r.coverage.last().is_some_and(|c| c.1 > 0.1), "{r:?}");
    // The robot moved along its waypoints: gt_robot.tum is the scripted route's.
    let (scenario, _) = Scenario::load("lab").unwrap();
    let route = starc_hil::sim::motion::RobotMotion::new(scenario.robot.get_ref());
    let truth = std::fs::read_to_string(dir.path().join("gt_robot.tum")).unwrap();
    let last: Vec<f64> = truth.lines().last().unwrap().split(' ').map(|v| v.parse().unwrap()).collect();
    let end = route.base_pose(12.0).translation.vector;
    assert!((last[1] - end.x).abs() < 0.01 && (last[2] - end.y).abs() < 0.01, "{last:?} {end:?}");
}

#[test]
fn the_simulated_base_is_set_up_as_the_scenario_builds_it() {
    let (scenario, _) = Scenario::load("lab").unwrap();
    let template = BaseConfig::from_toml(BASE_TOML).unwrap();
    let cfg = sim_base_config(scenario.robot.get_ref(), template.clone());
    assert_eq!(cfg.kinematics, starc_hil::sim::wheels::default_geometry(scenario.robot.get_ref().wheels));
    let ids: Vec<u8> = cfg.motors.wheels.iter().map(|w| w.id).collect();
    assert_eq!(ids, (1..=cfg.kinematics.wheel_count() as u8).collect::<Vec<_>>());
    // The rest is the template's: limits, watchdog, gains.
    assert_eq!((cfg.limits, cfg.watchdog_ms), (template.limits, template.watchdog_ms));
}
