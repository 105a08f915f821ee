//! Free-space check of a registration. A pose can fit the surfaces well and still be wrong: a
//! room that matches part of another (the auditorium's lobby against the hall) leaves every
//! point on a surface of the map. What such a pose cannot hide is that the rig's rays then pass
//! through the map's walls and seats on their way to the points they hit. At the right pose a
//! ray crosses no mapped surface before its end.

use super::geometry::Vec3;
use crate::timing::Stopwatch;
use crate::voxel_hash::{key_of, KeyMap, NEIGHBOURS};
use nalgebra::{Isometry3, Point3};
use serde::Serialize;

/// One LiDAR ray of the source: from the sensor's position when it fired to the point it hit,
/// both in the source's frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ray {
    pub origin: Vec3,
    pub end: Vec3,
}

/// What the check found for one pose.
#[derive(Clone, Debug, Default, Serialize)]
pub struct FreeSpace {
    /// Rays long enough to be checked.
    pub rays: usize,
    /// Rays that crossed a mapped surface and ended more than the end margin behind it.
    pub blocked: usize,
    /// `blocked / rays` (0 when no ray was checked).
    pub blocked_ratio: f64,
    /// Time the check took.
    pub ms: f64,
}

/// How rays are walked.
#[derive(Clone, Copy, Debug)]
pub struct RayParams {
    /// Rays checked, at most (taken evenly through those given).
    pub max_rays: usize,
    /// Distance between samples along a ray.
    pub step_m: f64,
    /// The first this many metres of a ray are not checked (the rig's own body, the operator).
    pub near_m: f64,
    /// A crossing counts only when the ray ends more than this behind the crossed surface's
    /// plane: a ray that ends on (or just behind) the surface it crossed hit that surface, seen
    /// through registration error and map noise, and a ray grazing the floor towards a far
    /// point crosses its bumps with the end still on the floor.
    pub end_margin_m: f64,
    /// The clock of [`FreeSpace::ms`].
    pub stopwatch: Stopwatch,
}

/// A small plane patch of the map: a point and its unit normal.
#[derive(Clone, Copy, Debug)]
struct Surfel {
    centre: Vec3,
    normal: Vec3,
}

/// The map's surfels, bucketed by voxel.
pub struct SurfelGrid {
    inv_cell_m: f64,
    cell_m: f64,
    cells: KeyMap<Vec<Surfel>>,
    /// With [`SurfelGrid::with_points`]: the map's points, bucketed by `near_m`, and that
    /// distance. A crossing counts only this close to a point: a surfel stands for a cell-wide
    /// disc, which the ends of a rack's posts and the gaps between its loads are not.
    points: Option<(KeyMap<Vec<Vec3>>, f64)>,
}

impl SurfelGrid {
    /// Surfels of the points that have a normal (corners and scatter have none and block nothing).
    pub fn new(points: &[Vec3], normals: &[Option<Vec3>], cell_m: f64) -> Self {
        let cell_m = cell_m.max(1e-3);
        let inv_cell_m = 1.0 / cell_m;
        let mut cells: KeyMap<Vec<Surfel>> = KeyMap::default();
        for (p, n) in points.iter().zip(normals) {
            if let Some(n) = n {
                cells.entry(key_of(p, inv_cell_m)).or_default().push(Surfel { centre: *p, normal: *n });
            }
        }
        Self { inv_cell_m, cell_m, cells, points: None }
    }

    /// A crossing counts only within `near_m` of one of `points` (the map at a finer voxel than
    /// the surfels'); a `near_m` that is not positive leaves the surfels alone to decide.
    pub fn with_points(mut self, points: &[Vec3], near_m: f64) -> Self {
        if near_m > 0.0 {
            let mut cells: KeyMap<Vec<Vec3>> = KeyMap::default();
            for p in points {
                cells.entry(key_of(p, 1.0 / near_m)).or_default().push(*p);
            }
            self.points = Some((cells, near_m));
        }
        self
    }

    /// Whether a map point lies within the set distance of `at` (always, without points).
    fn on_a_point(&self, at: &Vec3) -> bool {
        let Some((cells, near_m)) = &self.points else { return true };
        let (x, y, z) = key_of(at, 1.0 / near_m);
        let near2 = near_m * near_m;
        std::iter::once((0, 0, 0)).chain(NEIGHBOURS).any(|(dx, dy, dz)| {
            cells.get(&(x + dx, y + dy, z + dz)).is_some_and(|ps| ps.iter().any(|p| (p - at).norm_squared() <= near2))
        })
    }

