//! A global search of the source's level pose (x, y, yaw) over the whole target, for a rig that
//! may enter anywhere the robot has mapped. Both clouds are levelled by their IMUs, so what is
//! left is a plane: the walls and furniture each cloud sees between knee and head height,
//! projected onto 2D grids, are matched by correlation (Olson's correlative scan matching).
//!
//! A pose scores the source points that land on the target's structure, less
//! `free_penalty` for each that lands where the target's sensor saw through (its coverage): a
//! symmetric room turned 180 deg explains the view as well as the truth, but puts part of it
//! where the robot looked and saw nothing. Every yaw and every position over the target is
//! searched, best first, by branch and bound over max-pooled grids (each level's cell holds the
//! best value of a block of 2^k finer cells, so a block's sum bounds every pose inside it).

use super::coverage::Coverage;
use super::geometry::Vec3;
use nalgebra::{Isometry3, Translation3, UnitQuaternion};
use std::collections::BinaryHeap;

/// The band of heights, above each cloud's floor, that is projected: above most clutter and
/// below the ceiling, where rooms differ by their walls, doors and tall furniture.
const BAND_M: (f64, f64) = (0.4, 1.9);
/// A cloud's floor: this low quantile of its heights (both clouds see the floor around them).
const FLOOR_QUANTILE: f64 = 0.03;
/// Coarsest pooling level: blocks of 2^LEVELS cells.
const LEVELS: usize = 6;
/// A cell beside a structure cell is worth this much of a cell on it (the grid's quantisation).
const BESIDE_VALUE: f32 = 0.5;
/// At most this many cells per grid (about 210 x 210 m at 0.15 m; each of the 7 levels holds
/// 4 bytes a cell): a larger map turns the stage off rather than take gigabytes.
const MAX_CELLS: usize = 2_000_000;
/// Peaks closer than this (m, deg) to a better one are the same place.
const DISTINCT_M: f64 = 1.0;
const DISTINCT_DEG: f64 = 10.0;

/// Settings of the search (from [`super::AlignConfig`]'s `correlative_*` keys).
#[derive(Clone, Copy, Debug)]
pub struct CorrelativeParams {
    pub cell_m: f64,
    /// Distinct peaks returned, best first.
    pub peaks: usize,
    /// What a source point in seen-through space costs, against 1 for one on the structure.
    pub free_penalty: f64,
    /// A voxel is seen through when at least this many of the target sensor's rays crossed it.
    pub min_crossings: u16,
    /// The source is thinned to at most this many 2D cells.
    pub max_source_points: usize,
    /// Peaks score at least this share of the source points ...
    pub min_score: f64,
    /// ... and, once the best is found, at most this much below it (infinite: any). The search
    /// ends when nothing left in its queue can score that much; a place further below the best
    /// can neither rival it nor be accepted beside it.
    pub within_best: f64,
    /// Nodes taken from the queue, at most (bounds the time on a map with many equal places).
    pub max_expansions: usize,
}

/// A place found: the source's pose in the target (level, at the target's floor height) and
/// its score as a share of the source points (explained less penalised).
#[derive(Clone, Debug)]
pub struct Peak {
    pub pose: Isometry3<f64>,
    pub score: f64,
}

/// The searched grids of one target: value per cell, pooled per level.
pub struct TargetGrid {
    origin_m: [f64; 2],
    cell_m: f64,
    width: usize,
    height: usize,
    floor_m: f64,
    levels: Vec<Vec<f32>>,
    /// Of a [`Self::standing`] grid: per level, 1 where the block holds a cell the origin may
    /// stand in (empty: it may stand anywhere).
    standable: Vec<Vec<f32>>,
}

