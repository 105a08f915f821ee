//! Pillarization (docs/pillars.md): model-frame points into 0.2 m pillars, at most 32 points
//! each, with the 8 features of every kept point. scripts/train/pillars.py does the same in
//! numpy; the two must agree.

/// The crop, in the model frame (m).
pub const X_RANGE_M: (f32, f32) = (0.0, 19.2);
pub const Y_RANGE_M: (f32, f32) = (-9.6, 9.6);
pub const Z_RANGE_M: (f32, f32) = (-0.3, 2.7);
pub const PILLAR_M: f32 = 0.2;
/// Pillars along x and along y.
pub const GRID: usize = 96;
pub const MAX_POINTS: usize = 32;
pub const POINT_FEATURES: usize = 8;

/// The grid as the weights file's `grid` tensor states it.
pub const GRID_TENSOR: [f32; 8] =
    [X_RANGE_M.0, X_RANGE_M.1, Y_RANGE_M.0, Y_RANGE_M.1, Z_RANGE_M.0, Z_RANGE_M.1, PILLAR_M, MAX_POINTS as f32];

/// The non-empty pillars of a window, ordered by (row, column).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Pillars {
    /// (row `iy`, column `ix`) of each pillar.
    pub coords: Vec<(u16, u16)>,
    /// The kept points' 8 features, pillar after pillar, `counts[p]` rows each (no padding: the
    /// pillar net takes only real points).
    pub features: Vec<f32>,
    /// Kept points per pillar (1..=32).
    pub counts: Vec<u8>,
}

impl Pillars {
    pub fn len(&self) -> usize {
        self.coords.len()
    }

    pub fn is_empty(&self) -> bool {
        self.coords.is_empty()
    }

    /// The features as the ONNX graph takes them: `[pillar][point][feature]`, zero past a
    /// pillar's kept points (the reference check; inference never pads).
    pub fn padded(&self) -> Vec<f32> {
        let mut out = vec![0.0; self.len() * MAX_POINTS * POINT_FEATURES];
        let mut rows = self.features.chunks_exact(POINT_FEATURES);
        for (p, &n) in self.counts.iter().enumerate() {
            for (i, row) in rows.by_ref().take(usize::from(n)).enumerate() {
                let at = (p * MAX_POINTS + i) * POINT_FEATURES;
                out[at..at + POINT_FEATURES].copy_from_slice(row);
            }
        }
        out
    }
}

/// The pillar cell (`iy * GRID + ix`) of a model-frame point, if it is in the crop.
pub fn cell_of(p: &[f32; 3]) -> Option<usize> {
    let inside = |v: f32, (lo, hi): (f32, f32)| v >= lo && v < hi;
    if !(inside(p[0], X_RANGE_M) && inside(p[1], Y_RANGE_M) && inside(p[2], Z_RANGE_M)) {
        return None;
    }
    // A value a rounding step below the crop's top edge can divide to GRID: it joins the last
    // pillar (as the training's numpy does).
    let ix = (((p[0] - X_RANGE_M.0) / PILLAR_M) as usize).min(GRID - 1);
    let iy = (((p[1] - Y_RANGE_M.0) / PILLAR_M) as usize).min(GRID - 1);
    Some(iy * GRID + ix)
}

/// Pillarizes model-frame points given in window order. A pillar with more than 32 points keeps
/// those at `floor(i n / 32)`, i = 0..31: spread over the window, because the Avia's rosette
/// sweeps a pillar over time and its first 32 points would show only part of it.
pub fn pillarize(points: &[[f32; 3]]) -> Pillars {
    // A counting sort by cell: stable, so a pillar's points stay in window order.
    let cells: Vec<Option<usize>> = points.iter().map(cell_of).collect();
    let mut start = vec![0u32; GRID * GRID + 1];
    for cell in cells.iter().flatten() {
        start[cell + 1] += 1;
    }
    for i in 1..start.len() {
        start[i] += start[i - 1];
    }
    let mut next = start.clone();
    let mut order = vec![0u32; start[GRID * GRID] as usize];
    for (i, cell) in cells.iter().enumerate() {
        if let Some(&c) = cell.as_ref() {
            order[next[c] as usize] = i as u32;
            next[c] += 1;
        }
    }
    let mut out = Pillars::default();
    let mut kept = [[0f32; 3]; MAX_POINTS];
    for cell in 0..GRID * GRID {
        let group = &order[start[cell] as usize..start[cell + 1] as usize];
        let n = group.len();
        if n == 0 {
            continue;
        }
        let keep = n.min(MAX_POINTS);
        for (i, slot) in kept.iter_mut().take(keep).enumerate() {
            let k = if n <= MAX_POINTS { i } else { i * n / MAX_POINTS };
            *slot = group.get(k).and_then(|&j| points.get(j as usize)).copied().unwrap_or_default();
        }
        out.coords.push(((cell / GRID) as u16, (cell % GRID) as u16));
        out.counts.push(keep as u8);
        push_features(&mut out.features, &kept[..keep], cell % GRID, cell / GRID);
    }
    out
}

/// The 8 features of each kept point of one pillar.
fn push_features(out: &mut Vec<f32>, pts: &[[f32; 3]], ix: usize, iy: usize) {
    let n = pts.len() as f32;
    let mean = |k: usize| pts.iter().map(|p| p[k]).sum::<f32>() / n;
    let (mx, my, mz) = (mean(0), mean(1), mean(2));
    let cx = X_RANGE_M.0 + (ix as f32 + 0.5) * PILLAR_M;
    let cy = Y_RANGE_M.0 + (iy as f32 + 0.5) * PILLAR_M;
    for p in pts {
        out.extend([p[0], p[1], p[2], p[0] - mx, p[1] - my, p[2] - mz, p[0] - cx, p[1] - cy]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn points_go_to_their_pillar_in_row_then_column_order() {
        let pts = [[1.05, 0.05, 1.0], [0.05, 0.15, 0.5], [1.1, 0.1, 1.2], [30.0, 0.0, 1.0], [1.0, 0.0, 3.0]];
        let p = pillarize(&pts);
        // y 0.05 and 0.15 are rows 48 and 48; x 1.05 is column 5, 0.05 column 0.
        assert_eq!(p.coords, vec![(48, 0), (48, 5)]);
        assert_eq!(p.counts, vec![1, 2]);
        let padded = p.padded();
        let second = &padded[MAX_POINTS * POINT_FEATURES..][..16];
        assert_eq!(second.len(), 16);
        // x, y, z; offsets from the mean (1.075, 0.075, 1.1); offsets from the centre (1.1, -9.6 + 48.5 * 0.2).
        assert!((second[3] + 0.025).abs() < 1e-6 && (second[5] + 0.1).abs() < 1e-6);
        assert!((second[6] + 0.05).abs() < 1e-5 && (second[7] - (0.05 - (-9.6 + 48.5 * 0.2))).abs() < 1e-5);
        assert_eq!(p.padded().len(), 2 * MAX_POINTS * POINT_FEATURES);
    }

    #[test]
    fn a_full_pillar_keeps_32_points_spread_over_the_window() {
        let pts: Vec<[f32; 3]> = (0..64).map(|i| [5.01, 0.01, i as f32 * 0.01]).collect();
        let p = pillarize(&pts);
        assert_eq!(p.counts, vec![32]);
        // Every second point: the last kept is point 62.
        let first = p.padded();
        assert!((first[2] - 0.0).abs() < 1e-6 && (first[31 * 8 + 2] - 0.62).abs() < 1e-6);
    }
}
