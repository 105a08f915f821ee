//! A 2.5D occupancy grid of the floor the robot drives on, sans-IO: placed scans in (the
//! sensor's origin and its returns in the world), per cell what the rays said (free, hit,
//! unknown) and the floor's height where returns fell on it. Traversable is free floor, seen,
//! with no step to a neighbour higher than the base can climb.
//!
//! A return counts as an obstacle when it lies in the robot's body band: above the floor by more
//! than `max_step_m` and below `body_height_m` (a table top at 0.75 m blocks, a lamp at 2.2 m
//! does not); returns near the floor are floor. Rays are cast in the plane from the sensor to
//! each return (Bresenham) and clear the cells they cross: the robot's LiDAR looked through
//! them. Ceilings and the floor's own returns clear nothing past themselves.

use crate::voxel_hash::VoxelHashSet;
use nalgebra::Vector3;

/// Log-odds added per hit and per pass, and their bounds: a cell seen free many times takes a
/// few hits to turn occupied (a person walking through), and the other way round.
const HIT: i8 = 3;
const PASS: i8 = -1;
const CLAMP: i8 = 12;
/// At least this log-odds is occupied, at most the negative of it free.
const DECIDED: i8 = 2;

/// Settings of the grid.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OccupancyConfig {
    pub cell_m: f64,
    /// Side of the grid's square, metres, centred on the first scan's origin.
    pub extent_m: f64,
    /// The floor's height in the world (the robot's base stands on it).
    pub floor_z_m: f64,
    /// The highest step the base climbs; returns below it over the floor are floor.
    pub max_step_m: f64,
    /// Returns above this over the floor do not block the robot.
    pub body_height_m: f64,
    /// Rays longer than this (m, in the plane) are cut: far returns are sparse and noisy.
    pub max_range_m: f64,
    /// The LiDAR's minimum range: a ray clears no cell nearer than this to the sensor (in the
    /// plane), since something there would not have returned it (0: every cell it crosses).
    pub min_range_m: f64,
}

impl Default for OccupancyConfig {
    fn default() -> Self {
        Self {
            cell_m: 0.1,
            extent_m: 80.0,
            floor_z_m: 0.0,
            max_step_m: 0.05,
            body_height_m: 1.2,
            max_range_m: 15.0,
            min_range_m: 0.0,
        }
    }
}

/// What is known of a cell.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Cell {
    Unknown,
    Free,
    Occupied,
}

/// The grid: log-odds per cell and the floor's highest return per cell.
pub struct OccupancyGrid {
    cfg: OccupancyConfig,
    origin_m: [f64; 2],
    side: usize,
    log_odds: Vec<i8>,
    /// The floor's height where returns fell on it (NaN: no floor return).
    floor_m: Vec<f32>,
}

impl OccupancyGrid {
    /// An empty grid of `cfg.extent_m` around `centre` (x, y). `None` for a cell size or extent
    /// that is not positive, or more than 2^26 cells.
    pub fn new(cfg: OccupancyConfig, centre: [f64; 2]) -> Option<Self> {
        let side = (cfg.extent_m / cfg.cell_m).ceil();
        if !(cfg.cell_m > 0.0 && side >= 1.0 && side * side <= (1u64 << 26) as f64) {
            return None;
        }
        let side = side as usize;
        let half = side as f64 * cfg.cell_m / 2.0;
        Some(Self {
            cfg,
            origin_m: [centre[0] - half, centre[1] - half],
            side,
            log_odds: vec![0; side * side],
            floor_m: vec![f32::NAN; side * side],
        })
    }

    pub fn config(&self) -> &OccupancyConfig {
        &self.cfg
    }

    /// Cells along each side.
    pub fn side(&self) -> usize {
        self.side
    }

    /// The cell (column, row) of a world point; `None` outside the grid.
    pub fn cell_of(&self, x: f64, y: f64) -> Option<(usize, usize)> {
        let i = ((x - self.origin_m[0]) / self.cfg.cell_m).floor();
        let j = ((y - self.origin_m[1]) / self.cfg.cell_m).floor();
        let n = self.side as f64;
        ((0.0..n).contains(&i) && (0.0..n).contains(&j)).then_some((i as usize, j as usize))
    }

