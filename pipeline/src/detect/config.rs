//! Tunables of the geometric person detector, loaded from TOML (`config/detect.toml`); every
//! field has a default.

use crate::PipelineError;
use serde::{Deserialize, Serialize};

/// Settings of [`crate::detect::GeometricDetector`]. Heights are above the estimated floor;
/// lengths in metres. The defaults are fitted to the simulator's four shipped scenarios (seed 1;
/// seed 2, other noise on the same scenes, checks them): see docs/detect.md.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DetectConfig {
    /// Bin of the z histograms that find the floor and the ceiling.
    pub floor_bin_m: f64,
    /// A histogram bin is a floor candidate when it holds at least this share of the fullest bin
    /// below the sensor; the lowest candidate wins (a stage or table top is not the floor).
    pub floor_min_share: f64,
    /// Points closer than this to the fitted floor plane are floor.
    pub floor_band_m: f64,
    /// A ceiling is only assumed when its bin holds at least this many points.
    pub ceiling_min_points: usize,
    /// Points closer than this below the ceiling are ceiling.
    pub ceiling_band_m: f64,
    /// A ceiling is at least this high above the floor: below it, the highest well-filled bin
    /// is something in the room (a seated person filling the view, a table top), and taking it
    /// for the ceiling cut that person off as structure.
    pub ceiling_min_height_m: f64,
    /// Voxel size of the downsampled cloud the clusters are built on (26-connected voxels join).
    pub voxel_m: f64,
    /// A cluster needs at least this many points (of the window, before downsampling).
    pub min_points: usize,
    /// Clusters bigger than any person are split by peeling off planes (walls, table tops, box
    /// faces) and clustering what remains. A peeled plane must reach this far along its longer in-plane axis...
    pub plane_min_length_m: f64,
    /// ... and this far along its shorter one (smaller planes can be part of a person).
    pub plane_min_width_m: f64,
    /// Distance of a voxel centre to a plane to count as on it.
    pub plane_tolerance_m: f64,
    /// At most this many planes are peeled off one cluster.
    pub max_planes: usize,
    /// Upright people (standing, walking): vertical extent.
    pub upright_height_m: [f64; 2],
    /// Sitting or crouching people: vertical extent.
    pub low_height_m: [f64; 2],
    /// People lying on the floor: vertical extent.
    pub lying_height_m: [f64; 2],
    /// Head and shoulders seen above furniture or a stage edge (the rest hidden): vertical
    /// extent, and the range of their top above the floor.
    pub upper_body_height_m: [f64; 2],
    pub upper_body_top_m: [f64; 2],

    /// Longest horizontal side of an upright or low person's box.
    pub upright_max_length_m: f64,
    /// Horizontal sides of a lying person's box: length range and largest width.
    pub lying_length_m: [f64; 2],
    pub lying_max_width_m: f64,
    /// The lowest point of a person is at most this high (feet on the floor or a stage; people
    /// seen above furniture start higher).
    pub max_bottom_m: f64,
    /// Distance of a point to its cluster's box to count as on a face of it.
    pub face_tolerance_m: f64,
    /// Boxes (furniture, clutter, walls) put nearly all their points on the faces of their
    /// bounding box, standing and sitting people do not: such clusters with a larger share are
    /// rejected (soft gate; not applied to lying people, whose low round bodies are all face).
    pub max_face_share: f64,
    /// Planarity ((l2 - l3) / l1 of the voxel covariance) above which a cluster is a plane.
    pub max_planarity: f64,
    /// Upright, sitting and crouching people are at least this thick (RMS distance of their
    /// points to their best-fit plane); wall strips, door jambs and table sides are thinner.
    pub min_thickness_m: f64,
    /// Detections scoring below this are dropped.
    pub min_score: f64,
    /// A cluster whose top reaches within this of the upper edge of the sensor's field of view
    /// (learned from the window) has no known height: it is taken only as an upright person at
    /// least `upright_height_m[0]` tall, never as sitting or crouching (0: no check).
    pub fov_edge_margin_deg: f64,
    /// A person confirmed by every gate is followed for this long (0: no following): a cluster
    /// within `follow_radius_m` of where they were, in a later window, that fails only what a
    /// partial view fails (a face share up to `follow_max_face_share`, a top cut by the field of
    /// view) is still that person. Only full confirmations extend the time, so a track never
    /// lives on its own continuations. A person is followed when every gate has confirmed them
    /// `follow_min_confirmations` times in the last 2 x `follow_s` (one window's fluke is not),
    /// the last time within `follow_s`, counting a confirmation as theirs when it lies within
    /// `follow_radius_m` plus a walk at `follow_walk_mps` since it.
    pub follow_s: f64,
    pub follow_min_confirmations: usize,
    pub follow_walk_mps: f64,
    pub follow_radius_m: f64,
    pub follow_max_face_share: f64,
    /// ... a width down to this (a sliver of them beside a door or the side of the view) ...
    pub follow_min_width_m: f64,
    /// ... a thickness down to this (a narrow strip of a body is as flat as the range noise) ...
    pub follow_min_thickness_m: f64,
    /// ... or a lying body shorter than `lying_length_m[0]` down to this (cut by the side of the
    /// view as the robot turns away).
    pub follow_lying_min_length_m: f64,
    /// Someone behind something (boxes, a table, a counter) shows only head and shoulders, as a
    /// sliver as flat and narrow as a partial view: a cluster `behind_height_m` tall, floating
    /// (its lowest point at least 0.45 m up), with a top and place like head and shoulders, is a
    /// person when, in at least `behind_min_edge_share` of its columns of the range image, the
    /// return just above it is farther (the room beyond their head) and the return just below it
    /// nearer (what hides them). 0 turns it off.
    pub behind_height_m: [f64; 2],
    pub behind_min_edge_share: f64,
    /// Which detector runs: `geometric` (the rules above), `trees` (the same clusters scored by
    /// learned trees, set in `[trees]`) or `pointpillars` (the learned network, set in
    /// `[pillars]`; it uses the floor settings above).
    pub kind: DetectorKind,
    pub pillars: PillarsConfig,
    pub trees: TreesConfig,
}

