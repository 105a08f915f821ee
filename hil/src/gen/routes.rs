//! The robot's and the responder's routes through a generated building, planned on its
//! occupancy grid: the robot visits the rooms that hold people; the responder starts where the
//! robot has been but outside its first view, walks through mapped space, and ends facing a
//! wall with someone the robot saw behind it.

use crate::gen::families::Building;
use crate::gen::grid::Grid;
use crate::gen::layout::Dice;
use crate::gen::plan::{PlanPerson, Routes};
use crate::sim::motion::{ResponderMotion, RobotMotion};
use crate::sim::obstacles::{
    distance_to_polyline, distance_to_segment, segment_points, Doorway, FloorPlan, Footprint, ObstacleKind,
};
use crate::sim::scenario::{Responder, Robot};

/// The robot stops visiting rooms once its route is this long: a run's length is mostly the
/// robot's drive (rest to rest at about half its top speed), and a held-out evaluation of two
/// dozen buildings must fit in minutes.
const MAX_ROBOT_ROUTE_M: f64 = 12.0;
/// The robot starts this far (straight line) from the way into the first room with people:
/// it has been driven in, and the search starts near them.
const ENTRY_REACH_M: (f64, f64) = (2.5, 6.0);
/// The robot stops this far from anyone.
const KEEP_FROM_PEOPLE_M: f64 = 1.2;
/// Turns sharper than this are made on the spot, before the next leg.
const TURN_ON_SPOT_DEG: f64 = 30.0;
/// The responder's end point is this far outside the inner face of the person's room or aisle,
/// nearest first.
/// Beyond a double row of racking (2-2.4 m deep) the farther ones are the same distance from
/// its far face.
const FACING_WALL_M: [f64; 7] = [1.0, 1.3, 1.7, 3.0, 3.3, 3.7, 4.1];
/// ... and within this distance of somewhere the robot drove: space the robot has mapped.
const MAPPED_REACH_M: f64 = 4.0;
/// The responder walks at least this far when the building allows, and never farther than
/// the longer bound (a run's length is what an evaluation pays for).
const MIN_WALK_M: f64 = 3.0;
const MAX_WALK_M: f64 = 12.0;
/// Furniture at least this tall hides who is behind it as a wall does (loaded racking).
const OCCLUDER_M: f64 = 1.8;
/// The responder stays this long at the end, looking through the wall.
const LOOK_S: f64 = 8.0;

/// Why a building got no routes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum NoRoute {
    /// No room with people that the robot can reach.
    #[error("no room with people that the robot can reach")]
    NoReachablePeople,
    /// No place behind a wall from a seen person that the responder can reach.
    #[error("no place behind a wall from a person the robot saw that the responder can reach")]
    NoResponderGoal,
}

/// The robot's visits, then the responder's walk.
/// `plan` is the building's floor plan without its people; `grid` has them.
pub fn plan(
    d: &mut Dice,
    (b, plan): (&Building, &FloorPlan),
    people: &[PlanPerson],
    grid: &Grid,
) -> Result<Routes, NoRoute> {
    let entry = choose_entry(d, b, people, grid);
    let (robot_xy, visited) = robot_path(entry, b, people, grid)?;
    let robot = with_headings(&robot_xy, entry[2], people, &visited);
    let robot_speed = d.range(0.5, 0.8);
    let robot_motion = RobotMotion::new(&Robot::with_route(robot.clone(), robot_speed));
    let responder_speed = d.range(0.8, 1.2);
    let seen: Vec<&PlanPerson> = people.iter().filter(|p| visited.contains(&p.region) && p.path.is_empty()).collect();
    let (responder, start_s) = responder_walk(d, (entry, b, plan), grid, &robot_xy, &robot_motion, &seen)?;
    let walk_end =
        ResponderMotion::new(&Responder::with_route(responder.clone(), start_s, responder_speed)).route().end_s();
    let duration_s = (robot_motion.route().end_s() + 2.0).max(walk_end + LOOK_S).ceil();
    Ok(Routes {
        robot,
        robot_speed_m_s: robot_speed,
        responder,
        responder_start_s: start_s,
        responder_speed_m_s: responder_speed,
        duration_s,
    })
}