    /// The centre of a cell in the world (x, y).
    pub fn centre_of(&self, (i, j): (usize, usize)) -> [f64; 2] {
        [self.origin_m[0] + (i as f64 + 0.5) * self.cfg.cell_m, self.origin_m[1] + (j as f64 + 0.5) * self.cfg.cell_m]
    }

    fn index(&self, (i, j): (usize, usize)) -> Option<usize> {
        (i < self.side && j < self.side).then_some(j * self.side + i)
    }

    /// What is known of a cell (outside the grid: unknown).
    pub fn cell(&self, c: (usize, usize)) -> Cell {
        match self.index(c).and_then(|k| self.log_odds.get(k)) {
            Some(&v) if v >= DECIDED => Cell::Occupied,
            Some(&v) if v <= -DECIDED => Cell::Free,
            _ => Cell::Unknown,
        }
    }

    /// The floor's height in a cell, where returns fell on it.
    pub fn floor(&self, c: (usize, usize)) -> Option<f64> {
        let v = self.index(c).and_then(|k| self.floor_m.get(k)).copied()?;
        v.is_finite().then_some(f64::from(v))
    }

    /// Whether the base can stand on a cell: free, its floor seen (rays cross a stairwell's
    /// cells as readily as a floor's), and no neighbour's floor a step higher or lower than it
    /// climbs (an edge, a stair, a kerb).
    pub fn traversable(&self, c: (usize, usize)) -> bool {
        if self.cell(c) != Cell::Free {
            return false;
        }
        let Some(here) = self.floor(c) else { return false };
        self.neighbours(c).all(|n| self.floor(n).is_none_or(|f| (f - here).abs() <= self.cfg.max_step_m))
    }

