//! What lies just above and just below a cluster as the sensor sees it: the window's nearest
//! return per direction (a range image in the sensor's frame at the window's stamp).
//!
//! Someone seen over a table, past a door's edge or behind a row of boxes shows a top edge with
//! the room beyond it (free) and a bottom edge where something nearer hides the rest of them. A
//! wall strip, a door jamb or a piece of furniture seen through a gap has its edges where the
//! gap's own edges are, or continues into what is above and below it at the same range.

use super::fov::{az_el_deg, in_sensor_frame};
use super::WindowPoint;
use nalgebra::{Isometry3, Vector3};

/// Cell size of the image, deg (8 cm at 9 m; about three returns per cell over a 0.3 s window).
const CELL_DEG: f64 = 0.5;
/// How many cells above the top (below the bottom) of each column are looked at.
const LOOK_CELLS: usize = 3;
/// A return this much farther than the cluster's edge is the room beyond it; this much nearer,
/// something in front of it.
const GAP_M: f32 = 0.5;

/// How a cluster's top and bottom edges meet what is around them.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Silhouette {
    /// Of the azimuth columns with a return just above the cluster, the share where that return
    /// is farther (the top edge is the cluster's own).
    pub top_free: f64,
    /// Of the columns with a return just below, the share where it is nearer (hidden below).
    pub bottom_hidden: f64,
    /// Columns with a return above, and below.
    pub top_columns: usize,
    pub bottom_columns: usize,
}

/// One azimuth column of a cluster: its highest and lowest elevation cell, each with the range
/// of the cluster's nearest return there.
struct Column {
    az: usize,
    top: (usize, f32),
    bottom: (usize, f32),
}

/// The window's nearest return per (azimuth, elevation) cell around one cluster, in the
/// sensor's frame at the window's stamp (only points in a cone around the cluster are placed:
/// a full image of a window cost milliseconds).
pub struct RangeImage {
    sensor_t_world: Isometry3<f64>,
    /// Azimuth of the cluster's mean direction, deg; cells count from `az0 - half width`.
    az0_deg: f64,
    az_from_deg: f64,
    el_from_deg: f64,
    az_cells: usize,
    el_cells: usize,
    nearest_m: Vec<f32>,
}

impl RangeImage {
    /// The image around the cluster made of `cluster` (indices into `points`); `None` when none
    /// of its points has a direction.
    pub fn around(points: &[WindowPoint], world_t_sensor: &Isometry3<f64>, cluster: &[u32]) -> Option<Self> {
        let sensor_t_world = world_t_sensor.inverse();
        let dirs: Vec<Vector3<f64>> = cluster
            .iter()
            .filter_map(|&i| points.get(i as usize))
            .filter_map(|p| in_sensor_frame(&sensor_t_world, p))
            .map(|d| d.normalize())
            .collect();
        let mean = dirs.iter().sum::<Vector3<f64>>().try_normalize(1e-9)?;
        let spread_deg = dirs.iter().map(|d| d.dot(&mean).clamp(-1.0, 1.0).acos().to_degrees()).fold(0.0, f64::max);
        let margin_deg = (LOOK_CELLS + 2) as f64 * CELL_DEG;
        let half_deg = (spread_deg + margin_deg).min(89.0);
        let mut image = Self {
            sensor_t_world,
            az0_deg: mean.y.atan2(mean.x).to_degrees(),
            az_from_deg: -half_deg,
            el_from_deg: (mean.z.atan2(mean.xy().norm()).to_degrees() - half_deg).max(-90.0),
            az_cells: (2.0 * half_deg / CELL_DEG) as usize + 1,
            el_cells: (2.0 * half_deg / CELL_DEG) as usize + 1,
            nearest_m: Vec::new(),
        };
        // Azimuths widen towards the poles: the cone test is only a filter, cells decide.
        image.nearest_m = vec![f32::INFINITY; image.az_cells * image.el_cells];
        let cos_half = half_deg.to_radians().cos();
        for p in points {
            let Some(d) = in_sensor_frame(&image.sensor_t_world, p) else { continue };
            let range = d.norm();
            if d.dot(&mean) < range * cos_half {
                continue;
            }
            if let Some((a, e)) = image.cell_of(&d) {
                if let Some(n) = image.nearest_m.get_mut(a * image.el_cells + e) {
                    *n = n.min(range as f32);
                }
            }
        }
        Some(image)
    }

    fn cell_of(&self, d: &Vector3<f64>) -> Option<(usize, usize)> {
        let (az, el) = az_el_deg(d)?;
        let az = (az - self.az0_deg + 540.0).rem_euclid(360.0) - 180.0;
        let a = (az - self.az_from_deg) / CELL_DEG;
        let e = (el - self.el_from_deg) / CELL_DEG;
        let inside = (0.0..self.az_cells as f64).contains(&a) && (0.0..self.el_cells as f64).contains(&e);
        inside.then_some((a as usize, e as usize))
    }

    /// (azimuth cell, elevation cell) and range of a point.
    fn angles(&self, p: &WindowPoint) -> Option<(usize, usize, f32)> {
        let d = in_sensor_frame(&self.sensor_t_world, p)?;
        self.cell_of(&d).map(|(a, e)| (a, e, d.norm() as f32))
    }

