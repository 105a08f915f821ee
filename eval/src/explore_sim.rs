//! Exploration on a generated building, kinematic: the base moves exactly as the explorer
//! commands, at its true pose, and an idealised Avia (rays in random directions over its
//! 70 x 77 deg view, cast into the simulator's world, people included) scans it. This measures the
//! explorer's policy (where it goes, how much floor it comes to know, whether it touches
//! anything) against the scenario's scripted route scanned the same way; it is not the closed
//! loop over the mock devices with the LIO's poses (`starc sim --explore`, [`crate::explore_loop`]).

use nalgebra::Vector3;
use starc_hil::rng::{hash2, SplitMix64};
use starc_hil::sim::human::Body;
use starc_hil::sim::motion::RobotMotion;
use starc_hil::sim::scenario::Scenario;
use starc_hil::sim::world::World;
use starc_pipeline::explore::{ExploreConfig, ExploreState, Explorer, OccupancyGrid, Pose2};
use std::time::Instant;

/// Settings of a kinematic run.
#[derive(Clone, Debug)]
pub struct KinematicConfig {
    /// How long the explorer may run (s).
    pub duration_s: f64,
    pub control_hz: f64,
    pub scan_hz: f64,
    /// Rays per scan, each in a direction drawn anew over the Avia's 70.4 x 77.2 deg view (as
    /// its non-repetitive pattern fills the view over time; a fixed grid leaves the floor
    /// between its rows unseen, and the grid needs the floor seen cell by cell).
    pub rays_per_scan: usize,
    /// Known floor is sampled this often (s) for the timeline.
    pub sample_s: f64,
    pub explore: ExploreConfig,
}

impl Default for KinematicConfig {
    fn default() -> Self {
        Self {
            duration_s: 180.0,
            control_hz: 20.0,
            scan_hz: 5.0,
            rays_per_scan: 24000,
            sample_s: 10.0,
            explore: ExploreConfig::default(),
        }
    }
}

/// What one run came to know, and how.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct KinematicRun {
    /// Traversable floor known (m²) every `sample_s`, and at the end.
    pub timeline: Vec<(f64, f64)>,
    pub final_area_m2: f64,
    /// When the explorer was done (home, nothing left); None for the scripted route or a run
    /// that used all its time.
    pub done_s: Option<f64>,
    /// Control periods in which the base's disc (the controller's radius) touched a surface or
    /// a person, and how many separate contacts that made.
    pub contact_periods: usize,
    pub contacts: usize,
    pub distance_m: f64,
    /// Time of each control step of the explorer (ms; planning included when it planned).
    pub step_ms: Vec<f64>,
    /// Goals given up.
    pub blacklisted: usize,
}

/// One scan from the base at `pose` at time `t_s`, the `k`th of the run: (sensor origin,
/// returns) in the world.
pub fn scan(
    world: &World,
    cfg: &KinematicConfig,
    lidar_z_m: f64,
    pose: &Pose2,
    t_s: f64,
    k: u64,
) -> (Vector3<f64>, Vec<Vector3<f64>>) {
    let origin = Vector3::new(pose.x_m, pose.y_m, lidar_z_m);
    let bodies = world.bodies_at(t_s);
    let (half_az, half_el) = (35.2f64.to_radians(), 38.6f64.to_radians());
    let mut rng = SplitMix64::new(hash2(0x5ca7, k));
    let mut points = Vec::with_capacity(cfg.rays_per_scan);
    for _ in 0..cfg.rays_per_scan {
        let az = pose.yaw_rad + (rng.next_f64() * 2.0 - 1.0) * half_az;
        let el = (rng.next_f64() * 2.0 - 1.0) * half_el;
        let d = Vector3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin());
        if let Some(h) = world.cast(&origin, &d, 30.0, &bodies) {
            points.push(origin + d * h.t);
        }
    }
    (origin, points)
}

/// Whether the base's disc of `radius_m` at `pose` touches anything ([`disc_hit`]).
pub fn touches(world: &World, pose: &Pose2, radius_m: f64, t_s: f64) -> bool {
    disc_hit(world, &world.bodies_at(t_s), [pose.x_m, pose.y_m], radius_m).is_some()
}

/// What a disc of `radius_m` centred at (x, y) on the floor touches, people as `bodies`:
/// horizontal rays in 16 directions at 0.1, 0.5 and 1.0 m; the label hit (0 the building, k
/// person k) and the lowest height it was hit at. The scorer's one notion of the base's body.
pub fn disc_hit(world: &World, bodies: &[Body], [x, y]: [f64; 2], radius_m: f64) -> Option<(u16, f64)> {
    [0.1, 0.5, 1.0].into_iter().find_map(|z| {
        (0..16).find_map(|k| {
            let a = f64::from(k) * std::f64::consts::TAU / 16.0;
            let d = Vector3::new(a.cos(), a.sin(), 0.0);
            world.cast(&Vector3::new(x, y, z), &d, radius_m, bodies).map(|h| (h.label, z))
        })
    })
}

/// Counts a period's contact into `run` (a new contact when the last period had none).
fn note_contact(run: &mut KinematicRun, touching: bool, was: &mut bool) {
    if touching {
        run.contact_periods += 1;
        if !*was {
            run.contacts += 1;
        }
    }
    *was = touching;
}