/// The detector a robot runs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum DetectorKind {
    Geometric,
    #[default]
    Trees,
    Pointpillars,
}

impl std::str::FromStr for DetectorKind {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "geometric" => Ok(Self::Geometric),
            "trees" => Ok(Self::Trees),
            "pointpillars" => Ok(Self::Pointpillars),
            _ => Err(format!("{s:?}: want geometric, trees or pointpillars")),
        }
    }
}

/// Settings of the learned cluster scorer (`kind = "trees"`, [`crate::detect::trees`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TreesConfig {
    /// A trees file (STPW, docs/detect.md); none: the trees built into the program
    /// (config/models/cluster_trees.stpw when it was built).
    pub model: Option<std::path::PathBuf>,
    /// A cluster is a person when the trees give it at least this probability of being one.
    pub min_score: f64,
    /// Of two people found closer than this, only the likelier is kept (two pieces of one body
    /// are not two people).
    pub min_separation_m: f64,
    /// A cluster the trees give at least this (but under `min_score`) is still a person where
    /// someone followed (`follow_s`, `follow_min_confirmations`, `follow_radius_m`) may be by
    /// now: a person once found is kept through the windows where the trees doubt them. At
    /// `min_score` or above nobody is followed.
    pub follow_min_score: f64,
    /// Only confirmations the trees give at least this count towards following someone: most
    /// people are confirmed at 0.9 or more, most furniture taken for someone below it.
    pub track_min_score: f64,
    /// Where someone followed is in no detection of a window, the points inside the box they
    /// were last confirmed in (moved on at their velocity, grown by `carve_margin_m`) are
    /// clustered on their own and shown to the trees (a person merged with the bed they lie on
    /// or the chair they sit in). Only while following (`follow_min_score` under `min_score`).
    pub carve: bool,
    pub carve_margin_m: f64,
}