/// The robot's path through every reachable room with people, nearest first, and the rooms.
fn robot_path(
    entry: [f64; 3],
    b: &Building,
    people: &[PlanPerson],
    grid: &Grid,
) -> Result<(Vec<[f64; 2]>, Vec<usize>), NoRoute> {
    let mut at = [entry[0], entry[1]];
    let mut path = vec![at];
    let mut visited = Vec::new();
    let mut todo: Vec<usize> = people.iter().map(|p| p.region).collect();
    todo.sort_unstable();
    todo.dedup();
    let mut length = 0.0;
    while !todo.is_empty() && length < MAX_ROBOT_ROUTE_M {
        let legs: Vec<(usize, Vec<[f64; 2]>)> =
            todo.iter().filter_map(|&r| Some((r, grid.path(at, view_point(b, r, people, grid)?)?))).collect();
        let Some((region, leg)) = legs.into_iter().min_by(|a, b| polyline_m(&a.1).total_cmp(&polyline_m(&b.1))) else {
            break;
        };
        todo.retain(|&r| r != region);
        length += polyline_m(&leg);
        if length > MAX_ROBOT_ROUTE_M && !visited.is_empty() {
            break;
        }
        path.extend(leg.iter().skip(1));
        at = *path.last().unwrap_or(&at);
        visited.push(region);
    }
    if visited.is_empty() {
        return Err(NoRoute::NoReachablePeople);
    }
    Ok((path, visited))
}

/// Where the robot starts: a passable point of the first region (the corridor, the main aisle)
/// a few metres from the way into a room with people, facing it; the building's own entry
/// when there is none.
fn choose_entry(d: &mut Dice, b: &Building, people: &[PlanPerson], grid: &Grid) -> [f64; 3] {
    let doors: Vec<[f64; 2]> = people.iter().filter_map(|p| b.regions.get(p.region)?.entrance).collect();
    let (Some(door), Some(start)) = (d.pick(&doors), b.regions.first()) else { return b.entry };
    let r = start.rect;
    let step = 0.25;
    let mut candidates = Vec::new();
    for i in 0..=(r.size()[0] / step) as usize {
        for j in 0..=(r.size()[1] / step) as usize {
            let p = [r.min[0] + i as f64 * step, r.min[1] + j as f64 * step];
            let reach = (p[0] - door[0]).hypot(p[1] - door[1]);
            if (ENTRY_REACH_M.0..=ENTRY_REACH_M.1).contains(&reach) && grid.passable(p) {
                candidates.push(p);
            }
        }
    }
    match d.pick(&candidates) {
        Some(p) => [p[0], p[1], (door[1] - p[1]).atan2(door[0] - p[0]).to_degrees()],
        None => b.entry,
    }
}

/// Where the robot stops to look at a region: the passable point nearest its centre, clear of
/// its people.
fn view_point(b: &Building, region: usize, people: &[PlanPerson], grid: &Grid) -> Option<[f64; 2]> {
    let r = b.regions.get(region)?.rect;
    let c = r.centre();
    let mut best: Option<([f64; 2], f64)> = None;
    let step = 0.25;
    let (nx, ny) = ((r.size()[0] / step) as usize, (r.size()[1] / step) as usize);
    for i in 0..=nx {
        for j in 0..=ny {
            let p = [r.min[0] + i as f64 * step, r.min[1] + j as f64 * step];
            let near_person = people.iter().any(|q| (q.at[0] - p[0]).hypot(q.at[1] - p[1]) < KEEP_FROM_PEOPLE_M);
            if near_person || !grid.passable(p) {
                continue;
            }
            let dist = (p[0] - c[0]).hypot(p[1] - c[1]);
            if best.is_none_or(|(_, d)| dist < d) {
                best = Some((p, dist));
            }
        }
    }
    best.map(|(p, _)| p)
}

fn polyline_m(points: &[[f64; 2]]) -> f64 {
    points.windows(2).map(|w| (w[1][0] - w[0][0]).hypot(w[1][1] - w[0][1])).sum()
}

