//! The floor and the ceiling of a window, from its z histogram: the floor is the lowest
//! well-filled bin below the sensor, refined by a least-squares plane (a slightly tilted map
//! frame is absorbed); the ceiling is the highest well-filled bin above the sensor and no lower
//! than a ceiling can be, parallel to it.

use super::{DetectConfig, WindowPoint};
use nalgebra::{Matrix3, Vector3};

/// The floor plane `z = a x + b y + c` and, when one was seen, the ceiling's height above it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FloorModel {
    pub a: f64,
    pub b: f64,
    pub c: f64,
    pub ceiling_above_floor_m: Option<f64>,
}

impl FloorModel {
    /// A flat floor at height `z_m` and no ceiling.
    pub fn flat(z_m: f64) -> Self {
        Self { a: 0.0, b: 0.0, c: z_m, ceiling_above_floor_m: None }
    }

    /// Height of a point above the floor.
    pub fn height(&self, x: f64, y: f64, z: f64) -> f64 {
        z - (self.a * x + self.b * y + self.c)
    }
}

/// Largest floor tilt accepted from the plane fit (a steeper fit means a ramp, a wall foot or
/// too few points: the flat peak height is used instead).
const MAX_TILT: f64 = 0.09; // about 5 deg

/// Estimates the floor (and ceiling) of a window; `sensor_z` is the sensor's height in the
/// world. Without points below the sensor the floor is put 10 m under it (nothing is removed).
pub fn estimate_floor(points: &[WindowPoint], sensor_z: f64, cfg: &DetectConfig) -> FloorModel {
    let bin = cfg.floor_bin_m;
    // Histogram over sensor_z +- 20 m: enough for any room, and bounded.
    let lo = sensor_z - 20.0;
    let nbins = (40.0 / bin).ceil() as usize;
    let mut hist = vec![0u32; nbins];
    for p in points {
        // Truncation is the floor here: below zero (and NaN) is out.
        let i = (f64::from(p.z_m) - lo) / bin;
        if i >= 0.0 {
            if let Some(h) = hist.get_mut(i as usize) {
                *h += 1;
            }
        }
    }
    let sensor_bin = (((sensor_z - lo) / bin).floor() as usize).min(nbins);
    let below = hist.get(..sensor_bin.saturating_sub(1)).unwrap_or(&[]);
    let best_below = below.iter().copied().max().unwrap_or(0);
    if best_below == 0 {
        return FloorModel::flat(sensor_z - 10.0);
    }
    let need = (f64::from(best_below) * cfg.floor_min_share).max(1.0);
    let floor_bin = below.iter().position(|&n| f64::from(n) >= need).unwrap_or(0);
    let peak_z = lo + (floor_bin as f64 + 0.5) * bin;
    let mut floor = fit_plane(points, peak_z, 2.0 * bin).unwrap_or(FloorModel::flat(peak_z));
    if let Some(refit) = fit_plane_model(points, &floor, bin) {
        floor = refit;
    }

    // The ceiling: the highest well-filled bin at least 0.3 m above the sensor and at least
    // `ceiling_min_height_m` above the floor.
    let lowest_ceiling_z = (sensor_z + 0.3).max(peak_z + cfg.ceiling_min_height_m);
    let above_from = (((lowest_ceiling_z - lo) / bin).ceil() as usize).min(nbins);
    let above = hist.get(above_from..).unwrap_or(&[]);
    let best_above = above.iter().copied().max().unwrap_or(0);
    if best_above as usize >= cfg.ceiling_min_points {
        let need = f64::from(best_above) * cfg.floor_min_share;
        if let Some(i) = above.iter().rposition(|&n| f64::from(n) >= need) {
            let z = lo + ((above_from + i) as f64 + 0.5) * bin;
            // Median height above the floor plane of the points in that bin's neighbourhood.
            let mut h: Vec<f64> = points
                .iter()
                .filter(|p| (f64::from(p.z_m) - z).abs() < bin)
                .map(|p| floor.height(f64::from(p.x_m), f64::from(p.y_m), f64::from(p.z_m)))
                .collect();
            if !h.is_empty() {
                let mid = h.len() / 2;
                let (_, m, _) = h.select_nth_unstable_by(mid, f64::total_cmp);
                floor.ceiling_above_floor_m = Some(*m);
            }
        }
    }
    floor
}

/// Least-squares plane through the points within `band` of height `z`.
fn fit_plane(points: &[WindowPoint], z: f64, band: f64) -> Option<FloorModel> {
    fit(points.iter().map(|p| p.xyz()).filter(|p| (p.z - z).abs() < band))
}

/// Refit on the points within `band` of an earlier plane.
fn fit_plane_model(points: &[WindowPoint], m: &FloorModel, band: f64) -> Option<FloorModel> {
    fit(points.iter().map(|p| p.xyz()).filter(|p| m.height(p.x, p.y, p.z).abs() < band))
}

fn fit(points: impl Iterator<Item = Vector3<f64>>) -> Option<FloorModel> {
    // Normal equations of z = a x + b y + c, centred for conditioning.
    let pts: Vec<Vector3<f64>> = points.collect();
    if pts.len() < 10 {
        return None;
    }
    let n = pts.len() as f64;
    let mean = pts.iter().sum::<Vector3<f64>>() / n;
    let mut ata = Matrix3::zeros();
    let mut atb = Vector3::zeros();
    for p in &pts {
        let d = p - mean;
        let row = Vector3::new(d.x, d.y, 1.0);
        ata += row * row.transpose();
        atb += row * d.z;
    }
    let sol = ata.lu().solve(&atb)?;
    let (a, b) = (sol.x, sol.y);
    if !(a.is_finite() && b.is_finite()) || a.hypot(b) > MAX_TILT {
        return Some(FloorModel::flat(mean.z));
    }
    let c = mean.z + sol.z - a * mean.x - b * mean.y;
    Some(FloorModel { a, b, c, ceiling_above_floor_m: None })
}
