//! Whether a scenario's routes could be driven and walked: no leg of the robot's, the
//! responder's or a walker's route may pass through a wall, a closed door or furniture (a
//! walker on a stage walks on it, not through it). Ground without a floor slab is allowed (the
//! outdoors before a door). Run on every scenario `starc sim` loads, generated or by hand.

use crate::sim::obstacles::{segment_points, FloorPlan};
use crate::sim::scenario::Scenario;

/// How close the robot's or the responder's centre line may come to an obstacle: a body is at
/// least this wide on either side (the robot's base, a person's shoulders turned sideways).
pub const BODY_HALF_WIDTH_M: f64 = 0.12;
/// A walker's path is the centre line of their feet, and a walking person steps around the
/// corner of a box: only a path through an obstacle is refused.
pub const WALKER_HALF_WIDTH_M: f64 = 0.0;
/// Step along a leg when testing it.
const STEP_M: f64 = 0.02;

/// Whose route.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mover {
    Robot,
    Responder,
    Walker,
}

impl Mover {
    /// How close its centre line may come to an obstacle.
    pub fn half_width_m(self) -> f64 {
        match self {
            Mover::Robot | Mover::Responder => BODY_HALF_WIDTH_M,
            Mover::Walker => WALKER_HALF_WIDTH_M,
        }
    }
}

impl std::fmt::Display for Mover {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Mover::Robot => "robot",
            Mover::Responder => "responder",
            Mover::Walker => "walker",
        })
    }
}

/// One leg that runs into something.
#[derive(Clone, Debug, PartialEq)]
pub struct RouteViolation {
    pub mover: Mover,
    /// The walker's name; empty for the robot and the responder.
    pub who: String,
    /// Index of the leg (0 is the first waypoint to the second).
    pub leg: usize,
    /// Where on the leg it happens.
    pub at: [f64; 2],
    /// What it runs into ("wall", "closed door", a furniture name, "no floor").
    pub into: String,
    pub clearance_m: f64,
}

impl std::fmt::Display for RouteViolation {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let who = if self.who.is_empty() { String::new() } else { format!(" {:?}", self.who) };
        write!(
            f,
            "the {}{who}'s leg {} meets {} at ({:.2}, {:.2}) ({:.2} m clearance, more than {:.2} m needed)",
            self.mover,
            self.leg,
            self.into,
            self.at[0],
            self.at[1],
            self.clearance_m,
            self.mover.half_width_m()
        )
    }
}

/// Every leg of every route that meets an obstacle (the first point of each such leg).
pub fn check_routes(s: &Scenario) -> Vec<RouteViolation> {
    let plan = FloorPlan::of(s);
    let mut out = Vec::new();
    let robot: Vec<[f64; 2]> = s.robot.get_ref().waypoints.iter().map(|w| [w[0], w[1]]).collect();
    check_polyline(&plan, &robot, Mover::Robot, "", 0.0, &mut out);
    check_polyline(&plan, &s.responder.get_ref().waypoints, Mover::Responder, "", 0.0, &mut out);
    for p in &s.people {
        let p = p.get_ref();
        if p.path.is_empty() {
            continue;
        }
        let mut line = vec![p.at];
        line.extend(p.path.iter().copied());
        check_polyline(&plan, &line, Mover::Walker, &p.name, p.base_z_m, &mut out);
    }
    out
}

/// Checks each leg of `points`, for a mover whose feet are at `base_z_m` (what is no higher
/// than that is walked on).
fn check_polyline(
    plan: &FloorPlan,
    points: &[[f64; 2]],
    mover: Mover,
    who: &str,
    base_z_m: f64,
    out: &mut Vec<RouteViolation>,
) {
    let mut legs: Vec<(usize, [f64; 2], [f64; 2])> =
        points.windows(2).enumerate().map(|(i, pair)| (i, pair[0], pair[1])).collect();
    if let [only] = points {
        legs.push((0, *only, *only));
    }
    for (leg, a, b) in legs {
        if let Some((at, into, clearance_m)) = first_contact(plan, a, b, mover.half_width_m(), base_z_m) {
            out.push(RouteViolation { mover, who: who.into(), leg, at, into, clearance_m });
        }
    }
}

