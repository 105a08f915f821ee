//! What blocks a robot or a walking person on the floor plan: each wall piece, closed door,
//! furniture item and clutter box as an oriented rectangle on the floor, with the open doorways
//! beside them. The route planner (`gen::grid`) and the route check ([`check_routes`]) both read
//! the plan from here, so a generated route and a hand-written one are judged alike.

use crate::sim::scenario::{DoorState, Scenario, Wall};

/// Anything whose bottom is at or above this height does not block the floor (a shelf on a wall,
/// a beam): a responder of 1.95 m and the robot pass under it.
const PASSABLE_ABOVE_M: f64 = 2.0;
/// A window whose sill is lower than this is a gap one could step through; above it, the wall
/// below the window blocks.
const STEP_THROUGH_SILL_M: f64 = 0.05;

/// Someone standing this little below an obstacle's top stands on it (a stage's boards).
const WALKED_ON_M: f64 = 0.05;

/// What an obstacle is, for messages.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ObstacleKind {
    Wall,
    ClosedDoor,
    Furniture,
}

/// An oriented rectangle on the floor.
#[derive(Clone, Debug, PartialEq)]
pub struct Footprint {
    pub centre: [f64; 2],
    pub half_m: [f64; 2],
    pub yaw_rad: f64,
    pub kind: ObstacleKind,
    /// The item's name or kind, for messages.
    pub name: String,
    /// Its top above the floor: someone standing higher (on a stage) walks over it.
    pub top_z_m: f64,
}

/// Distance from `p` to a rectangle of half sizes `half_m` turned by `yaw_rad` about `centre`
/// (0 inside).
pub fn rect_distance_m(centre: [f64; 2], half_m: [f64; 2], yaw_rad: f64, p: [f64; 2]) -> f64 {
    let (s, c) = yaw_rad.sin_cos();
    let (dx, dy) = (p[0] - centre[0], p[1] - centre[1]);
    let (lx, ly) = (c * dx + s * dy, -s * dx + c * dy);
    let ox = (lx.abs() - half_m[0]).max(0.0);
    let oy = (ly.abs() - half_m[1]).max(0.0);
    ox.hypot(oy)
}

/// Points from `a` to `b`, both included, at most `step_m` apart (at most a million: a
/// non-finite or absurd leg is sampled coarsely rather than forever).
pub fn segment_points(a: [f64; 2], b: [f64; 2], step_m: f64) -> impl Iterator<Item = [f64; 2]> {
    const MOST: f64 = 1e6;
    let n = ((b[0] - a[0]).hypot(b[1] - a[1]) / step_m).ceil().clamp(1.0, MOST) as usize;
    (0..=n).map(move |k| {
        let t = k as f64 / n as f64;
        [a[0] + (b[0] - a[0]) * t, a[1] + (b[1] - a[1]) * t]
    })
}

