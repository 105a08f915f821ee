//! Both sides of a registration, prepared as the paper does before aligning:
//!
//! - the robot's map: the ground-near band and everything above the ceiling threshold removed
//!   (both relative to the floor and ceiling estimated from the map itself), downsampled, with
//!   normals ([`prepare_map`]);
//! - the rig's source: scans over a window placed by their LIO poses, with points inside given
//!   exclusion boxes (people) and moving points left out, downsampled ([`aggregate_window`]).

use super::geometry::{estimate_normals, key_of, voxel_downsample, KeyMap, Vec3};
use crate::PipelineError;
use nalgebra::{Isometry3, Point3};
use serde::{Deserialize, Serialize};

/// Map preparation settings (the `[map]` keys of the docs; all have defaults).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MapPrepConfig {
    /// Voxel size the map is reduced to (also the grid of the normals used to find the floor).
    pub voxel_m: f64,
    /// Normals: radius and neighbour count.
    pub normal_radius_m: f64,
    pub normal_neighbours: usize,
    /// A point is on a horizontal surface when |n_z| is at least this.
    pub horizontal_min_nz: f64,
    /// z histogram bin of the horizontal-surface points.
    pub histogram_bin_m: f64,
    /// A bin is a floor/ceiling candidate when it holds at least this share of the fullest bin;
    /// the floor is the lowest candidate, the ceiling the highest (tables and shelves are
    /// smaller than the floor and ceiling of the space they stand in).
    pub peak_share: f64,
    /// Points below floor + this are removed (the ground-near band).
    pub ground_band_m: f64,
    /// Points above ceiling - this are removed.
    pub ceiling_band_m: f64,
    /// Instead of removing the bands entirely, keep them thinned to this voxel size (0: remove).
    /// Floor and ceiling then no longer dominate the point count but still constrain height,
    /// roll and pitch (without them a room's degeneracy index falls about tenfold).
    pub band_keep_voxel_m: f64,
}

impl Default for MapPrepConfig {
    fn default() -> Self {
        Self {
            voxel_m: 0.1,
            normal_radius_m: 0.5,
            normal_neighbours: 12,
            horizontal_min_nz: 0.9,
            histogram_bin_m: 0.05,
            peak_share: 0.3,
            ground_band_m: 0.3,
            ceiling_band_m: 0.3,
            band_keep_voxel_m: 0.5,
        }
    }
}

/// A prepared map: reduced points with their normals, and what was found and removed.
#[derive(Clone, Debug)]
pub struct PreparedMap {
    pub points: Vec<Vec3>,
    pub normals: Vec<Option<Vec3>>,
    /// Estimated floor and ceiling heights (m, map frame; z up).
    pub floor_z_m: f64,
    pub ceiling_z_m: f64,
    /// Reduced points removed as ground band / above the ceiling threshold.
    pub removed_ground: usize,
    pub removed_ceiling: usize,
}

/// Estimates floor and ceiling heights from the z histogram of points on horizontal surfaces
/// (|n_z| >= `horizontal_min_nz`); `None` when fewer than two histogram peaks are found.
pub fn floor_and_ceiling(points: &[Vec3], normals: &[Option<Vec3>], c: &MapPrepConfig) -> Option<(f64, f64)> {
    let zs: Vec<f64> = points
        .iter()
        .zip(normals)
        .filter_map(|(p, n)| n.filter(|n| n.z.abs() >= c.horizontal_min_nz).map(|_| p.z))
        .filter(|z| z.is_finite())
        .collect();
    let lo = zs.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = zs.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    if !(lo.is_finite() && hi.is_finite()) || c.histogram_bin_m <= 0.0 {
        return None;
    }
    // Heights beyond 1 km are not a building: refuse rather than allocate a huge histogram.
    let bins = ((hi - lo) / c.histogram_bin_m).floor() as usize + 1;
    if bins > 20_000 {
        return None;
    }
    let mut hist = vec![0u32; bins];
    for z in &zs {
        let i = (((z - lo) / c.histogram_bin_m).floor() as usize).min(bins - 1);
        if let Some(h) = hist.get_mut(i) {
            *h += 1;
        }
    }
    let max = hist.iter().copied().max().unwrap_or(0);
    let threshold = (f64::from(max) * c.peak_share).max(1.0);
    let is_peak = |i: usize| hist.get(i).is_some_and(|&h| f64::from(h) >= threshold);
    let first = (0..bins).find(|&i| is_peak(i))?;
    let last = (0..bins).rev().find(|&i| is_peak(i))?;
    if last <= first {
        return None;
    }
    let centre = |i: usize| lo + (i as f64 + 0.5) * c.histogram_bin_m;
    Some((centre(first), centre(last)))
}