impl TargetGrid {
    /// The target's grids, with its coverage when there is one (without it nothing is
    /// penalised). `None` when the target has no structure in the band.
    pub fn new(target: &[Vec3], coverage: Option<&Coverage>, p: &CorrelativeParams) -> Option<Self> {
        let floor_m = quantile_z(target, FLOOR_QUANTILE)?;
        let band: Vec<&Vec3> = target.iter().filter(|q| in_band(q.z, floor_m)).collect();
        let (lo, hi) = bounds_xy(band.iter().copied())?;
        // A pooled block starting left of the structure stays inside the padding (values <= 0),
        // with two cells to spare for rounding.
        let pad = ((1usize << LEVELS) + 2) as f64 * p.cell_m;
        let origin_m = [lo[0] - pad, lo[1] - pad];
        let width = ((hi[0] - origin_m[0]) / p.cell_m).ceil() as usize + 2;
        let height = ((hi[1] - origin_m[1]) / p.cell_m).ceil() as usize + 2;
        if width.saturating_mul(height) > MAX_CELLS {
            tracing::debug!(width, height, "correlative stage off: the map's grid would be too large");
            return None;
        }
        let mut g =
            Self { origin_m, cell_m: p.cell_m, width, height, floor_m, levels: Vec::new(), standable: Vec::new() };
        let values = g.values(&band, coverage, p);
        g.levels = pooled_levels(values, width, height);
        Some(g)
    }

    /// The same grid with seen-through cells costing `free_penalty`, whose searches only take
    /// places where the source's origin (the rig's sensor) stands where the target's sensor saw
    /// through: inside what the robot has seen, not outside the building or inside a wall.
    /// `None` when the target's sensor saw through nothing (no coverage).
    pub fn standing(&self, free_penalty: f64) -> Option<Self> {
        let base = self.levels.first()?;
        let seen_through: Vec<f32> = base.iter().map(|&v| if v < 0.0 { 1.0 } else { 0.0 }).collect();
        if !seen_through.iter().any(|&v| v > 0.0) {
            return None;
        }
        let penalty = -(free_penalty as f32);
        let values = base.iter().map(|&v| if v < 0.0 { penalty } else { v }).collect();
        Some(Self {
            origin_m: self.origin_m,
            cell_m: self.cell_m,
            width: self.width,
            height: self.height,
            floor_m: self.floor_m,
            levels: pooled_levels(values, self.width, self.height),
            standable: pooled_levels(seen_through, self.width, self.height),
        })
    }

    fn cell_of(&self, x_m: f64, y_m: f64) -> Option<usize> {
        let cx = ((x_m - self.origin_m[0]) / self.cell_m).floor();
        let cy = ((y_m - self.origin_m[1]) / self.cell_m).floor();
        let inside = cx >= 0.0 && cy >= 0.0 && (cx as usize) < self.width && (cy as usize) < self.height;
        inside.then(|| cy as usize * self.width + cx as usize)
    }

    /// Per cell: 1 on structure, `BESIDE_VALUE` beside it, `-free_penalty` where the target's
    /// sensor saw through, else 0 (never looked at: says nothing).
    fn values(&self, band: &[&Vec3], coverage: Option<&Coverage>, p: &CorrelativeParams) -> Vec<f32> {
        let mut v = vec![0.0f32; self.width * self.height];
        if let Some(c) = coverage {
            self.mark_free(&mut v, c, p);
        }
        let mut on = vec![false; v.len()];
        for q in band {
            if let Some(i) = self.cell_of(q.x, q.y) {
                on[i] = true;
            }
        }
        for (i, _) in on.iter().enumerate().filter(|(_, &o)| o) {
            let (x, y) = ((i % self.width) as i64, (i / self.width) as i64);
            for (dx, dy) in (-1..=1).flat_map(|dx| (-1..=1).map(move |dy| (dx, dy))) {
                let (nx, ny) = (x + dx, y + dy);
                if nx < 0 || ny < 0 || nx as usize >= self.width || ny as usize >= self.height {
                    continue;
                }
                let j = ny as usize * self.width + nx as usize;
                let value = if dx == 0 && dy == 0 { 1.0 } else { BESIDE_VALUE };
                if let Some(c) = v.get_mut(j) {
                    *c = if *c > 0.0 { c.max(value) } else { value };
                }
            }
        }
        v
    }