/// Distance from `p` to the segment from `a` to `b`.
pub fn distance_to_segment(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let len2 = dx * dx + dy * dy;
    let t = if len2 > 0.0 { (((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / len2).clamp(0.0, 1.0) } else { 0.0 };
    (p[0] - a[0] - t * dx).hypot(p[1] - a[1] - t * dy)
}

/// Distance from `p` to a polyline (to its one point when it has one; infinite when empty).
pub fn distance_to_polyline(p: [f64; 2], line: &[[f64; 2]]) -> f64 {
    match line {
        [] => f64::INFINITY,
        [only] => (p[0] - only[0]).hypot(p[1] - only[1]),
        _ => line.windows(2).map(|w| distance_to_segment(p, w[0], w[1])).fold(f64::INFINITY, f64::min),
    }
}

impl Footprint {
    /// Distance from a point to the rectangle (0 inside).
    pub fn distance_m(&self, p: [f64; 2]) -> f64 {
        rect_distance_m(self.centre, self.half_m, self.yaw_rad, p)
    }

    /// The axis-aligned bounds (min, max) of the rectangle.
    pub fn bounds(&self) -> ([f64; 2], [f64; 2]) {
        let (s, c) = self.yaw_rad.sin_cos();
        let ex = (self.half_m[0] * c).abs() + (self.half_m[1] * s).abs();
        let ey = (self.half_m[0] * s).abs() + (self.half_m[1] * c).abs();
        ([self.centre[0] - ex, self.centre[1] - ey], [self.centre[0] + ex, self.centre[1] + ey])
    }
}

/// An open doorway: the gap in its wall, as a rectangle across the wall.
#[derive(Clone, Debug, PartialEq)]
pub struct Doorway {
    pub centre: [f64; 2],
    /// Half the door's width (along the wall) and half the wall's thickness.
    pub half_m: [f64; 2],
    pub yaw_rad: f64,
}

/// The floor plan's obstacles and doorways.
#[derive(Clone, Debug, Default)]
pub struct FloorPlan {
    pub obstacles: Vec<Footprint>,
    pub doorways: Vec<Doorway>,
    /// Windows above the floor: gaps one sees through but cannot walk through.
    pub windows: Vec<Doorway>,
    /// The floors' rectangles (min, max): outside them there is no floor.
    pub floors: Vec<([f64; 2], [f64; 2])>,
}

impl FloorPlan {
    pub fn of(s: &Scenario) -> Self {
        let mut plan = FloorPlan::default();
        for f in &s.floors {
            let f = f.get_ref();
            plan.floors.push((f.min, f.max));
        }
        for w in &s.walls {
            add_wall(&mut plan, w.get_ref());
        }
        for b in &s.boxes {
            let b = b.get_ref();
            for i in 0..b.count {
                let k = f64::from(i);
                if b.base_z_m + k * b.step_m[2] >= PASSABLE_ABOVE_M {
                    continue;
                }
                plan.obstacles.push(Footprint {
                    centre: [b.at[0] + k * b.step_m[0], b.at[1] + k * b.step_m[1]],
                    half_m: [b.size_m[0] / 2.0, b.size_m[1] / 2.0],
                    yaw_rad: b.yaw_deg.to_radians(),
                    kind: ObstacleKind::Furniture,
                    name: if b.name.is_empty() { "box".into() } else { b.name.clone() },
                    top_z_m: b.base_z_m + k * b.step_m[2] + b.size_m[2],
                });
            }
        }
        for item in crate::sim::clutter::placed(s) {
            plan.obstacles.push(Footprint {
                centre: item.centre,
                half_m: [item.size_m[0] / 2.0, item.size_m[1] / 2.0],
                yaw_rad: item.yaw_rad,
                kind: ObstacleKind::Furniture,
                name: "clutter".into(),
                top_z_m: item.size_m[2],
            });
        }
        for f in &s.furniture {
            let f = f.get_ref();
            if f.base_z_m >= PASSABLE_ABOVE_M {
                continue;
            }
            let (centre, half_m, yaw_rad) = f.footprint();
            let top_z_m = f.base_z_m + f.size_m()[2];
            plan.obstacles.push(Footprint {
                centre,
                half_m,
                yaw_rad,
                kind: ObstacleKind::Furniture,
                name: f.label(),
                top_z_m,
            });
        }
        plan
    }

    /// Whether a point stands on some floor.
    pub fn on_floor(&self, p: [f64; 2]) -> bool {
        self.floors.iter().any(|(lo, hi)| p[0] >= lo[0] && p[0] <= hi[0] && p[1] >= lo[1] && p[1] <= hi[1])
    }

    /// The nearest obstacle to a point that stands higher than `base_z_m`, and its distance.
    pub fn nearest_above(&self, p: [f64; 2], base_z_m: f64) -> Option<(&Footprint, f64)> {
        self.obstacles
            .iter()
            .filter(|o| o.top_z_m > base_z_m + WALKED_ON_M)
            .map(|o| (o, o.distance_m(p)))
            .min_by(|a, b| a.1.total_cmp(&b.1))
    }
}

/// A wall's solid pieces at floor level (closed doors included) and its open doorways.
fn add_wall(plan: &mut FloorPlan, w: &Wall) {
    let (dx, dy) = (w.to[0] - w.from[0], w.to[1] - w.from[1]);
    let len = dx.hypot(dy);
    if len <= 0.0 || w.base_z_m >= PASSABLE_ABOVE_M {
        return;
    }
    let yaw_rad = dy.atan2(dx);
    let (ux, uy) = (dx / len, dy / len);
    let at = |s: f64| [w.from[0] + ux * s, w.from[1] + uy * s];
    let half_t = w.thickness_m / 2.0;
    let top = w.base_z_m + w.height_m;
    // Gaps at floor level along the wall: open doors, and windows down to the floor.
    let mut gaps: Vec<(f64, f64, bool)> = Vec::new();
    for d in &w.doors {
        let (a, b) = (d.at_m - d.width_m / 2.0, d.at_m + d.width_m / 2.0);
        let open = d.state == DoorState::Open;
        gaps.push((a, b, open));
        if open {
            plan.doorways.push(Doorway { centre: at(d.at_m), half_m: [d.width_m / 2.0, half_t], yaw_rad });
        } else {
            plan.obstacles.push(piece(at, (a, b), half_t, yaw_rad, ObstacleKind::ClosedDoor, top));
        }
    }
    for o in &w.windows {
        if o.sill_m < STEP_THROUGH_SILL_M {
            gaps.push((o.at_m - o.width_m / 2.0, o.at_m + o.width_m / 2.0, true));
        } else {
            plan.windows.push(Doorway { centre: at(o.at_m), half_m: [o.width_m / 2.0, half_t], yaw_rad });
        }
    }
    gaps.sort_by(|p, q| p.0.total_cmp(&q.0));
    let mut s0 = 0.0;
    for (a, b, _) in gaps {
        if a > s0 {
            plan.obstacles.push(piece(at, (s0, a), half_t, yaw_rad, ObstacleKind::Wall, top));
        }
        s0 = s0.max(b);
    }
    if len > s0 {
        plan.obstacles.push(piece(at, (s0, len), half_t, yaw_rad, ObstacleKind::Wall, top));
    }
}

fn piece(
    at: impl Fn(f64) -> [f64; 2],
    (s0, s1): (f64, f64),
    half_t: f64,
    yaw_rad: f64,
    kind: ObstacleKind,
    top_z_m: f64,
) -> Footprint {
    let name = match kind {
        ObstacleKind::Wall => "wall",
        ObstacleKind::ClosedDoor => "closed door",
        ObstacleKind::Furniture => "furniture",
    };
    Footprint {
        centre: at((s0 + s1) / 2.0),
        half_m: [(s1 - s0) / 2.0, half_t],
        yaw_rad,
        kind,
        name: name.into(),
        top_z_m,
    }
}
