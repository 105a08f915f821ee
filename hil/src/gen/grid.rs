//! An occupancy grid of a floor plan, each free cell with its clearance to the nearest obstacle,
//! and A* over it: the routes a robot and a responder could really take.

use crate::sim::obstacles::{segment_points, FloorPlan};
use std::cmp::Ordering;
use std::collections::BinaryHeap;

/// Cell size.
pub const CELL_M: f64 = 0.05;
/// Clearance asked of a route everywhere but in doorways: the body's half width (0.25 m for
/// the robot's base) plus 0.3 m of margin to walls and furniture.
pub const ROUTE_CLEARANCE_M: f64 = 0.55;
/// In a doorway the route keeps this much from the jambs (a 0.8 m door leaves 0.4 m).
pub const DOORWAY_CLEARANCE_M: f64 = 0.3;
/// How far on either side of a wall a doorway's relaxed clearance reaches.
const DOORWAY_REACH_M: f64 = 0.8;

/// The grid: clearance per cell (0 on obstacles and off the floor), and where doorways relax it.
#[derive(Clone, Debug)]
pub struct Grid {
    pub origin: [f64; 2],
    pub width: usize,
    pub height: usize,
    clearance_m: Vec<f32>,
    in_doorway: Vec<bool>,
}

impl Grid {
    /// Rasterises `plan` over its floors.
    pub fn of(plan: &FloorPlan) -> Self {
        let (lo, hi) = plan.floors.iter().fold(([f64::MAX; 2], [f64::MIN; 2]), |(lo, hi), (a, b)| {
            ([lo[0].min(a[0]), lo[1].min(a[1])], [hi[0].max(b[0]), hi[1].max(b[1])])
        });
        // A border of cells off the floor: its edge is an obstacle like any other.
        let (lo, hi) = ([lo[0] - CELL_M, lo[1] - CELL_M], [hi[0] + CELL_M, hi[1] + CELL_M]);
        let width = (((hi[0] - lo[0]) / CELL_M).ceil().max(1.0) as usize).min(4000);
        let height = (((hi[1] - lo[1]) / CELL_M).ceil().max(1.0) as usize).min(4000);
        let mut grid =
            Grid { origin: lo, width, height, clearance_m: Vec::new(), in_doorway: vec![false; width * height] };
        let mut blocked = vec![false; width * height];
        for (i, cell) in blocked.iter_mut().enumerate() {
            *cell = !plan.on_floor(grid.centre(i));
        }
        for o in &plan.obstacles {
            let (a, b) = o.bounds();
            grid.for_cells_in(a, b, |g, i| {
                if o.distance_m(g.centre(i)) <= CELL_M * 0.5 {
                    blocked[i] = true;
                }
            });
        }
        for d in &plan.doorways {
            let reach = crate::sim::obstacles::Footprint {
                centre: d.centre,
                half_m: [d.half_m[0], d.half_m[1] + DOORWAY_REACH_M],
                yaw_rad: d.yaw_rad,
                kind: crate::sim::obstacles::ObstacleKind::Wall,
                name: String::new(),
                top_z_m: 0.0,
            };
            let (a, b) = reach.bounds();
            grid.for_cells_in(a, b, |g, i| {
                if reach.distance_m(g.centre(i)) <= 0.0 {
                    g.in_doorway[i] = true;
                }
            });
        }
        grid.clearance_m = distance_transform(&blocked, width, height);
        grid
    }

    fn centre(&self, i: usize) -> [f64; 2] {
        let (x, y) = (i % self.width, i / self.width);
        [self.origin[0] + (x as f64 + 0.5) * CELL_M, self.origin[1] + (y as f64 + 0.5) * CELL_M]
    }

    fn index(&self, p: [f64; 2]) -> Option<usize> {
        let x = ((p[0] - self.origin[0]) / CELL_M).floor();
        let y = ((p[1] - self.origin[1]) / CELL_M).floor();
        if x < 0.0 || y < 0.0 || x >= self.width as f64 || y >= self.height as f64 {
            return None;
        }
        Some(y as usize * self.width + x as usize)
    }

    fn for_cells_in(&mut self, a: [f64; 2], b: [f64; 2], mut f: impl FnMut(&mut Self, usize)) {
        let to_cell = |v: f64, o: f64, n: usize| (((v - o) / CELL_M).floor().max(0.0) as usize).min(n - 1);
        let (x0, x1) = (to_cell(a[0], self.origin[0], self.width), to_cell(b[0], self.origin[0], self.width));
        let (y0, y1) = (to_cell(a[1], self.origin[1], self.height), to_cell(b[1], self.origin[1], self.height));
        for y in y0..=y1 {
            for x in x0..=x1 {
                f(self, y * self.width + x);
            }
        }
    }

