//! Both sides of a registration, prepared as the paper does before aligning:
//!
//! - the robot's map: the ground-near band and everything above the ceiling threshold removed
//!   (both relative to the floor and ceiling estimated from the map itself), downsampled, with
//!   normals ([`prepare_map`]);
//! - the rig's source: scans over a window placed by their LIO poses, with points inside given
//!   exclusion boxes (people) and moving points left out, downsampled ([`aggregate_window`]).

use super::carve::seen_through;
use super::free_space::Ray;
use super::geometry::{estimate_normals, Vec3};
use crate::voxel_hash::{key_of, voxel_downsample, KeyMap, VoxelMeans};
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
    /// With the window's rays given, moving points are found by them instead: a voxel (of
    /// `motion_voxel_m`) seen in at most `carve_max_seen` slices of `carve_slice_s` and crossed
    /// by rays at least `carve_min_rays` times in slices in which nothing was seen in it held
    /// something that left ([`seen_through`]; `carve_min_rays` 0: the slices above decide even
    /// then).
    pub carve_min_rays: u32,
    pub carve_max_seen: u32,
    pub carve_slice_s: f64,
    /// The first metres of a ray do not count as crossed (the rig itself, its operator).
    pub carve_near_m: f64,
}

impl Default for WindowConfig {
    fn default() -> Self {
        Self {
            voxel_m: 0.1,
            slices: 5,
            min_slices: 2,
            motion_voxel_m: 0.3,
            carve_min_rays: 2,
            carve_max_seen: 2,
            carve_slice_s: 0.5,
            carve_near_m: 0.5,
        }
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
/// (its LIO pose, into the odometry frame), leaving out points the pose lookup cannot place, then
/// [`filter_window`].
pub fn aggregate_window(
    points: &[(u64, Vec3)],
    pose_at: impl Fn(u64) -> Option<Isometry3<f64>>,
    frame: &Isometry3<f64>,
    boxes: &[ExclusionBox],
    c: &WindowConfig,
) -> (Vec<Vec3>, AggregateStats) {
    let t0 = points.iter().map(|(t, _)| *t).min().unwrap_or(0);
    // Kept in f64 here (a caller's points may sit exactly on voxel or slice boundaries).
    let placed: Vec<(u32, Vec3)> = points
        .iter()
        .filter_map(|(t, p)| {
            let t_us = u32::try_from((t - t0) / 1000).unwrap_or(u32::MAX);
            Some((t_us, (pose_at(*t)? * Point3::from(*p)).coords))
        })
        .collect();
    let (out, stats) = filter_window(&placed, &[], frame, boxes, c);
    (out, AggregateStats { points_in: points.len(), ..stats })
}

/// A point of a window placed in the odometry frame: its time in microseconds from any start the
/// caller picks (time differences are all that count) and where it is.
pub trait Placed {
    fn t_us(&self) -> u32;
    fn xyz(&self) -> Vec3;
}

impl Placed for (u32, Vec3) {
    fn t_us(&self) -> u32 {
        self.0
    }

    fn xyz(&self) -> Vec3 {
        self.1
    }
}

/// A [`Placed`] point kept small (a rig's 10 s window holds millions): f32, as a window spans
/// metres, not kilometres.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlacedPoint {
    pub t_us: u32,
    pub xyz: [f32; 3],
}

impl PlacedPoint {
    pub fn new(t_us: u64, p: &Vec3) -> Self {
        Self { t_us: u32::try_from(t_us).unwrap_or(u32::MAX), xyz: [p.x as f32, p.y as f32, p.z as f32] }
    }
}

impl Placed for PlacedPoint {
    fn t_us(&self) -> u32 {
        self.t_us
    }

    fn xyz(&self) -> Vec3 {
        Vec3::new(f64::from(self.xyz[0]), f64::from(self.xyz[1]), f64::from(self.xyz[2]))
    }
}

/// Points of a window already placed in the odometry frame: those inside
/// `boxes` and the moving ones left out, the rest moved by `frame` (e.g. the inverse pose at the
/// window's end) and reduced to `voxel_m`. Moving points are those in voxels the window's `rays`
/// (with their firing times) saw through ([`seen_through`]) or, without rays, those of voxels
/// seen in fewer than `min_slices` time slices. `boxes` and `rays` are in the odometry frame too.
pub fn filter_window<P: Placed>(
    placed: &[P],
    rays: &[(u32, Ray)],
    frame: &Isometry3<f64>,
    boxes: &[ExclusionBox],
    c: &WindowConfig,
) -> (Vec<Vec3>, AggregateStats) {
    let mut stats = AggregateStats { points_in: placed.len(), ..AggregateStats::default() };
    let (t0, t1) = placed.iter().fold((u32::MAX, 0), |(a, b), p| (a.min(p.t_us()), b.max(p.t_us())));
    let span = u64::from(t1.saturating_sub(t0)).max(1);
    let carve = !rays.is_empty() && c.carve_min_rays > 0;
    let slices = if carve {
        ((span as f64 * 1e-6 / c.carve_slice_s.max(1e-3)).ceil() as usize).clamp(1, 64)
    } else {
        c.slices.max(1)
    };
    let slice_of = |t: u32| ((u64::from(t.saturating_sub(t0)) * slices as u64 / (span + 1)) as usize).min(slices - 1);
    let outside = |q: &Vec3| !boxes.iter().any(|b| b.contains(q));
    let inv = 1.0 / c.motion_voxel_m.max(1e-3);
    // Which slices saw a point in each voxel (a bit set: up to 64 slices).
    let mut seen: KeyMap<u64> = KeyMap::default();
    for p in placed {
        let q = p.xyz();
        if outside(&q) {
            *seen.entry(key_of(&q, inv)).or_insert(0) |= 1u64 << slice_of(p.t_us()).min(63);
        } else {
            stats.excluded_boxes += 1;
        }
    }
    let through = if carve {
        let timed: Vec<(u32, Ray)> = rays.iter().map(|(t, r)| (slice_of(*t) as u32, *r)).collect();
        seen_through(&timed, &seen, c.motion_voxel_m, c.carve_near_m, c.carve_min_rays, c.carve_max_seen)
    } else {
        KeyMap::default()
    };
    let need = c.min_slices.clamp(1, slices.min(64)) as u32;
    let still = |q: &Vec3| {
        if carve {
            !through.contains_key(&key_of(q, inv))
        } else {
            seen.get(&key_of(q, inv)).is_some_and(|m| m.count_ones() >= need)
        }
    };
    // Reduced as they come: a window's kept points need no buffer of their own.
    let mut kept = VoxelMeans::new(c.voxel_m);
    for p in placed {
        let q = p.xyz();
        if !outside(&q) {
            continue;
        }
        if still(&q) {
            kept.add(&(frame * Point3::from(q)).coords);
        } else {
            stats.excluded_moving += 1;
        }
    }
    let out = kept.finish();
    stats.points_out = out.len();
    (out, stats)
}