/// The first point from `a` to `b` within `half_width_m` of an obstacle that stands higher
/// than `base_z_m`.
fn first_contact(
    plan: &FloorPlan,
    a: [f64; 2],
    b: [f64; 2],
    half_width_m: f64,
    base_z_m: f64,
) -> Option<([f64; 2], String, f64)> {
    segment_points(a, b, STEP_M).find_map(|p| match plan.nearest_above(p, base_z_m) {
        Some((o, d)) if d <= half_width_m => Some((p, o.name.clone(), d)),
        _ => None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::scenario::SHIPPED;

    #[test]
    fn shipped_routes_are_clear() {
        for (name, text) in SHIPPED {
            let s = Scenario::parse(text, name);
            let s = match s {
                Ok(s) => s,
                Err(e) => panic!("{name}: {e}"),
            };
            let v = check_routes(&s);
            assert!(v.is_empty(), "{name}: {}", v.iter().map(|v| v.to_string()).collect::<Vec<_>>().join("; "));
        }
    }

    const ROOM: &str = r#"
name = "t"
[[floors]]
min = [-1, -1]
max = [11, 6]
[[walls]]
from = [5, -1]
to = [5, 6]
doors = [{ at_m = 1.5, state = "open" }, { at_m = 5.0, state = "closed" }]
[[boxes]]
name = "table"
at = [2, 4]
size_m = [1.0, 1.0, 0.75]
"#;

    fn violations(routes: &str) -> Vec<RouteViolation> {
        match Scenario::parse(&format!("{ROOM}{routes}"), "t") {
            Ok(s) => check_routes(&s),
            Err(e) => panic!("{e}"),
        }
    }

    #[test]
    fn open_doors_pass_walls_closed_doors_and_furniture_do_not() {
        let through_open = "[robot]\nwaypoints = [[1, 0.5, 0], [9, 0.5, 0]]\n[responder]\nwaypoints = [[1, 2]]\n";
        assert!(violations(through_open).is_empty(), "{:?}", violations(through_open));
        let through_wall = "[robot]\nwaypoints = [[1, 2.5, 0], [9, 2.5, 0]]\n[responder]\nwaypoints = [[1, 2]]\n";
        let v = violations(through_wall);
        assert!(v.len() == 1 && v[0].into == "wall" && v[0].mover == Mover::Robot, "{v:?}");
        let closed = "[robot]\nwaypoints = [[1, 0.5, 0]]\n[responder]\nwaypoints = [[1, 4], [9, 4]]\n";
        let v = violations(closed);
        assert!(v.len() == 1 && v[0].into == "table" && v[0].mover == Mover::Responder, "{v:?}");
        let door = "[robot]\nwaypoints = [[1, 0.5, 0]]\n[responder]\nwaypoints = [[3, 4], [9, 4]]\n";
        let v = violations(door);
        assert!(v.len() == 1 && v[0].into == "closed door", "{v:?}");
        let outdoors = "[robot]\nwaypoints = [[1, 0.5, 0], [1, 8, 0]]\n[responder]\nwaypoints = [[1, 2]]\n";
        assert!(violations(outdoors).is_empty(), "{:?}", violations(outdoors));
    }

    #[test]
    fn a_walker_on_a_stage_walks_on_it() {
        let on = "[[people]]\nname = \"w\"\nat = [1.5, 4]\nbase_z_m = 0.75\npath = [[2.5, 4]]\n[robot]\nwaypoints = [[1, 0.5, 0]]\n[responder]\nwaypoints = [[1, 2]]\n";
        assert!(violations(on).is_empty(), "{:?}", violations(on));
        let below = on.replace("base_z_m = 0.75", "base_z_m = 0.5");
        assert_eq!(violations(&below).len(), 1);
    }

    #[test]
    fn walkers_are_checked_too() {
        let routes = "[[people]]\nname = \"w\"\nat = [1, 4]\npath = [[4, 4]]\n[robot]\nwaypoints = [[1, 0.5, 0]]\n[responder]\nwaypoints = [[1, 2]]\n";
        let v = violations(routes);
        assert!(v.len() == 1 && v[0].mover == Mover::Walker && v[0].who == "w", "{v:?}");
        assert!(v[0].to_string().contains("walker \"w\"'s leg 0 meets table"), "{}", v[0]);
    }
}