    /// Clearance at a point (0 off the grid).
    pub fn clearance_m(&self, p: [f64; 2]) -> f64 {
        self.index(p).and_then(|i| self.clearance_m.get(i)).map_or(0.0, |&c| f64::from(c))
    }

    /// Whether a route may pass here: `ROUTE_CLEARANCE_M`, or less in a doorway.
    pub fn passable(&self, p: [f64; 2]) -> bool {
        self.index(p).is_some_and(|i| self.passable_cell(i))
    }

    fn passable_cell(&self, i: usize) -> bool {
        let need = if self.in_doorway[i] { DOORWAY_CLEARANCE_M } else { ROUTE_CLEARANCE_M };
        self.clearance_m.get(i).is_some_and(|&c| f64::from(c) >= need)
    }

    /// Whether the straight line from `a` to `b` is passable all along.
    pub fn line_passable(&self, a: [f64; 2], b: [f64; 2]) -> bool {
        segment_points(a, b, CELL_M * 0.5).all(|p| self.passable(p))
    }

    /// The shortest passable path from `a` to `b` (cell centres, then shortened to the corners
    /// that matter), or none. Cells near obstacles cost more, so paths keep to the middle.
    pub fn path(&self, a: [f64; 2], b: [f64; 2]) -> Option<Vec<[f64; 2]>> {
        let (start, goal) = (self.index(a)?, self.index(b)?);
        if !self.passable_cell(start) || !self.passable_cell(goal) {
            return None;
        }
        let cells = self.astar(start, goal)?;
        let mut points: Vec<[f64; 2]> = cells.iter().map(|&i| self.centre(i)).collect();
        if let Some(first) = points.first_mut() {
            *first = a;
        }
        if let Some(last) = points.last_mut() {
            *last = b;
        }
        Some(self.shorten(&points))
    }

    fn astar(&self, start: usize, goal: usize) -> Option<Vec<usize>> {
        let n = self.width * self.height;
        let mut cost = vec![f64::INFINITY; n];
        let mut from = vec![usize::MAX; n];
        let mut open = BinaryHeap::new();
        let target = self.centre(goal);
        let h = |i: usize| {
            let c = self.centre(i);
            (c[0] - target[0]).hypot(c[1] - target[1])
        };
        cost[start] = 0.0;
        open.push(Open { f: h(start), cell: start });
        while let Some(Open { cell, .. }) = open.pop() {
            if cell == goal {
                return Some(walk_back(&from, start, goal));
            }
            for (next, step_m) in self.neighbours(cell) {
                let c = cost[cell] + step_m * self.crowding(next);
                if c < cost[next] {
                    cost[next] = c;
                    from[next] = cell;
                    open.push(Open { f: c + h(next), cell: next });
                }
            }
        }
        None
    }

    /// 1 in the open (0.9 m or more of clearance), rising to 3 at the doorway clearance: a path
    /// keeps to the middle of a corridor.
    fn crowding(&self, i: usize) -> f64 {
        let c = self.clearance_m.get(i).map_or(0.0, |&c| f64::from(c));
        1.0 + 2.0 * (1.0 - ((c - DOORWAY_CLEARANCE_M) / 0.6).clamp(0.0, 1.0))
    }

    fn neighbours(&self, i: usize) -> impl Iterator<Item = (usize, f64)> + '_ {
        let (x, y) = ((i % self.width) as i64, (i / self.width) as i64);
        const STEPS: [(i64, i64); 8] = [(1, 0), (-1, 0), (0, 1), (0, -1), (1, 1), (1, -1), (-1, 1), (-1, -1)];
        STEPS.iter().filter_map(move |&(dx, dy)| {
            let (nx, ny) = (x + dx, y + dy);
            if nx < 0 || ny < 0 || nx >= self.width as i64 || ny >= self.height as i64 {
                return None;
            }
            let j = ny as usize * self.width + nx as usize;
            self.passable_cell(j).then_some((j, CELL_M * ((dx * dx + dy * dy) as f64).sqrt()))
        })
    }

    /// Drops every point that a straight passable line can skip.
    fn shorten(&self, points: &[[f64; 2]]) -> Vec<[f64; 2]> {
        let mut out = Vec::new();
        let mut i = 0;
        while let Some(&p) = points.get(i) {
            out.push(p);
            let reach = (i + 1..points.len()).rev().find(|&j| self.line_passable(p, points[j]));
            i = reach.unwrap_or(i + 1);
        }
        out
    }
}

fn walk_back(from: &[usize], start: usize, goal: usize) -> Vec<usize> {
    let mut cells = vec![goal];
    let mut at = goal;
    while at != start {
        at = from[at];
        cells.push(at);
    }
    cells.reverse();
    cells
}