    /// Cells under a coverage voxel in the band that enough rays crossed.
    fn mark_free(&self, v: &mut [f32], coverage: &Coverage, p: &CorrelativeParams) {
        let voxel_m = coverage.voxel_m();
        let penalty = -(p.free_penalty as f32);
        for (key, crossings) in coverage.voxels() {
            let z_m = (f64::from(key.2) + 0.5) * voxel_m;
            if crossings < p.min_crossings || !in_band(z_m, self.floor_m) {
                continue;
            }
            // Cells under the voxel's footprint, found by sampling it at about the cell size.
            let (x0, y0) = (f64::from(key.0) * voxel_m, f64::from(key.1) * voxel_m);
            let steps = (voxel_m / self.cell_m).ceil().max(1.0) as usize;
            for sx in 0..steps {
                for sy in 0..steps {
                    let x = x0 + (sx as f64 + 0.5) * voxel_m / steps as f64;
                    let y = y0 + (sy as f64 + 0.5) * voxel_m / steps as f64;
                    if let Some(c) = self.cell_of(x, y).and_then(|i| v.get_mut(i)) {
                        *c = penalty;
                    }
                }
            }
        }
    }

    /// The part of `source` (level, in its own frame) the search matches: its points in the
    /// band above its floor, one per cell. `None` when fewer than 10.
    pub fn source_band(&self, source: &[Vec3], p: &CorrelativeParams) -> Option<SourceBand> {
        let floor_m = quantile_z(source, FLOOR_QUANTILE)?;
        let points = thinned_band(source, floor_m, self.cell_m, p.max_source_points);
        (points.len() >= 10).then_some(SourceBand { points, floor_m })
    }

    /// The score of the source at `pose` (its yaw and horizontal position; level), as a share of
    /// its band's points.
    pub fn score(&self, band: &SourceBand, pose: &Isometry3<f64>) -> f64 {
        let sum: f32 = self.values_under(band, pose).sum();
        f64::from(sum) / band.points.len().max(1) as f64
    }

    /// The level-0 value under each of the band's points at `pose` (0 off the grid).
    fn values_under<'a>(&'a self, band: &'a SourceBand, pose: &Isometry3<f64>) -> impl Iterator<Item = f32> + 'a {
        let yaw = pose.rotation.euler_angles().2;
        let x = (pose.translation.x - self.origin_m[0]) / self.cell_m;
        let y = (pose.translation.y - self.origin_m[1]) / self.cell_m;
        let (s, c) = yaw.sin_cos();
        let (w, h) = (self.width as i64, self.height as i64);
        let grid = self.levels.first();
        band.points.iter().map(move |q| {
            let cx = ((c * q[0] - s * q[1]) / self.cell_m + x).floor() as i64;
            let cy = ((s * q[0] + c * q[1]) / self.cell_m + y).floor() as i64;
            if cx < 0 || cy < 0 || cx >= w || cy >= h {
                return 0.0;
            }
            grid.and_then(|g| g.get((cy * w + cx) as usize)).copied().unwrap_or(0.0)
        })
    }

    /// How the band lands at `pose` on what the target knows: the share of its points on known
    /// cells (structure, beside it, or seen through; a point where the target never looked says
    /// nothing) and their mean value there (1 on structure, negative where seen through).
    pub fn known_fit(&self, band: &SourceBand, pose: &Isometry3<f64>) -> KnownFit {
        let (mut known, mut sum) = (0usize, 0.0f64);
        for v in self.values_under(band, pose).filter(|&v| v != 0.0) {
            known += 1;
            sum += f64::from(v);
        }
        let n = band.points.len().max(1) as f64;
        KnownFit { known_share: known as f64 / n, score_on_known: sum / known.max(1) as f64 }
    }

    /// The level-0 value of the cell under (x, y): 0 outside the grid.
    pub fn value_at(&self, x_m: f64, y_m: f64) -> f32 {
        let grid = self.levels.first();
        self.cell_of(x_m, y_m).and_then(|i| grid.and_then(|g| g.get(i))).copied().unwrap_or(0.0)
    }

    /// The best distinct places of `source` (level, in its own frame) in the target, its origin
    /// searched over the target's extent in the band.
    pub fn search(&self, source: &[Vec3], p: &CorrelativeParams) -> Vec<Peak> {
        self.source_band(source, p).map_or_else(Vec::new, |band| self.search_band(&band, p))
    }

