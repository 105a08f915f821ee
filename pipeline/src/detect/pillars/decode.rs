//! From the head's 12 channels to boxes (docs/pillars.md): peaks of the class heatmaps, the
//! box regressed at each peak, then rotated non-maximum suppression in bird's-eye view.

use super::grid::{PILLAR_M, Y_RANGE_M};
use super::net::{Map, HEAD_CHANNELS};

/// The head's cell size (m): two pillars.
const CELL_M: f64 = 2.0 * PILLAR_M as f64;
/// Bounds of the log-size channels: a box from 7 mm to 148 m, whatever the net says.
const LOG_SIZE_BOUNDS: (f32, f32) = (-5.0, 5.0);

/// One box in the model frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ModelBox {
    /// Centre: ahead, left, height above the floor (m).
    pub centre_m: [f64; 3],
    /// Length (along `yaw_rad`), width, height (m).
    pub size_m: [f64; 3],
    pub yaw_rad: f64,
    pub score: f64,
    /// Pose class: 0 standing, 1 sitting, 2 crouching, 3 lying.
    pub class: usize,
}

fn sigmoid(v: f32) -> f32 {
    1.0 / (1.0 + (-v).exp())
}

/// The boxes at the heatmap's peaks scoring at least `min_score`.
pub fn peaks(head: &Map, min_score: f32) -> Vec<ModelBox> {
    if head.channels != HEAD_CHANNELS {
        return Vec::new();
    }
    let (rows, cols) = (head.rows, head.cols);
    // Per cell: the best class and its score.
    let best: Vec<(usize, f32)> = (0..rows * cols)
        .map(|i| {
            (0..4).map(|k| (k, sigmoid(head.at(k, i / cols, i % cols)))).fold((0, f32::MIN), |a, b| {
                if b.1 > a.1 {
                    b
                } else {
                    a
                }
            })
        })
        .collect();
    let score_at = |r: usize, c: usize| best.get(r * cols + c).map_or(0.0, |b| b.1);
    let mut out = Vec::new();
    for r in 0..rows {
        for c in 0..cols {
            let (class, s) = best[r * cols + c];
            let neighbours = (r.saturating_sub(1)..(r + 2).min(rows))
                .flat_map(|nr| (c.saturating_sub(1)..(c + 2).min(cols)).map(move |nc| (nr, nc)));
            if s < min_score || neighbours.into_iter().any(|(nr, nc)| score_at(nr, nc) > s) {
                continue;
            }
            out.push(regress(head, r, c, class, s));
        }
    }
    out
}

fn regress(head: &Map, r: usize, c: usize, class: usize, score: f32) -> ModelBox {
    let ch = |k: usize| head.at(k, r, c);
    let size = |k: usize| f64::from(ch(k).clamp(LOG_SIZE_BOUNDS.0, LOG_SIZE_BOUNDS.1)).exp();
    ModelBox {
        centre_m: [
            CELL_M * (c as f64 + f64::from(ch(4))),
            f64::from(Y_RANGE_M.0) + CELL_M * (r as f64 + f64::from(ch(5))),
            f64::from(ch(6)),
        ],
        size_m: [size(7), size(8), size(9)],
        yaw_rad: 0.5 * f64::from(ch(10)).atan2(f64::from(ch(11))),
        score: f64::from(score),
        class,
    }
}

/// Keeps the best-scoring boxes, dropping each that overlaps a kept one by more than `max_iou`
/// (bird's-eye view, rotated).
pub fn rotated_nms(mut boxes: Vec<ModelBox>, max_iou: f64) -> Vec<ModelBox> {
    boxes.sort_by(|a, b| b.score.total_cmp(&a.score));
    let mut kept: Vec<ModelBox> = Vec::new();
    for b in boxes {
        if kept.iter().all(|k| bev_iou(k, &b) <= max_iou) {
            kept.push(b);
        }
    }
    kept
}

/// The four corners of a box seen from above, counter-clockwise.
fn corners(b: &ModelBox) -> Vec<[f64; 2]> {
    let (s, c) = b.yaw_rad.sin_cos();
    let (hl, hw) = (b.size_m[0] / 2.0, b.size_m[1] / 2.0);
    [(hl, hw), (-hl, hw), (-hl, -hw), (hl, -hw)]
        .iter()
        .map(|&(u, v)| [b.centre_m[0] + c * u - s * v, b.centre_m[1] + s * u + c * v])
        .collect()
}

fn area(poly: &[[f64; 2]]) -> f64 {
    let n = poly.len();
    (0..n).map(|i| poly[i][0] * poly[(i + 1) % n][1] - poly[(i + 1) % n][0] * poly[i][1]).sum::<f64>().abs() / 2.0
}

