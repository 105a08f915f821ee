//! Frontiers: where the known, traversable floor meets the unknown, grouped into clusters the
//! robot can drive to. A frontier cell is traversable with unknown space a free cell or two
//! away (4-connected; [`is_frontier`]); frontier cells touching (8-connected) are one frontier.
//! Clusters smaller than `min_cells` (a gap between two returns, a cell behind a chair leg) are
//! left out.

use super::occupancy::{Cell, OccupancyGrid};
use std::collections::VecDeque;

/// One frontier: its cells, their mean (world x, y), and the cell of the frontier nearest that
/// mean, where the robot should go to look past it.
#[derive(Clone, Debug, PartialEq)]
pub struct Frontier {
    pub cells: Vec<(usize, usize)>,
    pub centroid_m: [f64; 2],
    pub goal: (usize, usize),
}

impl Frontier {
    /// The frontier's length, metres (cells times the cell size).
    pub fn length_m(&self, cell_m: f64) -> f64 {
        self.cells.len() as f64 * cell_m
    }
}

/// How many steps (4-connected) through free cells unknown space may lie from a frontier cell.
/// The edge of what the LiDAR saw is often a band of cells its rays crossed without a floor
/// return landing in them (free, but not known as floor): far floor is hit sparsely, and the
/// view's side edges graze it. Looking one cell past that band finds the unknown behind it;
/// walls (occupied) and the free cells beside them are never looked through.
pub const FRONTIER_REACH_CELLS: usize = 2;

/// Whether a cell is on a frontier: traversable, with unknown space (not a hole in what is
/// known) at most [`FRONTIER_REACH_CELLS`] steps away through free cells.
pub fn is_frontier(grid: &OccupancyGrid, c: (usize, usize)) -> bool {
    grid.traversable(c) && unknown_within(grid, c, FRONTIER_REACH_CELLS)
}

/// The 4-neighbours of a cell inside the grid.
fn four(grid: &OccupancyGrid, (i, j): (usize, usize)) -> impl Iterator<Item = (usize, usize)> {
    let side = grid.side();
    [
        (i > 0).then(|| (i - 1, j)),
        (i + 1 < side).then_some((i + 1, j)),
        (j > 0).then(|| (i, j - 1)),
        (j + 1 < side).then_some((i, j + 1)),
    ]
    .into_iter()
    .flatten()
}

/// Whether unknown space lies at most `steps` 4-connected steps from `c`, through free cells
/// that touch nothing occupied (a free cell beside a wall may be a gap in it: a wall's returns
/// split between two rows of cells).
fn unknown_within(grid: &OccupancyGrid, c: (usize, usize), steps: usize) -> bool {
    steps > 0
        && four(grid, c).any(|n| match grid.cell(n) {
            Cell::Unknown => open_unknown(grid, n),
            Cell::Free => {
                steps > 1
                    && !grid.neighbours(n).any(|m| grid.cell(m) == Cell::Occupied)
                    && unknown_within(grid, n, steps - 1)
            }
            Cell::Occupied => false,
        })
}

/// Whether an unknown cell is part of unknown space, not a hole in what is known: at least two
/// of its 4-neighbours are unknown too.
fn open_unknown(grid: &OccupancyGrid, c: (usize, usize)) -> bool {
    four(grid, c).filter(|&n| grid.cell(n) == Cell::Unknown).count() >= 2
}

/// Every frontier of at least `min_cells` cells, largest first.
pub fn frontiers(grid: &OccupancyGrid, min_cells: usize) -> Vec<Frontier> {
    let side = grid.side();
    let mut seen = vec![false; side * side];
    let mut out = Vec::new();
    for j in 0..side {
        for i in 0..side {
            if seen.get(j * side + i).copied().unwrap_or(true) || !is_frontier(grid, (i, j)) {
                continue;
            }
            let cells = flood(grid, (i, j), &mut seen);
            if cells.len() >= min_cells.max(1) {
                out.push(cluster(grid, cells));
            }
        }
    }
    out.sort_by_key(|f| std::cmp::Reverse(f.cells.len()));
    out
}

/// The frontier cells 8-connected to `start`, marking them seen.
fn flood(grid: &OccupancyGrid, start: (usize, usize), seen: &mut [bool]) -> Vec<(usize, usize)> {
    let side = grid.side();
    let mut cells = Vec::new();
    let mut queue = VecDeque::from([start]);
    if let Some(s) = seen.get_mut(start.1 * side + start.0) {
        *s = true;
    }
    while let Some(c) = queue.pop_front() {
        cells.push(c);
        for n in grid.neighbours(c) {
            let Some(s) = seen.get_mut(n.1 * side + n.0) else { continue };
            if !*s && is_frontier(grid, n) {
                *s = true;
                queue.push_back(n);
            }
        }
    }
    cells
}

fn cluster(grid: &OccupancyGrid, cells: Vec<(usize, usize)>) -> Frontier {
    let n = cells.len().max(1) as f64;
    let (sx, sy) = cells.iter().map(|&c| grid.centre_of(c)).fold((0.0, 0.0), |(x, y), [cx, cy]| (x + cx, y + cy));
    let centroid_m = [sx / n, sy / n];
    let d2 = |c: &(usize, usize)| {
        let [x, y] = grid.centre_of(*c);
        (x - centroid_m[0]).powi(2) + (y - centroid_m[1]).powi(2)
    };
    let goal = cells.iter().min_by(|a, b| d2(a).total_cmp(&d2(b))).copied().unwrap_or((0, 0));
    Frontier { cells, centroid_m, goal }
}