/// Waypoints with headings: the robot faces along each leg, turns on the spot where a leg
/// bends sharply, and at the end turns to face the people of the last room it visited.
fn with_headings(path: &[[f64; 2]], start_deg: f64, people: &[PlanPerson], visited: &[usize]) -> Vec<[f64; 3]> {
    let mut out = Vec::new();
    let mut heading = start_deg;
    let Some(first) = path.first() else { return out };
    out.push([first[0], first[1], heading]);
    for pair in path.windows(2) {
        let (a, b) = (pair[0], pair[1]);
        if (b[0] - a[0]).hypot(b[1] - a[1]) < 1e-3 {
            continue;
        }
        let towards = heading + wrap_deg((b[1] - a[1]).atan2(b[0] - a[0]).to_degrees() - heading);
        if (towards - heading).abs() > TURN_ON_SPOT_DEG {
            out.push([a[0], a[1], towards]);
        }
        heading = towards;
        out.push([b[0], b[1], heading]);
    }
    // Face the people of the last room visited.
    if let (Some(&last), Some(&region)) = (path.last(), visited.last()) {
        let here: Vec<&PlanPerson> = people.iter().filter(|p| p.region == region).collect();
        if !here.is_empty() {
            let n = here.len() as f64;
            let c = [here.iter().map(|p| p.at[0]).sum::<f64>() / n, here.iter().map(|p| p.at[1]).sum::<f64>() / n];
            let towards = heading + wrap_deg((c[1] - last[1]).atan2(c[0] - last[0]).to_degrees() - heading);
            out.push([last[0], last[1], towards]);
        }
    }
    out
}

fn wrap_deg(a: f64) -> f64 {
    (a + 180.0).rem_euclid(360.0) - 180.0
}

/// The responder's walk and start time: from a point of the robot's path outside its first
/// view, at least `MIN_WALK_M` of walking from a place facing a wall with a seen person behind
/// it (the longest walk found when none is that long).
fn responder_walk(
    d: &mut Dice,
    (entry, b, plan): ([f64; 3], &Building, &FloorPlan),
    grid: &Grid,
    robot_xy: &[[f64; 2]],
    robot: &RobotMotion,
    seen: &[&PlanPerson],
) -> Result<(Vec<[f64; 2]>, f64), NoRoute> {
    let starts = responder_starts(entry, grid, robot_xy);
    let mut order: Vec<usize> = (0..seen.len()).collect();
    for i in (1..order.len()).rev() {
        order.swap(i, d.below(i + 1));
    }
    let mut best: Option<(Vec<[f64; 2]>, [f64; 2])> = None;
    'search: for i in order {
        let Some(person) = seen.get(i) else { continue };
        for goal in behind_wall_goals((b, plan), grid, person, robot_xy) {
            for &start in &starts {
                if (start[0] - goal[0]).hypot(start[1] - goal[1]) < MIN_WALK_M * 0.7 {
                    continue;
                }
                let Some(mut walk) = grid.path(start, goal).filter(|w| polyline_m(w) <= MAX_WALK_M) else {
                    continue;
                };
                // A last short step towards the person: the responder ends facing the wall.
                let (dx, dy) = (person.at[0] - goal[0], person.at[1] - goal[1]);
                let n = dx.hypot(dy).max(1e-6);
                walk.push([goal[0] + dx / n * 0.25, goal[1] + dy / n * 0.25]);
                let long_enough = polyline_m(&walk) >= MIN_WALK_M;
                if best.as_ref().is_none_or(|(w, _)| polyline_m(&walk) > polyline_m(w)) {
                    best = Some((walk, start));
                }
                if long_enough {
                    break 'search;
                }
            }
        }
    }
    let (walk, start) = best.ok_or(NoRoute::NoResponderGoal)?;
    Ok((walk, time_robot_passed(robot, start) + 2.0))
}

