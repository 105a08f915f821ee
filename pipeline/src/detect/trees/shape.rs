//! What a cluster looks like beyond its height profile: where its points lie in height over the
//! floor, and its top seen from above.
//!
//! The profile in [`super::inputs`] is relative (the cluster's bottom to its top), so a seated
//! person and a chair of the same proportions read alike there. These inputs are absolute: a
//! head is a small cap 1.1-1.9 m up with shoulders under it, a table a wide top 0.7-0.8 m up, a
//! chair's back a thin edge.

use super::super::ClusterFeatures;
use nalgebra::Vector3;

/// Height bands of [`BAND_M`] from the floor; points above the last band count in it.
const HEIGHT_BANDS: usize = 10;
const BAND_M: f64 = 0.2;
/// Cells of the top view.
const CELL_M: f64 = 0.1;
/// The cap is the cells whose highest point is within this of the cluster's top; the collar
/// the cells below it down to twice this.
const CAP_DEPTH_M: f64 = 0.25;
/// Bins of the cells' highest points (a flat top puts most cells in one).
const TOP_BIN_M: f64 = 0.1;

/// Length of the shape inputs: bands, footprint (area, share of the box), cap and collar (area,
/// extent along and across the box), and the cells' tops (commonest height, its share, spread).
pub const SHAPE_INPUTS: usize = HEIGHT_BANDS + 2 + 3 + 3 + 3;

/// The shape inputs of a cluster: `f` and its points (x, y in the world, z above the floor).
pub fn shape_inputs(f: &ClusterFeatures, points: &[Vector3<f64>]) -> [f32; SHAPE_INPUTS] {
    let tops = TopView::new(f, points);
    let v = height_bands(points)
        .into_iter()
        .chain(tops.footprint(f))
        .chain(tops.band(f.top_m - CAP_DEPTH_M, f64::INFINITY))
        .chain(tops.band(f.top_m - 2.0 * CAP_DEPTH_M, f.top_m - CAP_DEPTH_M))
        .chain(tops.commonest_top());
    let mut out = [0.0f32; SHAPE_INPUTS];
    for (slot, x) in out.iter_mut().zip(v) {
        *slot = if x.is_finite() { x as f32 } else { 0.0 };
    }
    out
}

/// Share of the points in each height band over the floor.
fn height_bands(points: &[Vector3<f64>]) -> [f64; HEIGHT_BANDS] {
    let mut bands = [0.0; HEIGHT_BANDS];
    for p in points {
        let k = ((p.z / BAND_M).floor().max(0.0) as usize).min(HEIGHT_BANDS - 1);
        bands[k] += 1.0;
    }
    let n = points.len().max(1) as f64;
    bands.map(|c| c / n)
}

/// The cluster from above: the highest point of each [`CELL_M`] cell, in the box's frame (along
/// its length, across it).
struct TopView {
    /// (along, across, highest point over the floor) of each occupied cell.
    cells: Vec<(f64, f64, f64)>,
}

impl TopView {
    fn new(f: &ClusterFeatures, points: &[Vector3<f64>]) -> Self {
        let (s, c) = f.yaw_rad.sin_cos();
        let cols = (f.size.x / CELL_M).ceil() as usize + 1;
        let rows = (f.size.y / CELL_M).ceil() as usize + 1;
        let mut top = vec![f64::NEG_INFINITY; cols * rows];
        let index = |x: f64, half: f64, n: usize| (((x + half) / CELL_M).floor().max(0.0) as usize).min(n - 1);
        for p in points {
            let (dx, dy) = (p.x - f.centre.x, p.y - f.centre.y);
            let (a, b) = (c * dx + s * dy, -s * dx + c * dy);
            let k = index(a, f.size.x / 2.0, cols) * rows + index(b, f.size.y / 2.0, rows);
            top[k] = top[k].max(p.z);
        }
        let centre = |i: usize, half: f64| (i as f64 + 0.5) * CELL_M - half;
        let cells = (0..cols * rows)
            .filter(|&k| top[k].is_finite())
            .map(|k| (centre(k / rows, f.size.x / 2.0), centre(k % rows, f.size.y / 2.0), top[k]))
            .collect();
        Self { cells }
    }

    /// Area seen from above, and its share of the box's.
    fn footprint(&self, f: &ClusterFeatures) -> [f64; 2] {
        let area = self.cells.len() as f64 * CELL_M * CELL_M;
        [area, area / (f.size.x * f.size.y).max(CELL_M * CELL_M)]
    }

