//! The floor the robot could reach, from the simulator's truth (the scorer's alone): 0.1 m
//! cells over the scenario's floors where the base's disc touches nothing (the contact check's
//! rays), flooded 8-connected from where the robot starts (near the start, with the room the
//! start has: a scripted start may lie closer than the disc's radius to something). Coverage is the share of it the
//! explorer's grid knows as traversable, the grid's cells moved into the world by the LIO's
//! first pose against the truth's.

use crate::explore_sim::disc_hit;
use starc_hil::sim::scenario::Scenario;
use starc_hil::sim::world::World;
use starc_pipeline::explore::OccupancyGrid;
use std::collections::VecDeque;

const CELL_M: f64 = 0.1;
/// How far from its start a robot put down in a tight spot may move with less room than its
/// radius (m).
const START_M: f64 = 0.5;

/// The reachable floor as a grid over the scenario's floors.
pub struct Reachable {
    origin_m: [f64; 2],
    nx: usize,
    ny: usize,
    cells: Vec<bool>,
}

impl Reachable {
    /// Reachable cells from `start` (x, y) for a disc of `radius_m`, people as they stand at
    /// `t_s` (a walker crossing a doorway at that instant closes it only then; the start's
    /// scene is the one the run begins with).
    pub fn from_truth(scenario: &Scenario, world: &World, start: [f64; 2], radius_m: f64, t_s: f64) -> Self {
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for f in &scenario.floors {
            let f = f.get_ref();
            for k in 0..2 {
                lo[k] = lo[k].min(f.min[k]);
                hi[k] = hi[k].max(f.max[k]);
            }
        }
        let size = |k: usize| if hi[k] > lo[k] { ((hi[k] - lo[k]) / CELL_M).ceil() as usize } else { 0 };
        let (nx, ny) = (size(0).min(4000), size(1).min(4000));
        let mut me = Self { origin_m: lo, nx, ny, cells: vec![false; nx * ny] };
        let on_floor = |x: f64, y: f64| {
            scenario.floors.iter().any(|f| {
                let f = f.get_ref();
                (f.min[0]..=f.max[0]).contains(&x) && (f.min[1]..=f.max[1]).contains(&y)
            })
        };
        let bodies = world.bodies_at(t_s);
        let clear_by = |x: f64, y: f64, r: f64| on_floor(x, y) && disc_hit(world, &bodies, [x, y], r).is_none();
        // A robot put down nearer than its radius to something drives out of there: within
        // START_M of the start, the widest disc that fits at the start is enough.
        let start_r = [1.0, 0.8, 0.6, 0.4, 0.2, 0.0]
            .into_iter()
            .map(|f| f * radius_m)
            .find(|&r| clear_by(start[0], start[1], r))
            .unwrap_or(0.0);
        let clear = |x: f64, y: f64| {
            let near_start = (x - start[0]).hypot(y - start[1]) <= START_M;
            clear_by(x, y, radius_m) || (near_start && clear_by(x, y, start_r))
        };
        let Some(first) = me.index_of(start[0], start[1]) else { return me };
        let mut seen = vec![false; nx * ny];
        let mut queue = VecDeque::from([first]);
        if let Some(s) = seen.get_mut(first) {
            *s = true;
        }
        while let Some(k) = queue.pop_front() {
            let [x, y] = me.centre(k);
            if k != first && !clear(x, y) {
                continue;
            }
            if let Some(c) = me.cells.get_mut(k) {
                *c = true;
            }
            let (i, j) = ((k % nx) as i64, (k / nx) as i64);
            for (di, dj) in [(-1, -1), (0, -1), (1, -1), (-1, 0), (1, 0), (-1, 1), (0, 1), (1, 1)] {
                let (a, b) = (i + di, j + dj);
                if a < 0 || b < 0 || a >= nx as i64 || b >= ny as i64 {
                    continue;
                }
                let n = b as usize * nx + a as usize;
                if seen.get(n) == Some(&false) {
                    seen[n] = true;
                    queue.push_back(n);
                }
            }
        }
        me
    }