/// Passable points of the robot's path, every 0.5 m, where the responder may start: outside
/// the robot's first view (70 deg wide, as the Avia's) or 9 m or more along its path; past the
/// first 2 m when no point is.
fn responder_starts(entry: [f64; 3], grid: &Grid, robot_xy: &[[f64; 2]]) -> Vec<[f64; 2]> {
    let (sx, sy, yaw) = (entry[0], entry[1], entry[2].to_radians());
    let mut along = 0.0;
    let (mut outside, mut fallback) = (Vec::new(), Vec::new());
    for pair in robot_xy.windows(2) {
        let seg = (pair[1][0] - pair[0][0]).hypot(pair[1][1] - pair[0][1]);
        let steps = (seg / 0.5).ceil().max(1.0) as usize;
        for k in 0..steps {
            let t = k as f64 / steps as f64;
            let p = [pair[0][0] + (pair[1][0] - pair[0][0]) * t, pair[0][1] + (pair[1][1] - pair[0][1]) * t];
            let s = along + seg * t;
            if s < 2.0 || !grid.passable(p) {
                continue;
            }
            let bearing = wrap_deg(((p[1] - sy).atan2(p[0] - sx) - yaw).to_degrees());
            if bearing.abs() > 35.0 || s > 9.0 {
                outside.push(p);
            } else {
                fallback.push(p);
            }
        }
        along += seg;
    }
    if outside.is_empty() {
        fallback
    } else {
        outside
    }
}

/// Points outside the person's region, facing one of its sides across a wall (not through a
/// doorway), within reach of the robot's path, nearest to the path first.
fn behind_wall_goals(
    (b, plan): (&Building, &FloorPlan),
    grid: &Grid,
    person: &PlanPerson,
    robot_xy: &[[f64; 2]],
) -> Vec<[f64; 2]> {
    let Some(region) = b.regions.get(person.region) else { return Vec::new() };
    let r = region.rect;
    let p = person.at;
    let clamp = |v: f64, lo: f64, hi: f64| v.clamp(lo + 0.5, (hi - 0.5).max(lo + 0.5));
    let (x, y) = (clamp(p[0], r.min[0], r.max[0]), clamp(p[1], r.min[1], r.max[1]));
    let mut ok: Vec<([f64; 2], (f64, f64))> = FACING_WALL_M
        .iter()
        .flat_map(|&gap| {
            [[x, r.min[1] - gap], [x, r.max[1] + gap], [r.min[0] - gap, y], [r.max[0] + gap, y]].map(|g| (g, gap))
        })
        .filter(|&(g, _)| grid.passable(g) && !r.contains(g) && behind_a_wall(plan, g, p))
        .map(|(g, gap)| (g, (gap, distance_to_polyline(g, robot_xy))))
        .filter(|&(_, (_, reach))| reach <= MAPPED_REACH_M)
        .collect();
    // Nearest the wall first, then nearest the robot's route.
    ok.sort_by(|a, b| a.1 .0.total_cmp(&b.1 .0).then(a.1 .1.total_cmp(&b.1 .1)));
    ok.into_iter().map(|(g, _)| g).collect()
}

/// Whether the sight line from `a` to `c` is blocked by a wall, a closed door or something at
/// least `OCCLUDER_M` tall (loaded racking), and passes no doorway and no window.
fn behind_a_wall(plan: &FloorPlan, a: [f64; 2], c: [f64; 2]) -> bool {
    let gap = |o: &Doorway| distance_to_segment(o.centre, a, c) < o.half_m[0] + 0.3;
    if plan.doorways.iter().chain(&plan.windows).any(gap) {
        return false;
    }
    let blocks = |o: &&Footprint| match o.kind {
        ObstacleKind::Wall | ObstacleKind::ClosedDoor => true,
        ObstacleKind::Furniture => o.top_z_m >= OCCLUDER_M,
    };
    plan.obstacles.iter().filter(blocks).any(|o| segment_points(a, c, 0.05).any(|p| o.distance_m(p) <= 0.0))
}

/// When the robot was nearest to `p` (s), sampled every 0.1 s.
fn time_robot_passed(robot: &RobotMotion, p: [f64; 2]) -> f64 {
    let end = robot.route().end_s();
    let mut best = (0.0, f64::INFINITY);
    let mut t = 0.0;
    while t <= end {
        let s = robot.route().at(t);
        let dist = (s.x - p[0]).hypot(s.y - p[1]);
        if dist < best.1 {
            best = (t, dist);
        }
        t += 0.1;
    }
    best.0
}
