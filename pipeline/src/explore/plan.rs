//! Where to go next and how: the floor the base can use (traversable, kept `robot_radius_m` from
//! anything occupied), travel costs from the robot over it (Dijkstra, 8-connected), and the
//! frontier worth most: its length (what the robot may see past it) against the way there.
//! Goals the robot failed to reach are blacklisted by the caller and left out.

use super::frontier::Frontier;
use super::occupancy::{Cell, OccupancyGrid};
use std::cmp::Ordering;
use std::collections::BinaryHeap;

/// Settings of the goal choice.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlanConfig {
    /// Cells closer than this to an occupied cell are not driven through (the base's half width
    /// and a margin).
    pub robot_radius_m: f64,
    /// A frontier's worth: this many metres of travel per metre of frontier.
    pub gain_m_per_m: f64,
    /// A goal within this of a blacklisted point is left out.
    pub blacklist_radius_m: f64,
}

impl Default for PlanConfig {
    fn default() -> Self {
        Self { robot_radius_m: 0.35, gain_m_per_m: 2.0, blacklist_radius_m: 0.5 }
    }
}

/// The floor usable by the base: traversable and at least `robot_radius_m` from every occupied
/// cell. The robot's own cell and those around it within the radius are usable unless
/// occupied: the floor right under and beside a LiDAR is never seen.
pub fn usable(grid: &OccupancyGrid, robot: (usize, usize), robot_radius_m: f64) -> Vec<bool> {
    let side = grid.side();
    let cell_m = grid.config().cell_m;
    let r = (robot_radius_m / cell_m).ceil() as i64;
    // The cells within the radius of a cell, as offsets.
    let disc: Vec<(i64, i64)> = (-r..=r)
        .flat_map(|dj| (-r..=r).map(move |di| (di, dj)))
        .filter(|&(di, dj)| ((di * di + dj * dj) as f64).sqrt() * cell_m <= robot_radius_m)
        .collect();
    let mut ok: Vec<bool> = (0..side * side).map(|k| grid.traversable((k % side, k / side))).collect();
    let square: Vec<(i64, i64)> = (-r..=r).flat_map(|dj| (-r..=r).map(move |di| (di, dj))).collect();
    for c in around(side, robot, &square).filter(|&c| grid.cell(c) != Cell::Occupied) {
        if let Some(slot) = ok.get_mut(c.1 * side + c.0) {
            *slot = true;
        }
    }
    // Keep the radius from every occupied cell.
    for k in 0..side * side {
        let c = (k % side, k / side);
        if grid.cell(c) != Cell::Occupied {
            continue;
        }
        for (x, y) in around(side, c, &disc) {
            if let Some(slot) = ok.get_mut(y * side + x) {
                *slot = false;
            }
        }
    }
    ok
}

/// The cells at `offsets` from `(i, j)` that lie inside a grid `side` cells a side.
fn around(side: usize, (i, j): (usize, usize), offsets: &[(i64, i64)]) -> impl Iterator<Item = (usize, usize)> + '_ {
    let inside = move |v: i64| (0..side as i64).contains(&v);
    offsets
        .iter()
        .map(move |&(di, dj)| (i as i64 + di, j as i64 + dj))
        .filter(move |&(x, y)| inside(x) && inside(y))
        .map(|(x, y)| (x as usize, y as usize))
}

/// Travel costs (metres) from `start` over the usable cells, and each cell's predecessor on its
/// cheapest way (for [`path_to`]). Unreached cells cost infinity.
pub struct Costs {
    side: usize,
    metres: Vec<f64>,
    from: Vec<usize>,
}

#[derive(PartialEq)]
struct Open(f64, usize);

impl Eq for Open {}