    /// [`Self::search`] of a band already taken.
    pub fn search_band(&self, band: &SourceBand, p: &CorrelativeParams) -> Vec<Peak> {
        let (pts, source_floor_m) = (&band.points, band.floor_m);
        let yaws = yaw_steps(pts, self.cell_m);
        let footprints: Vec<Footprint> = yaws.iter().map(|&yaw| self.footprint(pts, yaw)).collect();
        let n_points = pts.len() as f64;
        let min_sum = p.min_score * n_points;
        let mut queue = BinaryHeap::new();
        let top = LEVELS;
        let block = 1i64 << top;
        let (lo, w, h) = (block, self.width as i64, self.height as i64);
        for (yi, fp) in footprints.iter().enumerate() {
            for tx in (lo..w).step_by(block as usize) {
                for ty in (lo..h).step_by(block as usize) {
                    let bound = self.sum(top, fp, tx, ty);
                    if f64::from(bound) >= min_sum && self.may_stand(top, tx, ty) {
                        queue.push(Node::new(bound, yi, top, tx, ty));
                    }
                }
            }
        }
        let z_m = self.floor_m - source_floor_m;
        // The peaks found, each with its yaw (rad), which every later pop compares against.
        let mut found: Vec<(Peak, f64)> = Vec::new();
        let mut expansions = 0;
        while let Some(n) = queue.pop() {
            // Every pose in this block is the same place as a peak found since it was queued:
            // nothing in it could become a peak.
            if self.within_a_peak(&n, &yaws, &found) {
                continue;
            }
            expansions += 1;
            let floor = found.first().map_or(min_sum, |(best, _)| min_sum.max((best.score - p.within_best) * n_points));
            if found.len() >= p.peaks || expansions > p.max_expansions || f64::from(n.bound) < floor {
                break;
            }
            if n.level == 0 {
                let pose = self.pose_of(&n, &yaws, z_m);
                if found.iter().all(|(q, _)| distinct(&q.pose, &pose)) {
                    let yaw = yaws.get(usize::from(n.yaw)).copied().unwrap_or(0.0);
                    found.push((Peak { pose, score: f64::from(n.bound) / n_points }, yaw));
                }
                continue;
            }
            let Some(fp) = footprints.get(usize::from(n.yaw)) else { continue };
            let level = usize::from(n.level) - 1;
            let half = 1i64 << level;
            let (ntx, nty) = (i64::from(n.tx), i64::from(n.ty));
            for (tx, ty) in [(ntx, nty), (ntx + half, nty), (ntx, nty + half), (ntx + half, nty + half)] {
                if tx >= w || ty >= h {
                    continue;
                }
                let bound = self.sum(level, fp, tx, ty);
                if f64::from(bound) >= min_sum && self.may_stand(level, tx, ty) {
                    queue.push(Node::new(bound, usize::from(n.yaw), level, tx, ty));
                }
            }
        }
        found.into_iter().map(|(peak, _)| peak).collect()
    }

    /// Whether every pose of the block `n` is closer than `DISTINCT_M` and `DISTINCT_DEG` to one
    /// of the peaks `found` (a hair inside both, so that [`distinct`] agrees on every leaf).
    fn within_a_peak(&self, n: &Node, yaws: &[f64], found: &[(Peak, f64)]) -> bool {
        let Some(&yaw) = yaws.get(usize::from(n.yaw)) else { return false };
        let span = ((1i64 << n.level) - 1) as f64 * self.cell_m;
        let x0 = self.origin_m[0] + f64::from(n.tx) * self.cell_m;
        let y0 = self.origin_m[1] + f64::from(n.ty) * self.cell_m;
        let hair = 1e-6;
        found.iter().any(|(q, q_yaw)| {
            let (qx, qy) = (q.pose.translation.x, q.pose.translation.y);
            let dx = (x0 - qx).abs().max((x0 + span - qx).abs());
            let dy = (y0 - qy).abs().max((y0 + span - qy).abs());
            let turn = yaw - q_yaw;
            let turn_deg = turn.sin().atan2(turn.cos()).abs().to_degrees();
            dx.hypot(dy) < DISTINCT_M - hair && turn_deg < DISTINCT_DEG - hair
        })
    }

    /// Whether the block of origins at (tx, ty) of `level` holds one the search may take.
    fn may_stand(&self, level: usize, tx: i64, ty: i64) -> bool {
        if self.standable.is_empty() {
            return true;
        }
        let (w, h) = (self.width as i64, self.height as i64);
        if tx < 0 || ty < 0 || tx >= w || ty >= h {
            return false;
        }
        self.standable.get(level).and_then(|g| g.get((ty * w + tx) as usize)).is_some_and(|&v| v > 0.0)
    }

