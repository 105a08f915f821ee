//! The person scorer: soft gates on a cluster's box and shape, one set per posture, times the
//! gates every person passes (not a box, not a plane, standing on something).

use super::{ClusterFeatures, DetectConfig, PersonPose};

/// 1 inside [lo, hi], falling linearly to 0 at `soft` outside it.
fn band(x: f64, lo: f64, hi: f64, soft: f64) -> f64 {
    if x < lo {
        (1.0 - (lo - x) / soft).max(0.0)
    } else if x > hi {
        (1.0 - (x - hi) / soft).max(0.0)
    } else {
        1.0
    }
}

/// The best posture and its score in [0, 1].
pub fn score(f: &ClusterFeatures, cfg: &DetectConfig) -> (PersonPose, f64) {
    let (length, width, height) = (f.size.x, f.size.y, f.size.z);
    // Boxes and slabs: standing or sitting people are thicker than a face and not boxy. (A
    // lying body is low and round: most of its points are near its box's faces anyway.)
    let thick =
        band(f.thickness_m, cfg.min_thickness_m, f64::MAX, 0.005) * band(f.face_share, 0.0, cfg.max_face_share, 0.1);
    let upright = thick
        * band(height, cfg.upright_height_m[0], cfg.upright_height_m[1], 0.15)
        * band(length, 0.0, cfg.upright_max_length_m, 0.15)
        * band(width, 0.1, 0.9, 0.1)
        // Feet near the floor or a stage, never a body hanging in the air.
        * band(f.bottom_m, f64::MIN, 0.5_f64.max(cfg.max_bottom_m - 0.4), 0.2);
    let low = thick
        * band(height, cfg.low_height_m[0], cfg.low_height_m[1], 0.1)
        * band(length, 0.15, cfg.upright_max_length_m, 0.15)
        * band(width, 0.1, 0.9, 0.1)
        * band(f.bottom_m, f64::MIN, cfg.max_bottom_m, 0.2);
    let lying = band(height, cfg.lying_height_m[0], cfg.lying_height_m[1], 0.05)
        * band(length, cfg.lying_length_m[0], cfg.lying_length_m[1], 0.15)
        * band(width, 0.15, cfg.lying_max_width_m, 0.1)
        * band(f.bottom_m, f64::MIN, 0.3, 0.1);
    let (pose, shape) = [(PersonPose::Upright, upright), (PersonPose::Low, low), (PersonPose::Lying, lying)]
        .into_iter()
        .fold((PersonPose::Upright, 0.0), |best, c| if c.1 > best.1 { c } else { best });
    let common = band(f.planarity, 0.0, cfg.max_planarity, 0.05)
        * band(f.points as f64, cfg.min_points as f64, f64::MAX, cfg.min_points as f64);
    (pose, shape * common)
}

/// Whether a cluster is bigger than any person, so that splitting it may find one.
pub fn too_big(f: &ClusterFeatures, cfg: &DetectConfig) -> bool {
    let (length, width, height) = (f.size.x, f.size.y, f.size.z);
    height > cfg.upright_height_m[1]
        || length > cfg.lying_length_m[1]
        || width > cfg.lying_max_width_m
        || (length > cfg.upright_max_length_m && height > cfg.lying_height_m[1])
}