impl Default for TreesConfig {
    fn default() -> Self {
        Self {
            model: None,
            min_score: 0.75,
            min_separation_m: 0.5,
            follow_min_score: 0.3,
            track_min_score: 0.9,
            carve: true,
            carve_margin_m: 0.0,
        }
    }
}

/// Settings of the learned detector ([`crate::detect::pillars::PillarsDetector`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PillarsConfig {
    /// A weights file (STPW, docs/pillars.md); none: the weights built into the program
    /// (config/models/pillars.stpw when it was built).
    pub model: Option<std::path::PathBuf>,
    /// A heatmap peak needs at least this score to be a person.
    pub min_score: f64,
    /// Boxes overlapping a better one by more than this (bird's-eye IoU) are dropped.
    pub nms_iou: f64,
    /// The LiDAR's height above the floor, for a window that shows no floor.
    pub sensor_height_m: f64,
}

impl Default for PillarsConfig {
    fn default() -> Self {
        Self { model: None, min_score: 0.3, nms_iou: 0.1, sensor_height_m: 0.45 }
    }
}

impl Default for DetectConfig {
    fn default() -> Self {
        Self {
            floor_bin_m: 0.05,
            floor_min_share: 0.3,
            floor_band_m: 0.06,
            ceiling_min_points: 200,
            ceiling_band_m: 0.15,
            ceiling_min_height_m: 2.0,
            voxel_m: 0.1,
            min_points: 25,
            plane_min_length_m: 0.8,
            plane_min_width_m: 0.45,
            plane_tolerance_m: 0.05,
            max_planes: 4,
            upright_height_m: [1.2, 2.1],
            low_height_m: [0.55, 1.35],
            lying_height_m: [0.1, 0.5],
            upper_body_height_m: [0.25, 1.2],
            upper_body_top_m: [0.9, 2.6],
            upright_max_length_m: 1.1,
            lying_length_m: [1.1, 2.2],
            lying_max_width_m: 0.8,
            max_bottom_m: 1.2,
            face_tolerance_m: 0.04,
            max_face_share: 0.5,
            max_planarity: 0.25,
            min_thickness_m: 0.02,
            min_score: 0.5,
            fov_edge_margin_deg: 1.0,
            follow_s: 1.5,
            follow_min_confirmations: 4,
            follow_walk_mps: 1.5,
            follow_radius_m: 0.4,
            follow_max_face_share: 1.0,
            follow_min_width_m: 0.05,
            follow_min_thickness_m: 0.01,
            follow_lying_min_length_m: 0.5,
            behind_height_m: [0.45, 1.2],
            behind_min_edge_share: 0.75,
            kind: DetectorKind::Trees,
            pillars: PillarsConfig::default(),
            trees: TreesConfig::default(),
        }
    }
}

impl DetectConfig {
    /// Reads a TOML file; fields left out keep their defaults, unknown fields are an error.
    pub fn from_toml(text: &str) -> Result<Self, PipelineError> {
        let config: Self = toml::from_str(text).map_err(|e| bad(&e.to_string()))?;
        config.validate()?;
        Ok(config)
    }