/// The explorer from the scripted route's start, for `cfg.duration_s` or until it is done.
pub fn explore_kinematic(scenario: &Scenario, cfg: &KinematicConfig) -> Option<KinematicRun> {
    let robot = scenario.robot.get_ref();
    let start = robot.waypoints.first()?;
    let world = World::new(scenario);
    let mut explorer = Explorer::new(cfg.explore, [start[0], start[1]])?;
    let mut pose = Pose2 { x_m: start[0], y_m: start[1], yaw_rad: start[2].to_radians() };
    let (dt_s, scan_every) = (1.0 / cfg.control_hz, (cfg.control_hz / cfg.scan_hz).round().max(1.0) as usize);
    let mut run = KinematicRun::default();
    let (mut was, mut next_s) = (false, 0.0);
    for k in 0..(cfg.duration_s * cfg.control_hz) as usize {
        let t_s = k as f64 * dt_s;
        if k % scan_every == 0 {
            let (origin, pts) = scan(&world, cfg, robot.lidar_height_m, &pose, t_s, k as u64);
            explorer.add_scan(&origin, &pts);
        }
        sample(&mut run, explorer.grid(), t_s, cfg.sample_s, &mut next_s);
        // The explorer's own memory of the placed scans and its grid are all the controller gets.
        let t0 = Instant::now();
        let step = explorer.step(t_s, &pose, &[], dt_s);
        run.step_ms.push(t0.elapsed().as_secs_f64() * 1e3);
        if step.state == ExploreState::Done {
            run.done_s = Some(t_s);
            break;
        }
        let next = pose.after(&step.twist, dt_s);
        run.distance_m += (next.x_m - pose.x_m).hypot(next.y_m - pose.y_m);
        pose = next;
        note_contact(&mut run, touches(&world, &pose, cfg.explore.control.robot_radius_m, t_s), &mut was);
    }
    run.final_area_m2 = explorer.grid().traversable_area_m2();
    run.timeline.push((run.done_s.unwrap_or(cfg.duration_s), run.final_area_m2));
    run.blacklisted = explorer.blacklist().len();
    Some(run)
}

/// The scenario's scripted route, scanned the same way, to its end.
pub fn scripted_kinematic(scenario: &Scenario, cfg: &KinematicConfig) -> Option<KinematicRun> {
    let robot = scenario.robot.get_ref();
    let start = robot.waypoints.first()?;
    let world = World::new(scenario);
    let motion = RobotMotion::new(robot);
    let mut grid = OccupancyGrid::new(cfg.explore.occupancy, [start[0], start[1]])?;
    let (dt_s, scan_every) = (1.0 / cfg.control_hz, (cfg.control_hz / cfg.scan_hz).round().max(1.0) as usize);
    let t0 = robot.start_s + robot.static_s;
    let mut run = KinematicRun::default();
    let (mut was, mut last, mut next_s): (bool, Option<Pose2>, f64) = (false, None, 0.0);
    for k in 0..((motion.route().end_s() - t0).max(0.0) * cfg.control_hz) as usize {
        let t_s = k as f64 * dt_s;
        let p = motion.base_pose(t0 + t_s);
        let pose = Pose2 { x_m: p.translation.x, y_m: p.translation.y, yaw_rad: p.rotation.euler_angles().2 };
        if k % scan_every == 0 {
            let (origin, pts) = scan(&world, cfg, robot.lidar_height_m, &pose, t0 + t_s, k as u64);
            grid.add_scan(&origin, &pts);
        }
        grid.mark_driven(pose.x_m, pose.y_m, cfg.explore.control.robot_radius_m);
        sample(&mut run, &grid, t_s, cfg.sample_s, &mut next_s);
        if let Some(l) = last {
            run.distance_m += (pose.x_m - l.x_m).hypot(pose.y_m - l.y_m);
        }
        last = Some(pose);
        note_contact(&mut run, touches(&world, &pose, cfg.explore.control.robot_radius_m, t0 + t_s), &mut was);
    }
    run.final_area_m2 = grid.traversable_area_m2();
    run.timeline.push(((motion.route().end_s() - t0).max(0.0), run.final_area_m2));
    Some(run)
}

/// The known floor at `t_s` once `next_s` is due, and the next sample's time.
fn sample(run: &mut KinematicRun, grid: &OccupancyGrid, t_s: f64, every_s: f64, next_s: &mut f64) {
    if t_s + 1e-9 >= *next_s {
        run.timeline.push((t_s, grid.traversable_area_m2()));
        *next_s += every_s;
    }
}

/// The known floor at time `t_s` of a run's timeline (its last sample at or before it).
pub fn area_at(run: &KinematicRun, t_s: f64) -> Option<f64> {
    run.timeline.iter().rev().find(|(t, _)| *t <= t_s + 1e-9).map(|&(_, a)| a)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used)]
    use super::*;

    #[test]
    fn a_short_run_on_a_generated_building_knows_floor_and_times_its_steps() {
        let g = starc_hil::gen::generate(1, None).unwrap();
        let cfg =
            KinematicConfig { duration_s: 10.0, rays_per_scan: 3000, sample_s: 2.0, ..KinematicConfig::default() };
        let run = explore_kinematic(&g.scenario, &cfg).unwrap();
        // The first sweep (2 pi at 1 rad/s) sees the start's surroundings.
        assert!(run.final_area_m2 > 5.0, "{run:?}");
        assert!(run.timeline.windows(2).all(|w| w[0].0 <= w[1].0 && w[0].1 <= w[1].1 + 1.0), "{:?}", run.timeline);
        assert_eq!(
            run.step_ms.len() as f64,
            run.done_s.map_or(cfg.duration_s * cfg.control_hz, |t| t * cfg.control_hz + 1.0)
        );
        // Sampled from the first scan on; nothing before it.
        assert!(area_at(&run, 0.0).is_some_and(|a| a > 0.0) && area_at(&run, -1.0).is_none());
        let scripted = scripted_kinematic(&g.scenario, &cfg).unwrap();
        assert!(scripted.final_area_m2 > 5.0 && scripted.distance_m > 1.0, "{scripted:?}");
        assert!(scripted.done_s.is_none() && scripted.step_ms.is_empty());
    }
}
