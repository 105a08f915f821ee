//! The person scorer: soft gates on a cluster's box and shape, one set per posture, times the
//! gates every person passes (not a box, not a plane, standing on something).

use super::{ClusterFeatures, DetectConfig, PersonPose};

/// 1 inside [lo, hi], falling linearly to 0 at `soft` outside it; 0 for a feature not measured
/// (NaN), so that no gate passes on one.
fn band(x: f64, lo: f64, hi: f64, soft: f64) -> f64 {
    if x.is_nan() {
        0.0
    } else if x < lo {
        (1.0 - (lo - x) / soft).max(0.0)
    } else if x > hi {
        (1.0 - (x - hi) / soft).max(0.0)
    } else {
        1.0
    }
}

/// Clusters with fewer points are judged by their face share more leniently.
const FACE_MIN_POINTS: usize = 300;

/// Shoulders, hips or a pair of legs are at least this long over the floor (a pole, a door
/// jamb or the corner of a box is not).
const MIN_LENGTH_M: f64 = 0.2;

/// A body seen from any side is at least this deep (the edge of a seat row, a door leaf or a
/// shelf's side, left over once the planes behind them are peeled, is thinner). Only clusters
/// with enough points to measure it are held to it: far away, a person is a sliver.
const MIN_WIDTH_M: f64 = 0.18;
const MIN_WIDTH_FEW_POINTS_M: f64 = 0.1;

/// How far past each posture's height range its gate falls to 0.
const UPRIGHT_HEIGHT_SOFT_M: f64 = 0.15;
const LOW_HEIGHT_SOFT_M: f64 = 0.1;
const UPPER_HEIGHT_SOFT_M: f64 = 0.05;
const LYING_HEIGHT_SOFT_M: f64 = 0.05;

/// The gates a partial view of a person fails: a sliver left by a door, a table or the side of
/// the view is flat, thin and all faces.
#[derive(Clone, Copy)]
struct ShapeGates {
    max_face_share: f64,
    /// Below the usual minimum width (which depends on the cluster's points) when set.
    min_width_m: Option<f64>,
    min_thickness_m: f64,
    lying_min_length_m: f64,
    /// A head alone (its shoulders sunk behind a table) may be all that is left of someone.
    head_alone: bool,
}

/// The best posture and its score in [0, 1].
pub fn score(f: &ClusterFeatures, cfg: &DetectConfig) -> (PersonPose, f64) {
    let gates = ShapeGates {
        max_face_share: cfg.max_face_share,
        min_width_m: None,
        min_thickness_m: cfg.min_thickness_m,
        lying_min_length_m: cfg.lying_length_m[0],
        head_alone: false,
    };
    score_with(f, cfg, gates)
}

/// [`score`] of a person already followed: the gates a partial view fails are those of
/// `follow_max_face_share`, `follow_min_width_m`, `follow_min_thickness_m` and
/// `follow_lying_min_length_m`.
pub fn score_followed(f: &ClusterFeatures, cfg: &DetectConfig) -> (PersonPose, f64) {
    let gates = ShapeGates {
        max_face_share: cfg.follow_max_face_share,
        min_width_m: Some(cfg.follow_min_width_m),
        min_thickness_m: cfg.follow_min_thickness_m.min(cfg.min_thickness_m),
        lying_min_length_m: cfg.follow_lying_min_length_m.min(cfg.lying_length_m[0]),
        head_alone: true,
    };
    score_with(f, cfg, gates)
}

fn score_with(f: &ClusterFeatures, cfg: &DetectConfig, gates: ShapeGates) -> (PersonPose, f64) {
    let (length, width, height) = (f.size.x, f.size.y, f.size.z);
    // Boxes and slabs: standing or sitting people are thicker than a face and not boxy. (A
    // lying body is low and round: most of its points are near its box's faces anyway.) With
    // few points (far away, a sliver through a gap) most of them are near some face anyway, so
    // only nearly all of them on faces counts against it.
    let min_width = if f.points >= FACE_MIN_POINTS { MIN_WIDTH_M } else { MIN_WIDTH_FEW_POINTS_M };
    let min_width = gates.min_width_m.map_or(min_width, |w| w.min(min_width));
    let max_face_share = gates.max_face_share;
    let max_face =
        if f.points >= FACE_MIN_POINTS { max_face_share } else { (max_face_share + 0.25).min(0.9).max(max_face_share) };
    let boxy = band(f.face_share, 0.0, max_face, 0.1);
    let thick = band(f.thickness_m, gates.min_thickness_m, f64::MAX, 0.005) * boxy;
    // Whole bodies are not flat; head and shoulders alone can be (and are judged without it).
    let not_flat = band(f.planarity, 0.0, cfg.max_planarity, 0.05);
    let upright = thick
        * not_flat
        * band(height, cfg.upright_height_m[0], cfg.upright_height_m[1], UPRIGHT_HEIGHT_SOFT_M)
        * band(length, MIN_LENGTH_M, cfg.upright_max_length_m, 0.15)
        * band(width, min_width, 0.9, 0.03)
        // Feet near the floor or a stage, never a body hanging in the air.
        * band(f.bottom_m, f64::MIN, 0.5_f64.max(cfg.max_bottom_m - 0.4), 0.2);
    let low = thick
        * not_flat
        * band(height, cfg.low_height_m[0], cfg.low_height_m[1], LOW_HEIGHT_SOFT_M)
        * band(length, MIN_LENGTH_M, cfg.upright_max_length_m, 0.15)
        * band(width, min_width, 0.9, 0.03)
        * band(f.bottom_m, f64::MIN, cfg.max_bottom_m, 0.2);
    let upper = thick * upper_body(f, cfg, cfg.upper_body_height_m, min_width);
    let lying = not_flat
        * band(height, cfg.lying_height_m[0], cfg.lying_height_m[1], LYING_HEIGHT_SOFT_M)
        * band(length, gates.lying_min_length_m, cfg.lying_length_m[1], 0.15)
        * band(width, 0.15, cfg.lying_max_width_m, 0.1)
        * band(f.bottom_m, f64::MIN, 0.3, 0.1);
    let head = if gates.head_alone { thick * head_alone(f, cfg, min_width) } else { 0.0 };
    let (pose, shape) = [
        (PersonPose::Upright, upright),
        (PersonPose::Low, low),
        (PersonPose::Low, upper),
        (PersonPose::Low, head),
        (PersonPose::Lying, lying),
    ]
    .into_iter()
    .fold((PersonPose::Upright, 0.0), |best, c| if c.1 > best.1 { c } else { best });
    let common = band(f.points as f64, cfg.min_points as f64, f64::MAX, cfg.min_points as f64);
    (pose, shape * common)
}