    /// Rejects settings the detector cannot work with.
    pub fn validate(&self) -> Result<(), PipelineError> {
        let positive = [
            self.floor_bin_m,
            self.floor_band_m,
            self.ceiling_band_m,
            self.voxel_m,
            self.plane_min_length_m,
            self.plane_min_width_m,
            self.plane_tolerance_m,
            self.upright_max_length_m,
            self.lying_max_width_m,
            self.face_tolerance_m,
            self.min_thickness_m,
        ];
        if positive.iter().any(|v| !(v.is_finite() && *v > 0.0)) {
            return Err(bad("bins, bands, voxel sizes, extents and tolerances must be positive"));
        }
        if self.voxel_m < 0.02 || self.floor_bin_m < 0.005 {
            return Err(bad("voxel_m below 0.02 m or floor_bin_m below 0.005 m would make the grids explode"));
        }
        let ranges = [
            self.upright_height_m,
            self.low_height_m,
            self.lying_height_m,
            self.lying_length_m,
            self.upper_body_height_m,
            self.upper_body_top_m,
            self.behind_height_m,
        ];
        if ranges.iter().any(|[lo, hi]| !(lo.is_finite() && hi.is_finite() && *lo >= 0.0 && lo < hi)) {
            return Err(bad("every [min, max] range needs 0 <= min < max"));
        }
        let shares =
            [self.floor_min_share, self.max_face_share, self.max_planarity, self.min_score, self.behind_min_edge_share];
        if shares.iter().any(|v| !(*v >= 0.0 && *v <= 1.0)) {
            return Err(bad(
                "floor_min_share, max_face_share, max_planarity, min_score and behind_min_edge_share must be in [0, 1]",
            ));
        }
        if !(self.fov_edge_margin_deg.is_finite() && (0.0..=20.0).contains(&self.fov_edge_margin_deg)) {
            return Err(bad("fov_edge_margin_deg must be between 0 and 20"));
        }
        if !(self.follow_s.is_finite() && (0.0..=10.0).contains(&self.follow_s)) {
            return Err(bad("follow_s must be between 0 and 10"));
        }
        if !(self.follow_walk_mps.is_finite() && (0.0..=10.0).contains(&self.follow_walk_mps)) {
            return Err(bad("follow_walk_mps must be between 0 and 10"));
        }
        if !(self.follow_radius_m.is_finite() && (0.0..=2.0).contains(&self.follow_radius_m)) {
            return Err(bad("follow_radius_m must be between 0 and 2"));
        }
        let slivers = [self.follow_min_width_m, self.follow_min_thickness_m];
        if slivers.iter().any(|v| !(v.is_finite() && *v >= 0.0)) {
            return Err(bad("follow_min_width_m and follow_min_thickness_m must be finite and not negative"));
        }
        if !(self.follow_lying_min_length_m.is_finite() && self.follow_lying_min_length_m >= 0.0) {
            return Err(bad("follow_lying_min_length_m must be finite and not negative"));
        }
        if !(self.follow_max_face_share >= 0.0 && self.follow_max_face_share <= 1.0) {
            return Err(bad("follow_max_face_share must be in [0, 1]"));
        }
        if !(self.ceiling_min_height_m.is_finite() && (0.0..=10.0).contains(&self.ceiling_min_height_m)) {
            return Err(bad("ceiling_min_height_m must be between 0 and 10"));
        }
        if !self.max_bottom_m.is_finite() {
            return Err(bad("max_bottom_m must be finite"));
        }
        let t = &self.trees;
        if !((0.0..=1.0).contains(&t.min_score) && t.min_separation_m.is_finite() && t.min_separation_m >= 0.0) {
            return Err(bad("trees.min_score must be in [0, 1] and trees.min_separation_m finite and not negative"));
        }
        if !(t.follow_min_score > 0.0 && t.follow_min_score <= 1.0) {
            return Err(bad(
                "trees.follow_min_score must be in (0, 1] (at trees.min_score or above nobody is followed)",
            ));
        }
        if !(0.0..=1.0).contains(&t.track_min_score) {
            return Err(bad("trees.track_min_score must be in [0, 1]"));
        }
        if !(t.carve_margin_m.is_finite() && (0.0..=1.0).contains(&t.carve_margin_m)) {
            return Err(bad("trees.carve_margin_m must be between 0 and 1"));
        }
        let p = &self.pillars;
        if !((0.0..=1.0).contains(&p.min_score) && (0.0..=1.0).contains(&p.nms_iou)) {
            return Err(bad("pillars.min_score and pillars.nms_iou must be in [0, 1]"));
        }
        if !(p.sensor_height_m.is_finite() && (0.0..=3.0).contains(&p.sensor_height_m)) {
            return Err(bad("pillars.sensor_height_m must be between 0 and 3"));
        }
        Ok(())
    }
}

fn bad(reason: &str) -> PipelineError {
    PipelineError::BadFile { format: "detect config", reason: reason.to_string() }
}