    /// The cells the source points fall in, turned by `yaw` (rad), relative to its origin's cell.
    fn footprint(&self, pts: &[[f64; 2]], yaw: f64) -> Footprint {
        let (s, c) = yaw.sin_cos();
        let cells: Vec<(i64, i64)> = pts
            .iter()
            .map(|q| {
                let x = c * q[0] - s * q[1];
                let y = s * q[0] + c * q[1];
                ((x / self.cell_m).floor() as i64, (y / self.cell_m).floor() as i64)
            })
            .collect();
        let w = self.width as i64;
        let flat = cells.iter().map(|&(dx, dy)| dy * w + dx).collect();
        let lo = cells.iter().fold((0, 0), |a, &(x, y)| (a.0.min(x), a.1.min(y)));
        let hi = cells.iter().fold((0, 0), |a, &(x, y)| (a.0.max(x), a.1.max(y)));
        Footprint { cells, flat, lo, hi }
    }

    /// The sum over the footprint's cells, moved by (tx, ty), of level `level`'s values (cells
    /// off the grid count 0).
    fn sum(&self, level: usize, fp: &Footprint, tx: i64, ty: i64) -> f32 {
        let Some(grid) = self.levels.get(level) else { return 0.0 };
        let (w, h) = (self.width as i64, self.height as i64);
        let inside = tx + fp.lo.0 >= 0 && ty + fp.lo.1 >= 0 && tx + fp.hi.0 < w && ty + fp.hi.1 < h;
        if inside {
            // Every cell is on the grid: one offset per point, no row arithmetic.
            let at = ty * w + tx;
            return fp.flat.iter().map(|&o| grid.get((at + o) as usize).copied().unwrap_or(0.0)).sum();
        }
        fp.cells
            .iter()
            .map(|&(dx, dy)| {
                let (x, y) = (dx + tx, dy + ty);
                if x < 0 || y < 0 || x >= w || y >= h {
                    return 0.0;
                }
                grid.get((y * w + x) as usize).copied().unwrap_or(0.0)
            })
            .sum()
    }

    fn pose_of(&self, n: &Node, yaws: &[f64], z_m: f64) -> Isometry3<f64> {
        let yaw = yaws.get(usize::from(n.yaw)).copied().unwrap_or(0.0);
        let x = self.origin_m[0] + f64::from(n.tx) * self.cell_m;
        let y = self.origin_m[1] + f64::from(n.ty) * self.cell_m;
        Isometry3::from_parts(Translation3::new(x, y, z_m), UnitQuaternion::from_euler_angles(0.0, 0.0, yaw))
    }
}

/// A band's fit on the part of the target that is known ([`TargetGrid::known_fit`]).
#[derive(Clone, Copy, Debug, serde::Serialize)]
pub struct KnownFit {
    pub known_share: f64,
    pub score_on_known: f64,
}

/// The source's points the search matches (2D, its own frame), and its floor's height.
pub struct SourceBand {
    points: Vec<[f64; 2]>,
    floor_m: f64,
}

/// A source's cells at one yaw, relative to its origin's cell: as (dx, dy), as offsets into a
/// level's row-major values, and their bounding box.
struct Footprint {
    cells: Vec<(i64, i64)>,
    flat: Vec<i64>,
    lo: (i64, i64),
    hi: (i64, i64),
}

/// A block of poses in the queue: every translation in [tx, tx + 2^level) x [ty, ..) at one yaw.
/// Small, because the queue holds hundreds of thousands on a large map.
struct Node {
    bound: f32,
    tx: i32,
    ty: i32,
    yaw: u16,
    level: u8,
}

impl Node {
    /// Grids hold at most `MAX_CELLS` cells and yaws are at least 0.5 deg apart, so every field fits.
    fn new(bound: f32, yaw: usize, level: usize, tx: i64, ty: i64) -> Self {
        Self { bound, tx: tx as i32, ty: ty as i32, yaw: yaw as u16, level: level as u8 }
    }
}