    /// Area and extent along and across the box of the cells whose highest point lies in
    /// (`low`, `high`].
    fn band(&self, low: f64, high: f64) -> [f64; 3] {
        let inside: Vec<_> = self.cells.iter().filter(|c| c.2 > low && c.2 <= high).collect();
        if inside.is_empty() {
            return [0.0; 3];
        }
        let extent = |get: fn(&(f64, f64, f64)) -> f64| {
            let (lo, hi) = inside.iter().map(|c| get(c)).fold((f64::MAX, f64::MIN), |(l, h), x| (l.min(x), h.max(x)));
            hi - lo + CELL_M
        };
        [inside.len() as f64 * CELL_M * CELL_M, extent(|c| c.0), extent(|c| c.1)]
    }

    /// The commonest height of the cells' tops (a table's or a seat's surface), the share of the
    /// cells there, and the spread of the tops.
    fn commonest_top(&self) -> [f64; 3] {
        if self.cells.is_empty() {
            return [0.0; 3];
        }
        let mut bins = std::collections::HashMap::<i64, usize>::new();
        for c in &self.cells {
            *bins.entry((c.2 / TOP_BIN_M).floor() as i64).or_default() += 1;
        }
        let (bin, count) = bins.into_iter().max_by_key(|&(b, n)| (n, -b)).unwrap_or((0, 0));
        let n = self.cells.len() as f64;
        let mean = self.cells.iter().map(|c| c.2).sum::<f64>() / n;
        let spread = (self.cells.iter().map(|c| (c.2 - mean).powi(2)).sum::<f64>() / n).sqrt();
        [(bin as f64 + 0.5) * TOP_BIN_M, count as f64 / n, spread]
    }
}

#[cfg(test)]
mod tests {
    use super::super::inputs::cluster as features;
    use super::*;

    fn grid(x: [f64; 2], y: [f64; 2], z: f64, step: f64) -> Vec<Vector3<f64>> {
        let n = |r: [f64; 2]| ((r[1] - r[0]) / step).round() as usize + 1;
        let mut pts = Vec::new();
        for i in 0..n(x) {
            for j in 0..n(y) {
                pts.push(Vector3::new(x[0] + i as f64 * step, y[0] + j as f64 * step, z));
            }
        }
        pts
    }

    #[test]
    fn a_table_top_is_wide_flat_and_common() {
        let f = features([0.0, 0.0], [1.2, 0.8, 0.05], 0.75);
        let v = shape_inputs(&f, &grid([-0.6, 0.6], [-0.4, 0.4], 0.75, 0.05));
        assert!((v[3] - 1.0).abs() < 1e-6, "all points in the 0.6-0.8 m band: {:?}", &v[..HEIGHT_BANDS]);
        let cap = &v[HEIGHT_BANDS + 2..HEIGHT_BANDS + 5];
        assert!(cap[0] > 0.8, "the whole top is the cap: {cap:?}");
        let tops = &v[HEIGHT_BANDS + 8..HEIGHT_BANDS + 11];
        assert!((tops[0] - 0.75).abs() < 0.06 && tops[1] > 0.99 && tops[2] < 0.01, "{tops:?}");
    }

    #[test]
    fn a_head_is_a_small_cap_over_wider_shoulders() {
        let f = features([0.0, 0.0], [0.5, 0.3, 1.3], 1.3);
        let mut pts = grid([-0.1, 0.1], [-0.1, 0.1], 1.3, 0.05);
        pts.extend(grid([-0.25, 0.25], [-0.15, 0.15], 1.0, 0.05));
        let v = shape_inputs(&f, &pts);
        let (cap, collar) = (&v[HEIGHT_BANDS + 2..HEIGHT_BANDS + 5], &v[HEIGHT_BANDS + 5..HEIGHT_BANDS + 8]);
        assert!(cap[0] < 0.1 && cap[1] < 0.35, "a head-sized cap: {cap:?}");
        assert!(collar[1] > cap[1], "shoulders wider than the head: {collar:?} against {cap:?}");
    }

    #[test]
    fn no_points_give_finite_inputs() {
        let f = features([0.0, 0.0], [0.0, 0.0, 0.0], 0.0);
        assert!(shape_inputs(&f, &[]).iter().all(|x| x.is_finite()));
    }
}
