//! A scenario's floor plan as an SVG picture, top down: walls, closed doors and furniture as
//! they block the floor, people (by pose, walkers with their walk), the robot's route (blue)
//! and the responder's (orange). `starc gen --svg` and `starc eval` write one per building.

use crate::sim::obstacles::{FloorPlan, Footprint, ObstacleKind};
use crate::sim::scenario::{PoseKind, Scenario};
use std::fmt::Write as _;

/// Pixels per metre.
const SCALE: f64 = 30.0;
const MARGIN_PX: f64 = 20.0;

/// The picture's SVG text.
pub fn plan_svg(s: &Scenario) -> String {
    let plan = FloorPlan::of(s);
    let (lo, hi) = bounds(&plan);
    let w = (hi[0] - lo[0]) * SCALE + 2.0 * MARGIN_PX;
    let h = (hi[1] - lo[1]) * SCALE + 2.0 * MARGIN_PX + 20.0;
    // World y points up, SVG y down.
    let px = |p: [f64; 2]| ((p[0] - lo[0]) * SCALE + MARGIN_PX, (hi[1] - p[1]) * SCALE + MARGIN_PX + 20.0);
    let mut out = String::new();
    let _ = write!(out, "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{w:.0}\" height=\"{h:.0}\" font-family=\"sans-serif\" font-size=\"11\">");
    let _ = write!(out, "<rect width=\"100%\" height=\"100%\" fill=\"white\"/><text x=\"{MARGIN_PX}\" y=\"15\">{} (1 m = {SCALE} px)</text>", escape(&s.name));
    for (a, b) in &plan.floors {
        let (x0, y1) = px(*a);
        let (x1, y0) = px(*b);
        let _ = write!(
            out,
            "<rect x=\"{x0:.1}\" y=\"{y0:.1}\" width=\"{:.1}\" height=\"{:.1}\" fill=\"#f4f4f4\"/>",
            x1 - x0,
            y1 - y0
        );
    }
    for o in &plan.obstacles {
        polygon(&mut out, o, &px);
    }
    people(&mut out, s, &px);
    let robot: Vec<[f64; 2]> = s.robot.get_ref().waypoints.iter().map(|w| [w[0], w[1]]).collect();
    polyline(&mut out, &robot, "#1f5fd6", &px);
    polyline(&mut out, &s.responder.get_ref().waypoints, "#ff7f0e", &px);
    out.push_str("</svg>\n");
    out
}

fn bounds(plan: &FloorPlan) -> ([f64; 2], [f64; 2]) {
    let mut lo = [f64::INFINITY; 2];
    let mut hi = [f64::NEG_INFINITY; 2];
    let corners = plan.floors.iter().flat_map(|(a, b)| [*a, *b]).chain(plan.obstacles.iter().flat_map(|o| {
        let (a, b) = o.bounds();
        [a, b]
    }));
    for p in corners {
        lo = [lo[0].min(p[0]), lo[1].min(p[1])];
        hi = [hi[0].max(p[0]), hi[1].max(p[1])];
    }
    if !(lo[0].is_finite() && hi[0].is_finite()) {
        return ([0.0, 0.0], [1.0, 1.0]);
    }
    (lo, hi)
}

fn polygon(out: &mut String, o: &Footprint, px: &impl Fn([f64; 2]) -> (f64, f64)) {
    let (s, c) = o.yaw_rad.sin_cos();
    let corners = [[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]].map(|[u, v]: [f64; 2]| {
        let (lx, ly) = (u * o.half_m[0], v * o.half_m[1]);
        px([o.centre[0] + c * lx - s * ly, o.centre[1] + s * lx + c * ly])
    });
    let points: Vec<String> = corners.iter().map(|(x, y)| format!("{x:.1},{y:.1}")).collect();
    let fill = match o.kind {
        ObstacleKind::Wall => "#333333",
        ObstacleKind::ClosedDoor => "#b5651d",
        ObstacleKind::Furniture => "#9aa7b0",
    };
    let _ = write!(
        out,
        "<polygon points=\"{}\" fill=\"{fill}\"><title>{}</title></polygon>",
        points.join(" "),
        escape(&o.name)
    );
}

fn people(out: &mut String, s: &Scenario, px: &impl Fn([f64; 2]) -> (f64, f64)) {
    for p in &s.people {
        let p = p.get_ref();
        let (x, y) = px(p.at);
        let colour = match p.pose {
            PoseKind::Standing => "#d62728",
            PoseKind::Sitting => "#e377c2",
            PoseKind::Crouching => "#8c564b",
            PoseKind::Lying => "#9467bd",
        };
        if !p.path.is_empty() {
            let walk: Vec<[f64; 2]> = std::iter::once(p.at).chain(p.path.iter().copied()).collect();
            polyline(out, &walk, "#d62728", px);
        }
        let _ = write!(
            out,
            "<circle cx=\"{x:.1}\" cy=\"{y:.1}\" r=\"5\" fill=\"{colour}\"><title>{} ({:?}, {:.2} m)</title></circle>",
            escape(&p.name),
            p.pose,
            p.height_m
        );
    }
}

fn polyline(out: &mut String, points: &[[f64; 2]], colour: &str, px: &impl Fn([f64; 2]) -> (f64, f64)) {
    let pts: Vec<String> = points.iter().map(|&p| px(p)).map(|(x, y)| format!("{x:.1},{y:.1}")).collect();
    let _ =
        write!(out, "<polyline points=\"{}\" fill=\"none\" stroke=\"{colour}\" stroke-width=\"2\"/>", pts.join(" "));
    if let Some(&first) = points.first() {
        let (x, y) = px(first);
        let _ =
            write!(out, "<rect x=\"{:.1}\" y=\"{:.1}\" width=\"8\" height=\"8\" fill=\"{colour}\"/>", x - 4.0, y - 4.0);
    }
}

fn escape(s: &str) -> String {
    s.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::scenario::SHIPPED;

    #[test]
    fn a_shipped_plan_draws_its_walls_people_and_routes() {
        let Some((name, text)) = SHIPPED.first() else { panic!("no shipped scenario") };
        let s = match Scenario::parse(text, name) {
            Ok(s) => s,
            Err(e) => panic!("{e}"),
        };
        let svg = plan_svg(&s);
        assert!(svg.starts_with("<svg") && svg.ends_with("</svg>\n"));
        assert_eq!(svg.matches("<circle").count(), s.people.len());
        assert_eq!(
            svg.matches("<polyline").count(),
            2 + s.people.iter().filter(|p| !p.get_ref().path.is_empty()).count()
        );
        assert!(svg.matches("#333333").count() >= s.walls.len());
    }
}