#[derive(PartialEq)]
struct Open {
    f: f64,
    cell: usize,
}

impl Eq for Open {}

impl Ord for Open {
    fn cmp(&self, other: &Self) -> Ordering {
        other.f.total_cmp(&self.f).then(other.cell.cmp(&self.cell))
    }
}

impl PartialOrd for Open {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

/// Distance from each cell to the nearest blocked cell (metres), by propagating each cell's
/// nearest blocked cell to its neighbours until nothing changes (8SSEDT-like, two sweeps).
fn distance_transform(blocked: &[bool], w: usize, h: usize) -> Vec<f32> {
    const FAR: (i32, i32) = (1 << 14, 1 << 14);
    let mut near: Vec<(i32, i32)> = blocked.iter().map(|&b| if b { (0, 0) } else { FAR }).collect();
    let d2 = |v: (i32, i32)| i64::from(v.0) * i64::from(v.0) + i64::from(v.1) * i64::from(v.1);
    let relax = |near: &mut Vec<(i32, i32)>, x: usize, y: usize, dx: i32, dy: i32| {
        let (nx, ny) = (x as i32 + dx, y as i32 + dy);
        if nx < 0 || ny < 0 || nx >= w as i32 || ny >= h as i32 {
            return;
        }
        let other = near[ny as usize * w + nx as usize];
        let cand = (other.0 + dx, other.1 + dy);
        let i = y * w + x;
        if d2(cand) < d2(near[i]) {
            near[i] = cand;
        }
    };
    for y in 0..h {
        for x in 0..w {
            for (dx, dy) in [(-1, 0), (0, -1), (-1, -1), (1, -1)] {
                relax(&mut near, x, y, dx, dy);
            }
        }
        for x in (0..w).rev() {
            relax(&mut near, x, y, 1, 0);
        }
    }
    for y in (0..h).rev() {
        for x in (0..w).rev() {
            for (dx, dy) in [(1, 0), (0, 1), (1, 1), (-1, 1)] {
                relax(&mut near, x, y, dx, dy);
            }
        }
        for x in 0..w {
            relax(&mut near, x, y, -1, 0);
        }
    }
    near.iter().map(|&v| ((d2(v) as f64).sqrt() * CELL_M) as f32).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::obstacles::{Doorway, Footprint, ObstacleKind};

    fn wall(centre: [f64; 2], half_m: [f64; 2]) -> Footprint {
        Footprint { centre, half_m, yaw_rad: 0.0, kind: ObstacleKind::Wall, name: "wall".into(), top_z_m: 2.5 }
    }

    /// Two rooms split by a wall at x = 5 with a 0.9 m doorway at y = 1.
    fn two_rooms() -> FloorPlan {
        FloorPlan {
            obstacles: vec![wall([5.0, -0.475], [0.06, 1.025]), wall([5.0, 3.725], [0.06, 2.275])],
            doorways: vec![Doorway { centre: [5.0, 1.0], half_m: [0.45, 0.06], yaw_rad: std::f64::consts::FRAC_PI_2 }],
            windows: Vec::new(),
            floors: vec![([0.0, -1.5], [10.0, 6.0])],
        }
    }

    #[test]
    fn clearance_is_the_distance_to_the_nearest_obstacle() {
        let g = Grid::of(&two_rooms());
        assert!((g.clearance_m([3.0, 4.0]) - 1.94).abs() < 0.06, "{}", g.clearance_m([3.0, 4.0]));
        assert!((g.clearance_m([1.0, 3.0]) - 1.0).abs() < 0.06, "{}", g.clearance_m([1.0, 3.0]));
        assert_eq!(g.clearance_m([5.0, 4.0]), 0.0);
    }

    #[test]
    fn paths_go_through_the_doorway_and_keep_clear() {
        let g = Grid::of(&two_rooms());
        let path = g.path([2.0, 4.0], [8.0, 4.0]);
        let Some(path) = path else { panic!("no path") };
        assert!(path.len() >= 3, "{path:?}");
        let through = path.windows(2).any(|p| (p[0][0] - 5.0) * (p[1][0] - 5.0) <= 0.0 && (p[0][1] - 1.0).abs() < 0.5);
        assert!(through, "{path:?}");
        for pair in path.windows(2) {
            assert!(g.line_passable(pair[0], pair[1]));
        }
        // Into a wall: none.
        assert!(g.path([2.0, 4.0], [5.0, 4.0]).is_none());
    }

    #[test]
    fn a_closed_plan_has_no_path() {
        let mut plan = two_rooms();
        plan.doorways.clear();
        plan.obstacles.push(wall([5.0, 1.0], [0.06, 0.45]));
        assert!(Grid::of(&plan).path([2.0, 4.0], [8.0, 4.0]).is_none());
    }
}