/// Intersection over union of two boxes seen from above (Sutherland-Hodgman clipping of one
/// rectangle by the other's edges).
pub fn bev_iou(a: &ModelBox, b: &ModelBox) -> f64 {
    let (pa, pb) = (corners(a), corners(b));
    let mut clipped = pa.clone();
    for i in 0..4 {
        let (e0, e1) = (pb[i], pb[(i + 1) % 4]);
        let side = |p: &[f64; 2]| (e1[0] - e0[0]) * (p[1] - e0[1]) - (e1[1] - e0[1]) * (p[0] - e0[0]);
        let input = std::mem::take(&mut clipped);
        for j in 0..input.len() {
            let (p, q) = (input[j], input[(j + 1) % input.len()]);
            let (sp, sq) = (side(&p), side(&q));
            if sp >= 0.0 {
                clipped.push(p);
            }
            if (sp >= 0.0) != (sq >= 0.0) {
                let t = sp / (sp - sq);
                clipped.push([p[0] + t * (q[0] - p[0]), p[1] + t * (q[1] - p[1])]);
            }
        }
        if clipped.is_empty() {
            return 0.0;
        }
    }
    let inter = area(&clipped);
    let union = area(&pa) + area(&pb) - inter;
    if union > 0.0 {
        inter / union
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn boxed(x: f64, y: f64, l: f64, w: f64, yaw: f64, score: f64) -> ModelBox {
        ModelBox { centre_m: [x, y, 0.9], size_m: [l, w, 1.8], yaw_rad: yaw, score, class: 0 }
    }

    #[test]
    fn iou_of_boxes_seen_from_above() {
        let a = boxed(0.0, 0.0, 2.0, 1.0, 0.0, 1.0);
        assert!((bev_iou(&a, &a) - 1.0).abs() < 1e-9);
        // Shifted by half its length: a third of the union.
        assert!((bev_iou(&a, &boxed(1.0, 0.0, 2.0, 1.0, 0.0, 1.0)) - 1.0 / 3.0).abs() < 1e-9);
        // A square turned 45 degrees over itself: 1 / (2 - 0.828...) / ... computed from the octagon.
        let sq = boxed(0.0, 0.0, 1.0, 1.0, 0.0, 1.0);
        let turned = boxed(0.0, 0.0, 1.0, 1.0, std::f64::consts::FRAC_PI_4, 1.0);
        let octagon = 2.0 * (2.0f64.sqrt() - 1.0);
        assert!((bev_iou(&sq, &turned) - octagon / (2.0 - octagon)).abs() < 1e-9);
        assert_eq!(bev_iou(&a, &boxed(5.0, 0.0, 2.0, 1.0, 0.3, 1.0)), 0.0);
    }

    #[test]
    fn nms_keeps_the_best_of_overlapping_boxes() {
        let kept = rotated_nms(
            vec![
                boxed(0.0, 0.0, 0.6, 0.5, 0.0, 0.5),
                boxed(0.05, 0.0, 0.6, 0.5, 0.1, 0.9),
                boxed(3.0, 0.0, 0.6, 0.5, 0.0, 0.4),
            ],
            0.3,
        );
        assert_eq!(kept.iter().map(|b| b.score).collect::<Vec<_>>(), vec![0.9, 0.4]);
    }

    #[test]
    fn a_peak_gives_its_box() {
        let mut head = Map { channels: 12, rows: 48, cols: 48, values: vec![-5.0; 12 * 48 * 48] };
        let set = |h: &mut Map, k: usize, r: usize, c: usize, v: f32| h.values[(k * 48 + r) * 48 + c] = v;
        set(&mut head, 3, 24, 10, 2.0); // lying
        set(&mut head, 3, 24, 11, 1.0); // its neighbour: not a peak
        set(&mut head, 4, 24, 10, 0.5);
        set(&mut head, 5, 24, 10, 0.25);
        set(&mut head, 6, 24, 10, 0.2);
        for k in 7..10 {
            set(&mut head, k, 24, 10, 0.0);
        }
        set(&mut head, 10, 24, 10, 0.0);
        set(&mut head, 11, 24, 10, -1.0); // cos 2 yaw = -1: yaw 90 degrees
        let found = peaks(&head, 0.3);
        assert_eq!(found.len(), 1);
        let b = found[0];
        assert_eq!(b.class, 3);
        assert!((b.centre_m[0] - 0.4 * 10.5).abs() < 1e-6 && (b.centre_m[1] - (-9.6 + 0.4 * 24.25)).abs() < 1e-6);
        assert!((b.yaw_rad.abs() - std::f64::consts::FRAC_PI_2).abs() < 1e-6 && (b.size_m[0] - 1.0).abs() < 1e-9);
    }
}