impl PartialOrd for Open {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for Open {
    fn cmp(&self, other: &Self) -> Ordering {
        // A min-heap on cost.
        other.0.total_cmp(&self.0).then(other.1.cmp(&self.1))
    }
}

impl Costs {
    /// Dijkstra from `start` over `usable` (8-connected: a cell or the square root of two).
    pub fn from(grid: &OccupancyGrid, usable: &[bool], start: (usize, usize)) -> Self {
        let side = grid.side();
        let cell_m = grid.config().cell_m;
        let mut metres = vec![f64::INFINITY; side * side];
        let mut from = vec![usize::MAX; side * side];
        let mut open = BinaryHeap::new();
        let s = start.1 * side + start.0;
        if let Some(m) = metres.get_mut(s) {
            *m = 0.0;
            open.push(Open(0.0, s));
        }
        while let Some(Open(cost, k)) = open.pop() {
            if metres.get(k).is_none_or(|&m| cost > m) {
                continue;
            }
            for n in grid.neighbours((k % side, k / side)) {
                let nk = n.1 * side + n.0;
                if !usable.get(nk).copied().unwrap_or(false) {
                    continue;
                }
                let step = if n.0 != k % side && n.1 != k / side { std::f64::consts::SQRT_2 } else { 1.0 };
                let c = cost + step * cell_m;
                if let Some(m) = metres.get_mut(nk).filter(|m| c < **m) {
                    *m = c;
                    if let Some(f) = from.get_mut(nk) {
                        *f = k;
                    }
                    open.push(Open(c, nk));
                }
            }
        }
        Self { side, metres, from }
    }

    /// The cost to a cell (infinity: not reached).
    pub fn to(&self, c: (usize, usize)) -> f64 {
        self.metres.get(c.1 * self.side + c.0).copied().unwrap_or(f64::INFINITY)
    }

    /// The cheapest way from the start to `goal`, start first; empty when it was not reached.
    pub fn path_to(&self, goal: (usize, usize)) -> Vec<(usize, usize)> {
        if !self.to(goal).is_finite() {
            return Vec::new();
        }
        let mut path = Vec::new();
        let mut k = goal.1 * self.side + goal.0;
        // Bounded by the cells: a predecessor chain never repeats.
        for _ in 0..self.metres.len() {
            path.push((k % self.side, k / self.side));
            match self.from.get(k) {
                Some(&p) if p != usize::MAX => k = p,
                _ => break,
            }
        }
        path.reverse();
        path
    }
}

/// The frontier chosen and where to drive: its reachable cell nearest the robot.
#[derive(Clone, Debug, PartialEq)]
pub struct GoalChoice {
    /// Index into the frontiers handed in.
    pub frontier: usize,
    pub goal: (usize, usize),
    pub travel_m: f64,
    pub utility: f64,
}

/// The frontier of greatest utility (`gain_m_per_m` x its length less the travel to it) that
/// can be reached, leaving out goals near a `blacklist` point (world x, y).
pub fn choose_goal(
    grid: &OccupancyGrid,
    frontiers: &[Frontier],
    costs: &Costs,
    blacklist: &[[f64; 2]],
    cfg: &PlanConfig,
) -> Option<GoalChoice> {
    let cell_m = grid.config().cell_m;
    let banned = |c: (usize, usize)| {
        let [x, y] = grid.centre_of(c);
        blacklist.iter().any(|b| (b[0] - x).hypot(b[1] - y) < cfg.blacklist_radius_m)
    };
    frontiers
        .iter()
        .enumerate()
        .filter_map(|(i, f)| {
            let goal = f
                .cells
                .iter()
                .copied()
                .filter(|&c| costs.to(c).is_finite() && !banned(c))
                .min_by(|a, b| costs.to(*a).total_cmp(&costs.to(*b)))?;
            let travel_m = costs.to(goal);
            let utility = cfg.gain_m_per_m * f.length_m(cell_m) - travel_m;
            Some(GoalChoice { frontier: i, goal, travel_m, utility })
        })
        .max_by(|a, b| a.utility.total_cmp(&b.utility))
}

/// Where to look at `target` from, for a LiDAR that sees nothing nearer than `near_m`: the
/// reachable cell (by `costs`) cheapest to get to whose centre lies between `near_m` and
/// `far_m` from `target`'s. `None` when no such cell can be reached.
pub fn viewpoint(
    grid: &OccupancyGrid,
    costs: &Costs,
    target: (usize, usize),
    near_m: f64,
    far_m: f64,
) -> Option<(usize, usize)> {
    let cell_m = grid.config().cell_m;
    let r = (far_m / cell_m).ceil() as i64;
    let square: Vec<(i64, i64)> = (-r..=r).flat_map(|dj| (-r..=r).map(move |di| (di, dj))).collect();
    let [tx, ty] = grid.centre_of(target);
    around(grid.side(), target, &square)
        .filter(|&c| {
            let [x, y] = grid.centre_of(c);
            let d = (x - tx).hypot(y - ty);
            (near_m..=far_m).contains(&d) && costs.to(c).is_finite()
        })
        .min_by(|a, b| costs.to(*a).total_cmp(&costs.to(*b)))
}