    /// The 8 neighbours inside the grid.
    pub fn neighbours(&self, (i, j): (usize, usize)) -> impl Iterator<Item = (usize, usize)> + '_ {
        let side = self.side as i64;
        (-1i64..=1).flat_map(move |dj| (-1i64..=1).map(move |di| (di, dj))).filter_map(move |(di, dj)| {
            let (x, y) = (i as i64 + di, j as i64 + dj);
            ((di, dj) != (0, 0) && (0..side).contains(&x) && (0..side).contains(&y)).then_some((x as usize, y as usize))
        })
    }

    /// The floor under the base, `radius_m` around (x, y), is free floor at the grid's floor
    /// height: it stood there. The LiDAR never sees the floor right under and beside it, and
    /// without this the way back to where the base started would end short of it.
    pub fn mark_driven(&mut self, x: f64, y: f64, radius_m: f64) {
        let floor_z = self.cfg.floor_z_m as f32;
        self.for_cells_within(x, y, radius_m, |v, f| {
            *v = -CLAMP;
            if !f.is_finite() {
                *f = floor_z;
            }
        });
    }

    /// The floor around (x, y), `radius_m` around, that the LiDAR cannot see from there
    /// (nearer than its minimum range, or under its view), taken as free floor at the grid's
    /// floor height where the floor just past it, straight out from (x, y), was seen: where the
    /// base starts, which the operator put it down in. Where what lies just past the ring is an
    /// obstacle or unknown (a bed reaching into the ring from beyond it), the ring stays
    /// unknown; occupied cells stay as they are. Without it a base that has not yet driven
    /// knows no floor it could reach from where it stands.
    pub fn assume_blind_floor(&mut self, x: f64, y: f64, radius_m: f64) {
        let Some(centre) = self.cell_of(x, y) else { return };
        let [cx, cy] = self.centre_of(centre);
        let beyond_m = radius_m + 2.0 * self.cfg.cell_m;
        let r = (radius_m.max(0.0) / self.cfg.cell_m).ceil().min(self.side as f64) as i64;
        let mut assumed = Vec::new();
        for dj in -r..=r {
            for di in -r..=r {
                let d = ((di * di + dj * dj) as f64).sqrt() * self.cfg.cell_m;
                if d > radius_m || d == 0.0 {
                    continue;
                }
                let (i, j) = (centre.0 as i64 + di, centre.1 as i64 + dj);
                let past = self.cell_of(
                    cx + di as f64 * self.cfg.cell_m / d * beyond_m,
                    cy + dj as f64 * self.cfg.cell_m / d * beyond_m,
                );
                if past.is_some_and(|c| self.traversable(c)) {
                    if let Some(k) = self.index_unbounded((i, j)) {
                        assumed.push(k);
                    }
                }
            }
        }
        let floor_z = self.cfg.floor_z_m as f32;
        for k in assumed {
            if let (Some(v), Some(f)) = (self.log_odds.get_mut(k), self.floor_m.get_mut(k)) {
                if *v < DECIDED {
                    *v = (*v).min(-DECIDED);
                    if !f.is_finite() {
                        *f = floor_z;
                    }
                }
            }
        }
    }

    /// `f(log-odds, floor)` of every cell whose centre's offset from (x, y)'s cell is within
    /// `radius_m`.
    fn for_cells_within(&mut self, x: f64, y: f64, radius_m: f64, mut f: impl FnMut(&mut i8, &mut f32)) {
        let Some((ci, cj)) = self.cell_of(x, y) else { return };
        let r = (radius_m.max(0.0) / self.cfg.cell_m).ceil().min(self.side as f64) as i64;
        for dj in -r..=r {
            for di in -r..=r {
                let (i, j) = (ci as i64 + di, cj as i64 + dj);
                if i < 0 || j < 0 || ((di * di + dj * dj) as f64).sqrt() * self.cfg.cell_m > radius_m {
                    continue;
                }
                let Some(k) = self.index((i as usize, j as usize)) else { continue };
                if let (Some(v), Some(fl)) = (self.log_odds.get_mut(k), self.floor_m.get_mut(k)) {
                    f(v, fl);
                }
            }
        }
    }

    /// The centres (world x, y) of the occupied cells within `radius_m` of (x, y).
    pub fn occupied_near(&self, x: f64, y: f64, radius_m: f64) -> Vec<[f64; 2]> {
        let Some((ci, cj)) = self.cell_of(x, y) else { return Vec::new() };
        let r = (radius_m.max(0.0) / self.cfg.cell_m).ceil().min(self.side as f64) as i64;
        let mut out = Vec::new();
        for dj in -r..=r {
            for di in -r..=r {
                let (i, j) = (ci as i64 + di, cj as i64 + dj);
                if i < 0 || j < 0 {
                    continue;
                }
                let c = (i as usize, j as usize);
                let [cx, cy] = self.centre_of(c);
                if self.cell(c) == Cell::Occupied && (cx - x).hypot(cy - y) <= radius_m {
                    out.push([cx, cy]);
                }
            }
        }
        out
    }

    /// Adds one placed scan: the sensor at `origin` (world), its returns in the world. Cells an
    /// obstacle return falls in are not cleared by the same scan's rays or floor returns (the
    /// floor at a wall's foot shares its cell).
    pub fn add_scan<'a>(&mut self, origin: &Vector3<f64>, points: impl IntoIterator<Item = &'a Vector3<f64>> + Clone) {
        let Some(from) = self.cell_of(origin.x, origin.y) else { return };
        let hit: VoxelHashSet<usize> = points
            .clone()
            .into_iter()
            .filter(|p| {
                p.iter().all(|v| v.is_finite())
                    && self.blocks(p)
                    && (p.xy() - origin.xy()).norm() <= self.cfg.max_range_m
            })
            .filter_map(|p| self.cell_of(p.x, p.y).and_then(|c| self.index(c)))
            .collect();
        for &k in &hit {
            self.bump(k, HIT);
        }
        let floor = self.cfg.floor_z_m;
        for p in points {
            if !p.iter().all(|v| v.is_finite()) {
                continue;
            }
            let over_floor = p.z - floor;
            let d = (p.xy() - origin.xy()).norm();
            // Far returns: the ray clears up to the range, the return itself is not trusted.
            let (end, trusted) = if d > self.cfg.max_range_m {
                let f = self.cfg.max_range_m / d;
                (origin.xy() + (p.xy() - origin.xy()) * f, false)
            } else {
                (p.xy(), true)
            };
            let to = self.cell_unbounded(end.x, end.y);
            let is_floor = trusted && over_floor.abs() <= self.cfg.max_step_m * 4.0 && !self.blocks(p);
            // A return on the floor or an obstacle ends where it fell; one overhead (a ceiling,
            // a shelf over the robot's head) clears the floor beneath its ray only up to the
            // cell before it, which its ray crossed.
            self.pass_along(from, to, &hit);
            if let Some(k) = self.index_unbounded(to).filter(|k| !hit.contains(k)) {
                if is_floor {
                    self.bump(k, PASS);
                    if let Some(f) = self.floor_m.get_mut(k) {
                        let z = over_floor as f32 + floor as f32;
                        *f = if f.is_finite() { f.max(z) } else { z };
                    }
                }
            }
        }
    }

    /// The cell of a finite world point, inside the grid or not (saturating far outside it).
    fn cell_unbounded(&self, x: f64, y: f64) -> (i64, i64) {
        let at = |v: f64, o: f64| ((v - o) / self.cfg.cell_m).floor() as i64;
        (at(x, self.origin_m[0]), at(y, self.origin_m[1]))
    }

    fn index_unbounded(&self, (i, j): (i64, i64)) -> Option<usize> {
        self.index((usize::try_from(i).ok()?, usize::try_from(j).ok()?))
    }

    /// Whether a return lies in the robot's body band over the floor.
    fn blocks(&self, p: &Vector3<f64>) -> bool {
        let over_floor = p.z - self.cfg.floor_z_m;
        over_floor > self.cfg.max_step_m && over_floor < self.cfg.body_height_m
    }

    /// Lowers the log-odds of every cell from `a` (inside the grid) up to (not including) `b`,
    /// except `hit` ones; a ray leaving the grid stops there (it cannot come back in).
    fn pass_along(&mut self, a: (usize, usize), (x1, y1): (i64, i64), hit: &VoxelHashSet<usize>) {
        let blind_cells = self.cfg.min_range_m / self.cfg.cell_m;
        let blind_sq = (blind_cells * blind_cells).floor() as i64;
        let (mut x, mut y) = (a.0 as i64, a.1 as i64);
        let (dx, dy) = ((x1 - x).abs(), -(y1 - y).abs());
        let (sx, sy) = (if x < x1 { 1 } else { -1 }, if y < y1 { 1 } else { -1 });
        let mut err = dx + dy;
        while (x, y) != (x1, y1) {
            let Some(k) = self.index_unbounded((x, y)) else { break };
            let near = (x - a.0 as i64).pow(2) + (y - a.1 as i64).pow(2) < blind_sq;
            if !hit.contains(&k) && !near {
                self.bump(k, PASS);
            }
            let e2 = 2 * err;
            if e2 >= dy {
                err += dy;
                x += sx;
            }
            if e2 <= dx {
                err += dx;
                y += sy;
            }
        }
    }

    fn bump(&mut self, k: usize, by: i8) {
        if let Some(v) = self.log_odds.get_mut(k) {
            *v = v.saturating_add(by).clamp(-CLAMP, CLAMP);
        }
    }

    /// The floor the base can stand on (traversable cells), square metres.
    pub fn traversable_area_m2(&self) -> f64 {
        let n = (0..self.side * self.side).filter(|&k| self.traversable((k % self.side, k / self.side))).count();
        n as f64 * self.cfg.cell_m * self.cfg.cell_m
    }

    /// Cells known free and occupied, for reports (free, occupied).
    pub fn known(&self) -> (usize, usize) {
        let free = self.log_odds.iter().filter(|&&v| v <= -DECIDED).count();
        let occupied = self.log_odds.iter().filter(|&&v| v >= DECIDED).count();
        (free, occupied)
    }
}