impl PartialEq for Node {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other) == std::cmp::Ordering::Equal
    }
}
impl Eq for Node {}
impl PartialOrd for Node {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Node {
    /// Higher bound first; at equal bounds the finer node, so leaves come out before the blocks
    /// that tie with them; then by yaw and position, so that which of two equal places comes
    /// first does not depend on what the queue held before.
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        self.bound
            .total_cmp(&other.bound)
            .then(other.level.cmp(&self.level))
            .then(other.yaw.cmp(&self.yaw))
            .then(other.tx.cmp(&self.tx))
            .then(other.ty.cmp(&self.ty))
    }
}

fn distinct(a: &Isometry3<f64>, b: &Isometry3<f64>) -> bool {
    let (m, deg) = super::geometry::pose_error(a, b);
    m >= DISTINCT_M || deg >= DISTINCT_DEG
}

fn in_band(z_m: f64, floor_m: f64) -> bool {
    z_m >= floor_m + BAND_M.0 && z_m <= floor_m + BAND_M.1
}

fn quantile_z(points: &[Vec3], q: f64) -> Option<f64> {
    let mut z: Vec<f64> = points.iter().map(|p| p.z).filter(|z| z.is_finite()).collect();
    if z.is_empty() {
        return None;
    }
    let k = ((z.len() - 1) as f64 * q).round() as usize;
    let (_, v, _) = z.select_nth_unstable_by(k, f64::total_cmp);
    Some(*v)
}

fn bounds_xy<'a>(points: impl Iterator<Item = &'a Vec3>) -> Option<([f64; 2], [f64; 2])> {
    let mut lo = [f64::INFINITY; 2];
    let mut hi = [f64::NEG_INFINITY; 2];
    for q in points.filter(|q| q.x.is_finite() && q.y.is_finite()) {
        lo = [lo[0].min(q.x), lo[1].min(q.y)];
        hi = [hi[0].max(q.x), hi[1].max(q.y)];
    }
    (lo[0] <= hi[0] && lo[1] <= hi[1]).then_some((lo, hi))
}

/// The source's points in the band, one per 2D cell, at most `max` (evenly thinned).
fn thinned_band(source: &[Vec3], floor_m: f64, cell_m: f64, max: usize) -> Vec<[f64; 2]> {
    let mut seen = std::collections::HashSet::new();
    let pts: Vec<[f64; 2]> = source
        .iter()
        .filter(|q| in_band(q.z, floor_m) && q.x.is_finite() && q.y.is_finite())
        .filter(|q| seen.insert(((q.x / cell_m).floor() as i64, (q.y / cell_m).floor() as i64)))
        .map(|q| [q.x, q.y])
        .collect();
    let stride = pts.len().div_ceil(max.max(1)).max(1);
    pts.into_iter().step_by(stride).collect()
}

/// Yaw steps fine enough that the farthest (90th percentile) point moves about a cell per step.
fn yaw_steps(pts: &[[f64; 2]], cell_m: f64) -> Vec<f64> {
    let mut r: Vec<f64> = pts.iter().map(|q| q[0].hypot(q[1])).collect();
    r.sort_by(f64::total_cmp);
    let far = r.get((r.len().saturating_sub(1)) * 9 / 10).copied().unwrap_or(1.0).max(1.0);
    let step = (cell_m / far).clamp(0.5f64.to_radians(), 3.0f64.to_radians());
    let n = (std::f64::consts::TAU / step).ceil() as usize;
    (0..n).map(|i| i as f64 * std::f64::consts::TAU / n as f64).collect()
}