    fn nearest(&self, az_cell: usize, el_cells: impl Iterator<Item = usize>) -> Option<f32> {
        el_cells
            .filter(|&e| e < self.el_cells)
            .filter_map(|e| self.nearest_m.get(az_cell * self.el_cells + e).copied())
            .filter(|r| r.is_finite())
            .reduce(f32::min)
    }

    /// The top and bottom edges of the cluster made of `indices` (into `points`).
    pub fn silhouette(&self, points: &[WindowPoint], indices: impl Iterator<Item = u32>) -> Silhouette {
        let mut columns: Vec<Column> = Vec::new();
        for p in indices.filter_map(|i| points.get(i as usize)) {
            let Some((az, el, r)) = self.angles(p) else { continue };
            match columns.iter_mut().find(|c| c.az == az) {
                Some(c) => {
                    if el > c.top.0 || (el == c.top.0 && r < c.top.1) {
                        c.top = (el, r);
                    }
                    if el < c.bottom.0 || (el == c.bottom.0 && r < c.bottom.1) {
                        c.bottom = (el, r);
                    }
                }
                None => columns.push(Column { az, top: (el, r), bottom: (el, r) }),
            }
        }
        let mut s = Silhouette::default();
        let (mut free, mut hidden) = (0usize, 0usize);
        for c in &columns {
            let ((top, top_r), (bottom, bottom_r)) = (c.top, c.bottom);
            if let Some(above) = self.nearest(c.az, top + 1..=top + LOOK_CELLS) {
                s.top_columns += 1;
                free += usize::from(above > top_r + GAP_M);
            }
            if let Some(below) = self.nearest(c.az, bottom.saturating_sub(LOOK_CELLS)..bottom) {
                s.bottom_columns += 1;
                hidden += usize::from(below < bottom_r - GAP_M);
            }
        }
        s.top_free = free as f64 / s.top_columns.max(1) as f64;
        s.bottom_hidden = hidden as f64 / s.bottom_columns.max(1) as f64;
        s
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    fn pt(x: f64, y: f64, z: f64) -> WindowPoint {
        WindowPoint { x_m: x as f32, y_m: y as f32, z_m: z as f32, t_ns: 0 }
    }

    fn plane(out: &mut Vec<WindowPoint>, x: f64, y: [f64; 2], z: [f64; 2]) -> Vec<u32> {
        let mut idx = Vec::new();
        let mut v = y[0];
        while v <= y[1] {
            let mut h = z[0];
            while h <= z[1] {
                out.push(pt(x, v, h));
                idx.push((out.len() - 1) as u32);
                h += 0.02;
            }
            v += 0.02;
        }
        idx
    }

    /// A sensor at 0.45 m; a wall 12 m ahead; boxes 6 m ahead up to 0.9 m; a torso 9 m ahead
    /// from 0.9 to 1.5 m behind them; and a strip of the wall beside it, clear of the boxes.
    #[test]
    fn a_torso_over_boxes_has_a_free_top_and_a_hidden_bottom_and_a_wall_strip_not() {
        let sensor = Isometry3::translation(0.0, 0.0, 0.45);
        let mut points = Vec::new();
        plane(&mut points, 12.0, [-3.0, 3.0], [0.0, 2.8]);
        plane(&mut points, 6.0, [-1.0, 1.0], [0.0, 0.6]);
        let torso = plane(&mut points, 9.0, [-0.15, 0.15], [0.9, 1.5]);
        let strip: Vec<u32> = (0..points.len() as u32)
            .filter(|&i| points[i as usize].x_m == 12.0 && (1.0..1.3).contains(&points[i as usize].y_m))
            .filter(|&i| (1.8..2.3).contains(&points[i as usize].z_m))
            .collect();
        let image = RangeImage::around(&points, &sensor, &torso).unwrap();
        let s = image.silhouette(&points, torso.iter().copied());
        assert!(s.top_free > 0.9 && s.bottom_hidden > 0.9, "{s:?}");
        assert!(s.top_columns >= 3 && s.bottom_columns >= 3, "{s:?}");
        let image = RangeImage::around(&points, &sensor, &strip).unwrap();
        let w = image.silhouette(&points, strip.iter().copied());
        assert!(w.top_free < 0.1 && w.bottom_hidden < 0.1, "{w:?}");
    }

    #[test]
    fn nothing_around_and_garbage_give_no_columns() {
        let points = vec![pt(3.0, 0.0, 1.0), pt(f64::NAN, 0.0, 0.0), pt(1e30, 0.0, -1e30), pt(0.0, 0.0, 0.45)];
        let sensor = Isometry3::translation(0.0, 0.0, 0.45);
        let image = RangeImage::around(&points, &sensor, &[0, 1, 2, 3, 9]).unwrap();
        let s = image.silhouette(&points, 0..10);
        assert_eq!((s.top_columns, s.bottom_columns), (0, 0));
        assert_eq!((s.top_free, s.bottom_hidden), (0.0, 0.0));
        assert!(RangeImage::around(&points, &sensor, &[1, 3, 7]).is_none(), "no direction");
    }
}