/// Head and shoulders above a table, a seat back or a stage edge (nothing else floats): the
/// gates on size and place alone.
fn upper_body(f: &ClusterFeatures, cfg: &DetectConfig, height_m: [f64; 2], min_width: f64) -> f64 {
    band(f.size.z, height_m[0], height_m[1], UPPER_HEIGHT_SOFT_M)
        * at_head_height(f, cfg)
        * band(f.size.x, MIN_LENGTH_M, 0.8, 0.1)
        * band(f.size.y, min_width, 0.7, 0.03)
}

/// Floating (lowest point at least 0.45 m up) with its top where heads are (`upper_body_top_m`).
fn at_head_height(f: &ClusterFeatures, cfg: &DetectConfig) -> f64 {
    band(f.top_m, cfg.upper_body_top_m[0], cfg.upper_body_top_m[1], 0.1) * band(f.bottom_m, 0.45, f64::MAX, 0.1)
}

/// A head is 0.2-0.25 m tall and 0.15-0.25 m across; the gates leave 5 cm for a neck and range
/// noise.
const HEAD_HEIGHT_M: [f64; 2] = [0.15, 0.3];
const HEAD_MAX_SIDE_M: f64 = 0.3;
const HEAD_SOFT_M: f64 = 0.03;

/// A head alone over a table edge or a seat back, where a person already followed was: no wider
/// than a head either way, so no table top or lectern is taken for one.
fn head_alone(f: &ClusterFeatures, cfg: &DetectConfig, min_width: f64) -> f64 {
    band(f.size.z, HEAD_HEIGHT_M[0], HEAD_HEIGHT_M[1], HEAD_SOFT_M)
        * at_head_height(f, cfg)
        * band(f.size.x, min_width, HEAD_MAX_SIDE_M, HEAD_SOFT_M)
        * band(f.size.y, min_width, HEAD_MAX_SIDE_M, HEAD_SOFT_M)
}

/// The shape score of someone whose lower body something nearer hides, seen as a sliver
/// (`behind_height_m` tall, held to the gates of a partial view: any face share, as narrow as
/// `follow_min_width_m`, as flat as `follow_min_thickness_m`). Only their silhouette tells them
/// from a strip of structure (see [`super::occlusion`]), so the caller must check it.
pub fn score_behind(f: &ClusterFeatures, cfg: &DetectConfig) -> f64 {
    let min_width = cfg.follow_min_width_m.min(MIN_WIDTH_FEW_POINTS_M);
    let thick = band(f.thickness_m, cfg.follow_min_thickness_m.min(cfg.min_thickness_m), f64::MAX, 0.005);
    let common = band(f.points as f64, cfg.min_points as f64, f64::MAX, cfg.min_points as f64);
    thick * upper_body(f, cfg, cfg.behind_height_m, min_width) * common
}

/// A cluster at least this tall scores 0 in every posture (each height gate's upper edge plus
/// its soft margin, as in [`score`]) and is [`too_big`].
pub fn tallest_scorable_m(cfg: &DetectConfig) -> f64 {
    (cfg.upright_height_m[1] + UPRIGHT_HEIGHT_SOFT_M)
        .max(cfg.low_height_m[1] + LOW_HEIGHT_SOFT_M)
        .max(cfg.upper_body_height_m[1] + UPPER_HEIGHT_SOFT_M)
        .max(cfg.lying_height_m[1] + LYING_HEIGHT_SOFT_M)
}

/// Whether a cluster is bigger than any person, so that splitting it may find one.
pub fn too_big(f: &ClusterFeatures, cfg: &DetectConfig) -> bool {
    let (length, width, height) = (f.size.x, f.size.y, f.size.z);
    height > cfg.upright_height_m[1]
        || length > cfg.lying_length_m[1]
        || width > cfg.lying_max_width_m
        || (length > cfg.upright_max_length_m && height > cfg.lying_height_m[1])
}