/// Level 0 is `values`; level k holds, per cell, the largest value of the 2^k x 2^k block that
/// starts there (cells past the grid count 0, as lookups outside it do).
fn pooled_levels(values: Vec<f32>, width: usize, height: usize) -> Vec<Vec<f32>> {
    let mut levels = vec![values];
    for k in 1..=LEVELS {
        let half = 1usize << (k - 1);
        let Some(prev) = levels.last() else { break };
        let at = |x: usize, y: usize| {
            if x < width && y < height {
                prev.get(y * width + x).copied().unwrap_or(0.0)
            } else {
                0.0
            }
        };
        let mut next = vec![0.0f32; width * height];
        for y in 0..height {
            for x in 0..width {
                let m = at(x, y).max(at(x + half, y)).max(at(x, y + half)).max(at(x + half, y + half));
                if let Some(c) = next.get_mut(y * width + x) {
                    *c = m;
                }
            }
        }
        levels.push(next);
    }
    levels
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    fn params() -> CorrelativeParams {
        CorrelativeParams {
            cell_m: 0.15,
            peaks: 3,
            free_penalty: 1.0,
            min_crossings: 2,
            max_source_points: 400,
            min_score: 0.2,
            max_expansions: 200_000,
            within_best: f64::INFINITY,
        }
    }

    /// Walls of an L-shaped pair of rooms (an asymmetric place), 0 to 2.5 m high, and a floor.
    fn rooms() -> Vec<Vec3> {
        let mut pts = Vec::new();
        let mut wall = |a: [f64; 2], b: [f64; 2]| {
            let n = ((b[0] - a[0]).hypot(b[1] - a[1]) / 0.05) as usize;
            for i in 0..=n {
                let t = i as f64 / n as f64;
                for k in 0..=25 {
                    pts.push(Vec3::new(a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1]), k as f64 * 0.1));
                }
            }
        };
        wall([0.0, 0.0], [8.0, 0.0]);
        wall([8.0, 0.0], [8.0, 4.0]);
        wall([8.0, 4.0], [4.0, 4.0]);
        wall([4.0, 4.0], [4.0, 9.0]);
        wall([4.0, 9.0], [0.0, 9.0]);
        wall([0.0, 9.0], [0.0, 0.0]);
        wall([2.0, 2.0], [3.0, 2.0]);
        for x in 0..80 {
            for y in 0..90 {
                pts.push(Vec3::new(x as f64 * 0.1, y as f64 * 0.1, 0.0));
            }
        }
        pts
    }

    /// The rig stands at (2, 6) turned 130 deg, 1.2 m above the map's frame: its view is the
    /// map moved into its frame, cut to what lies within 6 m; and that pose.
    fn view_from_2_6(map: &[Vec3]) -> (Vec<Vec3>, Isometry3<f64>) {
        let truth = Isometry3::from_parts(
            Translation3::new(2.0, 6.0, 1.2),
            UnitQuaternion::from_euler_angles(0.0, 0.0, 130f64.to_radians()),
        );
        let view = map
            .iter()
            .map(|p| truth.inverse_transform_point(&(*p).into()).coords)
            .filter(|q| q.xy().norm() < 6.0)
            .collect();
        (view, truth)
    }

    #[test]
    fn finds_the_place_of_a_view_from_anywhere() {
        let map = rooms();
        let grid = TargetGrid::new(&map, None, &params()).unwrap();
        let (view, truth) = view_from_2_6(&map);
        let peaks = grid.search(&view, &params());
        let best = peaks.first().unwrap();
        let (m, deg) = super::super::geometry::pose_error(&best.pose, &truth);
        assert!(m < 0.35 && deg < 3.0, "best peak {m:.2} m {deg:.1} deg off ({:.2})", best.score);
        assert!(best.score > 0.8, "{}", best.score);
    }

    #[test]
    fn a_search_kept_within_the_best_finds_the_same_peaks_down_to_that_score() {
        let map = rooms();
        let grid = TargetGrid::new(&map, None, &params()).unwrap();
        let (view, _) = view_from_2_6(&map);
        let wide = CorrelativeParams { peaks: 8, min_score: 0.05, ..params() };
        let all = grid.search(&view, &wide);
        assert!(all.len() >= 3, "{} peaks", all.len());
        let best = all.first().unwrap().score;
        // A window that keeps some peaks and drops others.
        let within = best - all.get(2).unwrap().score + 1e-9;
        let kept = grid.search(&view, &CorrelativeParams { within_best: within, ..wide });
        let expected: Vec<&Peak> = all.iter().filter(|q| q.score >= best - within).collect();
        assert_eq!(kept.len(), expected.len());
        for (k, e) in kept.iter().zip(&expected) {
            assert_eq!(k.pose, e.pose);
            assert_eq!(k.score, e.score);
        }
        // Peaks come best first and are distinct places.
        for (i, a) in all.iter().enumerate() {
            assert!(all.iter().skip(i + 1).all(|b| b.score <= a.score && distinct(&a.pose, &b.pose)));
        }
    }

    #[test]
    fn standing_only_places_stand_where_the_robot_saw_through_and_known_fit_counts_what_is_known() {
        let map = rooms();
        // The robot saw through the lower room only (y under 4 m, x under 8 m).
        let mut coverage = Coverage::new(0.25);
        for x in 1..32 {
            for y in 1..16 {
                for k in 2..8 {
                    let p = Vec3::new(f64::from(x) * 0.25, f64::from(y) * 0.25, f64::from(k) * 0.25);
                    coverage.set_crossings(crate::voxel_hash::key_of(&p, 4.0), 5);
                }
            }
        }
        let (view, truth) = view_from_2_6(&map);
        let p = CorrelativeParams { peaks: 5, min_score: 0.05, ..params() };
        let grid = TargetGrid::new(&map, Some(&coverage), &p).unwrap().standing(1.0).unwrap();
        let peaks = grid.search(&view, &p);
        assert!(!peaks.is_empty());
        for peak in &peaks {
            let (x, y) = (peak.pose.translation.x, peak.pose.translation.y);
            assert!(grid.value_at(x, y) < 0.0, "a place at ({x:.2}, {y:.2}) the robot did not see through");
        }
        // The truth stands where the robot never looked: not a standing place, but its view
        // fits what the map knows there.
        assert!(peaks.iter().all(|q| super::super::geometry::pose_error(&q.pose, &truth).0 > 0.5));
        let band = grid.source_band(&view, &p).unwrap();
        let fit = grid.known_fit(&band, &truth);
        assert!(fit.known_share > 0.5 && fit.score_on_known > 0.7, "{fit:?}");
    }

    #[test]
    fn a_view_placed_where_the_robot_saw_through_loses_to_the_truth() {
        // A square room is the same turned 90 deg. The rig sees a cabinet the robot did not map,
        // in a corner the robot never looked at; the robot saw through the rest of the room. A
        // turned pose puts the cabinet where the robot saw nothing.
        let mut map = Vec::new();
        for (a, b) in
            [([0.0, 0.0], [6.0, 0.0]), ([6.0, 0.0], [6.0, 6.0]), ([6.0, 6.0], [0.0, 6.0]), ([0.0, 6.0], [0.0, 0.0])]
        {
            for i in 0..=120 {
                let t = f64::from(i) / 120.0;
                for k in 0..=25 {
                    map.push(Vec3::new(a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1]), f64::from(k) * 0.1));
                }
            }
        }
        for x in 0..60 {
            for y in 0..60 {
                map.push(Vec3::new(f64::from(x) * 0.1, f64::from(y) * 0.1, 0.0));
            }
        }
        let cabinet: Vec<Vec3> = (0..=20)
            .flat_map(|i| (0..=15).map(move |k| Vec3::new(1.0 + f64::from(i) * 0.05, 0.6, f64::from(k) * 0.1)))
            .collect();
        let mut coverage = Coverage::new(0.25);
        for x in 1..24 {
            for y in 1..24 {
                for k in 0..8 {
                    let p = Vec3::new(f64::from(x) * 0.25 + 0.1, f64::from(y) * 0.25 + 0.1, f64::from(k) * 0.25 + 0.1);
                    if p.x > 2.5 || p.y > 1.5 {
                        coverage.set_crossings(crate::voxel_hash::key_of(&p, 4.0), 5);
                    }
                }
            }
        }
        let truth =
            Isometry3::from_parts(Translation3::new(3.0, 3.0, 1.0), UnitQuaternion::from_euler_angles(0.0, 0.0, 0.3));
        let view: Vec<Vec3> =
            map.iter().chain(&cabinet).map(|p| truth.inverse_transform_point(&(*p).into()).coords).collect();
        let grid = TargetGrid::new(&map, Some(&coverage), &params()).unwrap();
        let peaks = grid.search(&view, &params());
        let best = peaks.first().unwrap();
        let (m, deg) = super::super::geometry::pose_error(&best.pose, &truth);
        // Within the search's resolution: a cell or two, a yaw step (here about 2 deg).
        assert!(m < 0.35 && deg < 3.0, "best peak {m:.2} m {deg:.1} deg off");
        // Without the coverage the four turns tie within the quantisation.
        let blind = TargetGrid::new(&map, None, &params()).unwrap().search(&view, &params());
        let scores: Vec<f64> = blind.iter().map(|p| p.score).collect();
        assert!(scores.len() >= 3 && scores[0] - scores[2] < 0.05, "{scores:?}");
    }
}