/// The robot's map for registration: reduced, floor band and ceiling removed, with normals.
pub fn prepare_map(points: &[Vec3], c: &MapPrepConfig) -> Result<PreparedMap, PipelineError> {
    let reduced = voxel_downsample(points, c.voxel_m);
    let normals = estimate_normals(&reduced, c.normal_radius_m, c.normal_neighbours);
    let (floor_z_m, ceiling_z_m) = floor_and_ceiling(&reduced, &normals, c).ok_or_else(|| PipelineError::BadFile {
        format: "map",
        reason: "no floor and ceiling found (too few horizontal surfaces)".into(),
    })?;
    let (lo, hi) = (floor_z_m + c.ground_band_m, ceiling_z_m - c.ceiling_band_m);
    let mut out = PreparedMap {
        points: Vec::with_capacity(reduced.len()),
        normals: Vec::with_capacity(reduced.len()),
        floor_z_m,
        ceiling_z_m,
        removed_ground: 0,
        removed_ceiling: 0,
    };
    let mut band = Vec::new();
    for (p, n) in reduced.iter().zip(normals) {
        if p.z < lo {
            out.removed_ground += 1;
            band.push(*p);
        } else if p.z > hi {
            out.removed_ceiling += 1;
            band.push(*p);
        } else {
            out.points.push(*p);
            out.normals.push(n);
        }
    }
    if c.band_keep_voxel_m > 0.0 {
        let thinned = voxel_downsample(&band, c.band_keep_voxel_m);
        // Floor and ceiling are planes: their normal is vertical.
        out.normals.extend(thinned.iter().map(|_| Some(Vec3::new(0.0, 0.0, 1.0))));
        out.points.extend(thinned);
    }
    Ok(out)
}

/// A box to leave out (a detected person): centre, size (length along its heading, width,
/// height) and heading (rad about +z), in the frame the scans are placed into.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ExclusionBox {
    pub centre: Vec3,
    pub size_m: Vec3,
    pub yaw_rad: f64,
}

impl ExclusionBox {
    pub fn contains(&self, p: &Vec3) -> bool {
        let d = p - self.centre;
        let (s, c) = self.yaw_rad.sin_cos();
        // Into the box's own axes.
        let local = Vec3::new(c * d.x + s * d.y, -s * d.x + c * d.y, d.z);
        local.x.abs() <= self.size_m.x * 0.5
            && local.y.abs() <= self.size_m.y * 0.5
            && local.z.abs() <= self.size_m.z * 0.5
    }
}

/// Window aggregation settings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct WindowConfig {
    /// Voxel size of the aggregated source.
    pub voxel_m: f64,
    /// Moving points: the window is cut into this many time slices; a voxel (of
    /// `motion_voxel_m`) must hold points from at least `min_slices` of them to be kept. A
    /// walking person crosses a 0.3 m voxel in a fraction of a slice; a wall stays.
    pub slices: usize,
    pub min_slices: usize,
    pub motion_voxel_m: f64,
}

impl Default for WindowConfig {
    fn default() -> Self {
        Self { voxel_m: 0.1, slices: 5, min_slices: 2, motion_voxel_m: 0.3 }
    }
}

/// What the aggregation kept and left out.
#[derive(Clone, Debug, Default)]
pub struct AggregateStats {
    pub points_in: usize,
    pub excluded_boxes: usize,
    pub excluded_moving: usize,
    pub points_out: usize,
}

/// The rig's source: every `(t_ns, point in the LiDAR frame)` of the window moved by `pose_at(t)`
/// (its LIO pose, into the odometry frame) and then by `frame` (e.g. the inverse pose at the
/// window's end), leaving out points the pose lookup cannot place, points inside `boxes` (given in
/// the odometry frame) and points of voxels seen in fewer than `min_slices` time slices; then
/// reduced to `voxel_m`.
pub fn aggregate_window(
    points: &[(u64, Vec3)],
    pose_at: impl Fn(u64) -> Option<Isometry3<f64>>,
    frame: &Isometry3<f64>,
    boxes: &[ExclusionBox],
    c: &WindowConfig,
) -> (Vec<Vec3>, AggregateStats) {
    let mut stats = AggregateStats { points_in: points.len(), ..AggregateStats::default() };
    let (t0, t1) = points.iter().fold((u64::MAX, 0), |(a, b), (t, _)| (a.min(*t), b.max(*t)));
    let span = (t1.saturating_sub(t0)).max(1);
    let slices = c.slices.max(1);
    let mut placed = Vec::with_capacity(points.len());
    for (t, p) in points {
        let Some(pose) = pose_at(*t) else { continue };
        let q = (pose * Point3::from(*p)).coords;
        if boxes.iter().any(|b| b.contains(&q)) {
            stats.excluded_boxes += 1;
            continue;
        }
        let slice = ((t - t0) as u128 * slices as u128 / (span as u128 + 1)) as usize;
        placed.push((q, slice.min(slices - 1)));
    }
    // Which slices saw each voxel (a bit set: up to 64 slices).
    let inv = 1.0 / c.motion_voxel_m.max(1e-3);
    let mut seen: KeyMap<u64> = KeyMap::default();
    for (q, s) in &placed {
        *seen.entry(key_of(q, inv)).or_insert(0) |= 1u64 << (*s).min(63);
    }
    let need = c.min_slices.clamp(1, slices.min(64)) as u32;
    let mut kept = Vec::with_capacity(placed.len());
    for (q, _) in &placed {
        if seen.get(&key_of(q, inv)).is_some_and(|m| m.count_ones() >= need) {
            kept.push((frame * Point3::from(*q)).coords);
        } else {
            stats.excluded_moving += 1;
        }
    }
    let out = voxel_downsample(&kept, c.voxel_m);
    stats.points_out = out.len();
    (out, stats)
}