    /// Whether the segment `a`-`b` (around sample `at`) passes through a surfel of `at`'s voxel
    /// (it changes sides of the surfel's plane within a cell's size of the surfel's centre) with
    /// the ray's `end` more than `margin_m` beyond that plane.
    fn crosses(&self, at: &Vec3, a: &Vec3, b: &Vec3, end: &Vec3, margin_m: f64) -> bool {
        let Some(surfels) = self.cells.get(&key_of(at, self.inv_cell_m)) else { return false };
        surfels.iter().any(|s| {
            let da = (a - s.centre).dot(&s.normal);
            let db = (b - s.centre).dot(&s.normal);
            if da * db >= 0.0 {
                return false;
            }
            let crossing = a + (b - a) * (da / (da - db));
            let behind_m = -(end - s.centre).dot(&s.normal) * da.signum();
            behind_m > margin_m
                && (crossing - s.centre).norm_squared() <= self.cell_m * self.cell_m
                && self.on_a_point(&crossing)
        })
    }

    /// Walks every checked ray, moved by `pose` (source into map), and counts those that cross
    /// a surface before their end.
    pub fn check(&self, rays: &[Ray], pose: &Isometry3<f64>, p: &RayParams) -> FreeSpace {
        let t0 = p.stopwatch.start();
        let step = p.step_m.max(0.01);
        let stride =
            if p.max_rays > 0 && rays.len() > p.max_rays { rays.len() as f64 / p.max_rays as f64 } else { 1.0 };
        let count = if stride > 1.0 { p.max_rays } else { rays.len() };
        let mut out = FreeSpace::default();
        for i in 0..count {
            let Some(ray) = rays.get((i as f64 * stride) as usize) else { continue };
            let o = (pose * Point3::from(ray.origin)).coords;
            let e = (pose * Point3::from(ray.end)).coords;
            let length = (e - o).norm();
            let last = length - p.end_margin_m;
            // NaN (a ray of non-finite points) fails this too.
            if last.partial_cmp(&(p.near_m + step)) != Some(std::cmp::Ordering::Greater) {
                continue;
            }
            out.rays += 1;
            let dir = (e - o) / length;
            let mut s = p.near_m + step;
            while s < last {
                let at = o + dir * s;
                if self.crosses(&at, &(at - dir * step), &(at + dir * step), &e, p.end_margin_m) {
                    out.blocked += 1;
                    break;
                }
                s += step;
            }
        }
        out.blocked_ratio = if out.rays > 0 { out.blocked as f64 / out.rays as f64 } else { 0.0 };
        out.ms = t0.ms();
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::align::pose_xyz_yaw;

    /// A wall at x = 5 (normal along x), 4 m wide and 3 m tall, in 0.25 m surfels.
    fn wall(x_m: f64) -> (Vec<Vec3>, Vec<Option<Vec3>>) {
        let mut points = Vec::new();
        for iy in -8..8 {
            for iz in 0..12 {
                points.push(Vec3::new(x_m, f64::from(iy) * 0.25 + 0.125, f64::from(iz) * 0.25 + 0.125));
            }
        }
        let normals = points.iter().map(|_| Some(Vec3::new(-1.0, 0.0, 0.0))).collect();
        (points, normals)
    }

    fn params() -> RayParams {
        RayParams { max_rays: 100, step_m: 0.1, near_m: 0.5, end_margin_m: 0.3, stopwatch: Stopwatch::Wall }
    }

    #[test]
    fn rays_that_end_on_the_wall_pass_and_rays_through_it_are_blocked() {
        let (points, normals) = wall(5.0);
        let grid = SurfelGrid::new(&points, &normals, 0.25);
        let origin = Vec3::new(0.0, 0.0, 1.5);
        // Ending on the wall (a few centimetres off, as registration leaves them).
        let on: Vec<Ray> = (-5..=5).map(|k| Ray { origin, end: Vec3::new(5.03, f64::from(k) * 0.3, 1.0) }).collect();
        let r = grid.check(&on, &Isometry3::identity(), &params());
        assert_eq!((r.rays, r.blocked), (11, 0));
        // The same rays with the rig placed 3 m farther back end 3 m past the wall's near side:
        // moved by a pose that puts the wall between the origin and the ends.
        let wrong = pose_xyz_yaw(3.0, 0.0, 0.0, 0.0);
        let r = grid.check(&on, &wrong, &params());
        assert_eq!((r.rays, r.blocked), (11, 11));
        assert!((r.blocked_ratio - 1.0).abs() < 1e-12);
    }

    #[test]
    fn a_ray_grazing_along_a_wall_is_not_blocked() {
        let (points, normals) = wall(5.0);
        let grid = SurfelGrid::new(&points, &normals, 0.25);
        // From beside the wall's plane, along it, ending on its far edge.
        let ray = Ray { origin: Vec3::new(4.9, -6.0, 1.5), end: Vec3::new(4.98, 1.9, 1.5) };
        let r = grid.check(&[ray], &Isometry3::identity(), &params());
        assert_eq!((r.rays, r.blocked), (1, 0));
        // Crossing the wall at a shallow angle but ending 10 cm behind it (the wall's bumps, a
        // far floor point): the end is still on the surface.
        let ray = Ray { origin: Vec3::new(4.8, -6.0, 1.5), end: Vec3::new(5.1, 1.9, 1.5) };
        let r = grid.check(&[ray], &Isometry3::identity(), &params());
        assert_eq!((r.rays, r.blocked), (1, 0));
    }

    #[test]
    fn short_rays_and_no_rays_are_not_counted() {
        let (points, normals) = wall(5.0);
        let grid = SurfelGrid::new(&points, &normals, 0.25);
        let short = Ray { origin: Vec3::zeros(), end: Vec3::new(0.8, 0.0, 0.0) };
        let r = grid.check(&[short], &Isometry3::identity(), &params());
        assert_eq!((r.rays, r.blocked, r.blocked_ratio), (0, 0, 0.0));
        let r = grid.check(&[], &Isometry3::identity(), &params());
        assert_eq!(r.rays, 0);
        let nan = Ray { origin: Vec3::zeros(), end: Vec3::new(f64::NAN, 1.0, 1.0) };
        let r = grid.check(&[nan], &Isometry3::identity(), &params());
        assert_eq!((r.rays, r.blocked), (0, 0));
    }

    #[test]
    fn many_rays_are_thinned_to_the_limit() {
        let (points, normals) = wall(5.0);
        let grid = SurfelGrid::new(&points, &normals, 0.25);
        let rays: Vec<Ray> = (0..1000)
            .map(|k| Ray { origin: Vec3::zeros(), end: Vec3::new(8.0, f64::from(k % 10) * 0.1, 1.0) })
            .collect();
        let r = grid.check(&rays, &Isometry3::identity(), &params());
        assert_eq!((r.rays, r.blocked), (100, 100));
    }

    /// Posts 4 cm wide every 0.5 m, as the map holds them: a surfel per post (normal along x)
    /// and its points at 2 cm.
    fn posts(x_m: f64) -> (Vec<Vec3>, Vec<Option<Vec3>>, Vec<Vec3>) {
        let centres: Vec<Vec3> = (-4..4).map(|k| Vec3::new(x_m, f64::from(k) * 0.5 + 0.06, 1.125)).collect();
        let normals = centres.iter().map(|_| Some(Vec3::new(-1.0, 0.0, 0.0))).collect();
        let fine = centres
            .iter()
            .flat_map(|c| {
                (-1..=1).flat_map(move |dy| {
                    (-12..=12).map(move |dz| c + Vec3::new(0.0, f64::from(dy) * 0.02, f64::from(dz) * 0.02))
                })
            })
            .collect();
        (centres, normals, fine)
    }

    #[test]
    fn a_ray_through_the_gap_beside_a_post_is_blocked_only_without_the_maps_points() {
        let (centres, normals, fine) = posts(5.0);
        // Through the gap 0.12 m beside a post (inside its surfel's disc and cell), to a wall 3 m
        // behind.
        let beside = Ray { origin: Vec3::new(0.0, 0.2, 1.125), end: Vec3::new(8.0, 0.2, 1.125) };
        let surfels_only = SurfelGrid::new(&centres, &normals, 0.25);
        assert_eq!(surfels_only.check(&[beside], &Isometry3::identity(), &params()).blocked, 1);
        let with_points = SurfelGrid::new(&centres, &normals, 0.25).with_points(&fine, 0.06);
        assert_eq!(with_points.check(&[beside], &Isometry3::identity(), &params()).blocked, 0);
        // Through the post itself it is blocked either way; a distance of 0 leaves the surfels
        // alone to decide.
        let through = Ray { origin: Vec3::new(0.0, 0.06, 1.125), end: Vec3::new(8.0, 0.06, 1.125) };
        assert_eq!(with_points.check(&[through], &Isometry3::identity(), &params()).blocked, 1);
        let off = SurfelGrid::new(&centres, &normals, 0.25).with_points(&fine, 0.0);
        assert_eq!(off.check(&[beside], &Isometry3::identity(), &params()).blocked, 1);
    }

    #[test]
    fn a_solid_wall_blocks_as_before_with_the_maps_points() {
        let (points, normals) = wall(5.0);
        // The wall's points at 0.1 m, as the map reduced for NDT holds them. A crossing amid four
        // of them is 0.07 m from each and does not count (about a twentieth of a wall): these
        // rays cross at a row's height.
        let fine: Vec<Vec3> = (-20..20)
            .flat_map(|iy| {
                (0..30).map(move |iz| Vec3::new(5.0, f64::from(iy) * 0.1 + 0.05, f64::from(iz) * 0.1 + 0.05))
            })
            .collect();
        let grid = SurfelGrid::new(&points, &normals, 0.25).with_points(&fine, 0.06);
        let origin = Vec3::new(0.0, 0.0, 1.05);
        let on: Vec<Ray> = (-5..=5).map(|k| Ray { origin, end: Vec3::new(5.03, f64::from(k) * 0.3, 1.05) }).collect();
        assert_eq!(grid.check(&on, &Isometry3::identity(), &params()).blocked, 0);
        assert_eq!(grid.check(&on, &pose_xyz_yaw(3.0, 0.0, 0.0, 0.0), &params()).blocked, 11);
    }
}