    fn index_of(&self, x: f64, y: f64) -> Option<usize> {
        let (i, j) = ((x - self.origin_m[0]) / CELL_M, (y - self.origin_m[1]) / CELL_M);
        let inside = i >= 0.0 && j >= 0.0 && (i as usize) < self.nx && (j as usize) < self.ny;
        inside.then(|| j as usize * self.nx + i as usize)
    }

    fn centre(&self, k: usize) -> [f64; 2] {
        let (i, j) = (k % self.nx, k / self.nx);
        [self.origin_m[0] + (i as f64 + 0.5) * CELL_M, self.origin_m[1] + (j as f64 + 0.5) * CELL_M]
    }

    #[cfg(test)]
    fn contains(&self, x: f64, y: f64) -> bool {
        self.index_of(x, y).and_then(|k| self.cells.get(k)).copied().unwrap_or(false)
    }

    pub fn area_m2(&self) -> f64 {
        self.cells.iter().filter(|c| **c).count() as f64 * CELL_M * CELL_M
    }

    /// The share of the reachable floor that `grid` knows as traversable, its cells moved into
    /// the world by `world_from_grid` (x, y, yaw: where the grid's origin and x axis lie).
    pub fn coverage(&self, grid: &OccupancyGrid, world_from_grid: [f64; 3]) -> f64 {
        let total = self.cells.iter().filter(|c| **c).count();
        if total == 0 {
            return 0.0;
        }
        let (s, c) = world_from_grid[2].sin_cos();
        let side = grid.side();
        // Each reachable cell counted once, however many grid cells fall in it.
        let mut known = vec![false; self.cells.len()];
        for j in 0..side {
            for i in 0..side {
                if !grid.traversable((i, j)) {
                    continue;
                }
                let [gx, gy] = grid.centre_of((i, j));
                let (x, y) = (world_from_grid[0] + c * gx - s * gy, world_from_grid[1] + s * gx + c * gy);
                if let Some(k) = self.index_of(x, y).filter(|&k| self.cells.get(k) == Some(&true)) {
                    known[k] = true;
                }
            }
        }
        known.iter().filter(|k| **k).count() as f64 / total as f64
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn the_lab_reachable_floor_is_less_than_its_floor_and_a_grid_covers_it_where_it_lies() {
        let (scenario, _) = Scenario::load("lab").unwrap();
        let world = World::new(&scenario);
        let start = scenario.robot.get_ref().waypoints[0];
        let r = Reachable::from_truth(&scenario, &world, [start[0], start[1]], 0.3, 0.0);
        assert!(r.contains(start[0], start[1]));
        let floor: f64 = scenario
            .floors
            .iter()
            .map(|f| (f.get_ref().max[0] - f.get_ref().min[0]) * (f.get_ref().max[1] - f.get_ref().min[1]))
            .sum();
        let area = r.area_m2();
        assert!(area > 5.0 && area < floor, "{area} of {floor} m²");
        // Put down right beside the wall along y = 0, closer than the disc: the rooms are
        // reached all the same (and a little more floor beside the start), nothing past the wall.
        let near = Reachable::from_truth(&scenario, &world, [start[0], 0.2], 0.3, 0.0);
        assert!(near.area_m2() > area - 0.5 && near.area_m2() < area + 5.0, "{} against {area}", near.area_m2());
        assert!(near.contains(start[0], 0.2) && !near.contains(start[0], -0.5));
        // An empty grid covers nothing; one that knows everything around covers all of it.
        let mut grid = OccupancyGrid::new(Default::default(), [start[0], start[1]]).unwrap();
        assert_eq!(r.coverage(&grid, [0.0, 0.0, 0.0]), 0.0);
        grid.mark_driven(start[0], start[1], 40.0);
        assert!((r.coverage(&grid, [0.0, 0.0, 0.0]) - 1.0).abs() < 1e-9);
        // Moved by the wrong transform, the same grid covers nothing.
        assert_eq!(r.coverage(&grid, [200.0, 0.0, 0.0]), 0.0);
    }
}
