//! The classical detector: floor and ceiling out, voxel clusters, planes peeled off oversized
//! clusters, each cluster scored as a person.

use super::carve::{carve, Shape};
use super::classify::{score, score_behind, score_followed, tallest_scorable_m, too_big};
use super::cluster::{drop_tall_columns, peel_plane, Grid};
use super::features::features;
use super::floor::estimate_floor;
use super::follow::{tracks, Track};
use super::fov::FovEnvelope;
use super::occlusion::{RangeImage, Silhouette};
use super::person_part::cut_to_person;
use super::trees::{self, TreeModel};
use super::{ClusterFeatures, DetectConfig, DetectWindow, Detection, Detector, DetectorKind, FloorModel, PersonPose};
use crate::PipelineError;
use nalgebra::{Vector2, Vector3};

/// A cluster whose top is this close to the ceiling cut touches the ceiling.
const CEILING_CONTACT_M: f64 = 0.05;

/// A cluster with this share of its voxels below the lying height is mostly low (a person
/// lying against something taller).
const LOW_SHARE: f64 = 0.6;

/// Geometric person detector (see the module docs). Between windows it holds only scratch
/// space and the people it confirmed in the last `follow_s` (see [`DetectConfig::follow_s`]).
pub struct GeometricDetector {
    cfg: DetectConfig,
    /// The learned scorer (`kind = "trees"`) in place of the posture gates.
    trees: Option<TreeModel>,
    /// The confirmations that count towards following someone: where (x, y in the world),
    /// when (window stamp, ns) and the box they were made in (to find the person again inside a
    /// cluster they merged with, [`super::carve`]).
    confirmed: Vec<Shape>,
    kept: Vec<(u32, Vector3<f64>)>,
    /// The last window's floor and clusters, for diagnosis and tuning.
    last_floor: Option<FloorModel>,
    last_clusters: Vec<(ClusterFeatures, f64)>,
    /// When set, the points of every scored cluster are kept too (tuning; costs allocations).
    keep_cluster_points: bool,
    /// When set, nobody is detected and every cluster too big for a person is split (training
    /// data for a learned scorer: every cluster any scorer could be shown).
    surveying: bool,
    /// When surveying, the learned scorer's input vector of each of `last_clusters`.
    last_inputs: Vec<[f32; trees::INPUTS]>,
    last_cluster_points: Vec<Vec<u32>>,
    last_silhouettes: Vec<Silhouette>,
}

impl GeometricDetector {
    pub fn new(cfg: DetectConfig) -> Result<Self, PipelineError> {
        cfg.validate()?;
        let trees = match cfg.kind {
            DetectorKind::Trees => Some(trees::load(&cfg.trees)?),
            _ => None,
        };
        Ok(Self {
            cfg,
            trees,
            confirmed: Vec::new(),
            kept: Vec::new(),
            last_floor: None,
            last_clusters: Vec::new(),
            keep_cluster_points: false,
            surveying: false,
            last_inputs: Vec::new(),
            last_cluster_points: Vec::new(),
            last_silhouettes: Vec::new(),
        })
    }

    pub fn config(&self) -> &DetectConfig {
        &self.cfg
    }

    /// The floor estimated in the last window.
    pub fn last_floor(&self) -> Option<FloorModel> {
        self.last_floor
    }

    /// Every cluster of the last window that was scored, with its score (people and rejects).
    pub fn last_clusters(&self) -> &[(ClusterFeatures, f64)] {
        &self.last_clusters
    }

    /// Keep the point indices of every scored cluster (for tuning the scorer on labelled data).
    pub fn keep_cluster_points(&mut self, keep: bool) {
        self.keep_cluster_points = keep;
    }

    /// Survey every cluster instead of detecting (training data for a learned scorer): nothing
    /// is detected or followed, every cluster too big for one person is split as well as
    /// scored, and each cluster's points are kept.
    pub fn survey(&mut self, on: bool) {
        self.surveying = on;
        self.keep_cluster_points |= on;
    }

    /// The learned scorer's input vector of each of [`Self::last_clusters`], when surveying (the
    /// same the trees are given when they score).
    pub fn last_inputs(&self) -> &[[f32; trees::INPUTS]] {
        &self.last_inputs
    }

    /// The points of each of [`Self::last_clusters`], when kept.
    pub fn last_cluster_points(&self) -> &[Vec<u32>] {
        &self.last_cluster_points
    }

    /// The silhouette of each of [`Self::last_clusters`], when their points are kept.
    pub fn last_silhouettes(&self) -> &[Silhouette] {
        &self.last_silhouettes
    }
}

impl Detector for GeometricDetector {
    fn name(&self) -> &'static str {
        match self.cfg.kind {
            DetectorKind::Trees => "trees",
            _ => "geometric",
        }
    }

    fn last_floor(&self) -> Option<FloorModel> {
        self.last_floor
    }

    fn detect(&mut self, window: &DetectWindow<'_>, out: &mut Vec<Detection>) {
        self.last_clusters.clear();
        self.last_cluster_points.clear();
        self.last_silhouettes.clear();
        self.last_inputs.clear();
        let followed = self.take_followed(window.stamp.ns);
        // Lent to the window's scene while the clusters are judged, then put back.
        let trees = self.trees.take();
        let scene = Scene::new(window, &self.cfg, &followed, trees.as_ref());
        self.last_floor = Some(scene.floor);
        keep_above_floor(&mut self.kept, &scene, &self.cfg);
        let first = out.len();
        let mut confirmed_now = self.judge_clusters(&scene, out);
        if scene.carving(&self.cfg) {
            find_followed_again(&scene, &self.kept, &self.cfg, first, out, &mut confirmed_now);
        }
        if scene.trees.is_some() {
            keep_separate(out, first, self.cfg.trees.min_separation_m);
        }
        // Last, on the detections only: following and finding again above match confirmations
        // to detections by the cluster's own centre, which the cut moves.
        for d in out.iter_mut().skip(first) {
            cut_to_person(window.points, &scene.floor, d);
        }
        self.trees = trees;
        self.confirmed = followed;
        self.confirmed.extend(confirmed_now);
    }
}

impl GeometricDetector {
    /// The confirmations still followed at `now_ns`, taken out of `self.confirmed` (the caller
    /// puts them back with this window's own). A window older than one already seen (a replay
    /// restarted) follows nobody. Confirmations are kept twice as long as a person is followed:
    /// all of them count towards the track, the last one starts the time it is followed for.
    fn take_followed(&mut self, now_ns: u64) -> Vec<Shape> {
        let follow_ns = follow_ns(&self.cfg);
        self.confirmed.retain(|c| c.t_ns <= now_ns && now_ns - c.t_ns <= 2 * follow_ns);
        std::mem::take(&mut self.confirmed)
    }

    /// Scores every cluster of the kept points (splitting the ones bigger than anyone) and
    /// pushes the people found to `out`; returns where each confirmation that counts towards
    /// following them was made (every one of the gates', the trees' from `track_min_score`).
    /// Partial views of followed people go last, once every full confirmation of the window is
    /// known: a piece of someone confirmed whole here is not a second person.
    fn judge_clusters(&mut self, scene: &Scene<'_, '_>, out: &mut Vec<Detection>) -> Vec<Shape> {
        let cfg = &self.cfg;
        let grid = Grid::new(&self.kept, cfg.voxel_m);
        // Built for the first candidate that needs it (most windows have none).
        let mut envelope: Option<FovEnvelope> = None;
        let mut partial: Vec<PartialView> = Vec::new();
        let mut confirmed_now: Vec<(Vector2<f64>, u64)> = Vec::new();
        let mut tracked_now: Vec<Shape> = Vec::new();
        let mut stack: Vec<(Vec<u32>, usize)> = grid.all_components().into_iter().map(|c| (c, 0)).collect();
        while let Some((cluster, depth)) = stack.pop() {
            if !enough_to_score(&grid, &cluster, cfg) {
                continue;
            }
            // Taller than anyone (a wall, a shelf): no posture can score it, so only split it,
            // without its features (the heading search over thousands of voxels was the
            // detector's largest cost). Its points span at least its voxel centres' heights.
            if !self.keep_cluster_points && centre_height_span(&grid, &cluster) >= tallest_scorable_m(cfg) {
                if depth < cfg.max_planes {
                    stack.extend(split(&grid, &cluster, cfg, depth));
                }
                continue;
            }
            let Some((f, pose, s)) = scene.rate(&grid, &cluster, cfg, self.keep_cluster_points, &mut envelope) else {
                continue;
            };
            if self.keep_cluster_points {
                let (silhouette, idx) = silhouette_of(scene.window, &grid, &cluster);
                self.last_silhouettes.push(silhouette);
                self.last_cluster_points.push(idx);
            }
            trace_cluster(scene.now_ns, &f, s);
            if self.surveying {
                self.last_inputs.push(scene.inputs(&grid, &cluster, &f));
                if depth < cfg.max_planes && too_big(&f, cfg) {
                    stack.extend(split(&grid, &cluster, cfg, depth));
                }
                self.last_clusters.push((f, s));
                continue;
            }
            if s >= scene.min_score(cfg) {
                confirmed_now.push((Vector2::new(f.centre.x, f.centre.y), scene.now_ns));
                if scene.tracks_on(s, cfg) {
                    tracked_now.push(Shape::of(&f, scene.now_ns));
                }
                out.push(detection(scene.window, &scene.floor, &f, pose, s, grid.points_of_cluster(&cluster), cfg));
                self.last_clusters.push((f, s));
                continue;
            }
            if let Some((followed_pose, followed_score)) = scene.as_followed(&f, pose, s, cfg) {
                let idx = grid.points_of_cluster(&cluster).collect();
                partial.push((f.clone(), followed_pose, followed_score, idx));
                self.last_clusters.push((f, followed_score));
                continue;
            }
            let split_it = depth < cfg.max_planes && too_big(&f, cfg);
            self.last_clusters.push((f, s));
            if split_it {
                stack.extend(split(&grid, &cluster, cfg, depth));
            }
        }
        push_partial_views(partial, &confirmed_now, scene, cfg, out);
        tracked_now
    }
}

/// A detection this much longer or wider than the box someone followed was last confirmed in,
/// over where they are, is them merged with what lies beside them (development hall-58: someone
/// lying beside a low bench, taken whole as one lying person 0.6-1 m off them), and they are
/// looked for inside it as if no detection held them.
const OUTGROWN_M: f64 = 0.5;

/// Each person followed whom no detection of `out[first..]` holds, or only detections that have
/// outgrown them ([`OUTGROWN_M`]), is looked for in the points of the box they were last
/// confirmed in, moved on at their velocity ([`super::carve`]); what the trees take for them
/// there is pushed (it is no confirmation: it does not keep them followed) in place of the
/// outgrown detections, whose confirmations are dropped from `confirmed_now`.
fn find_followed_again(
    scene: &Scene<'_, '_>,
    kept: &[(u32, Vector3<f64>)],
    cfg: &DetectConfig,
    first: usize,
    out: &mut Vec<Detection>,
    confirmed_now: &mut Vec<Shape>,
) {
    let mut envelope: Option<FovEnvelope> = None;
    for track in scene.tracks.iter().filter(|tr| scene.is_followed(tr, cfg)) {
        let now_at = track.now_at(scene.now_ns);
        let Some(shape) = scene.followed.get(track.newest) else { continue };
        // A detection near where they are, or over their box, is them (or a piece of them).
        let held = |d: &Detection| {
            let xy = d.centre_m.xy();
            (xy - now_at).norm() <= cfg.follow_radius_m || shape.covers(now_at, xy, cfg.trees.min_separation_m)
        };
        let outgrown = |d: &Detection| shape.outgrown_by(d.size_m.x, d.size_m.y, OUTGROWN_M);
        let holding: Vec<usize> = (first..out.len()).filter(|&i| held(&out[i])).collect();
        if holding.iter().any(|&i| !outgrown(&out[i])) {
            continue;
        }
        let carved = carve(kept, shape, now_at, cfg.trees.carve_margin_m);
        let grid = Grid::new(&carved, cfg.voxel_m);
        let largest = grid.all_components().into_iter().max_by_key(|c| grid.points_of_cluster(c).count());
        let Some(cluster) = largest.filter(|c| enough_to_score(&grid, c, cfg)) else { continue };
        let Some((f, pose, s)) = scene.rate(&grid, &cluster, cfg, false, &mut envelope) else { continue };
        if s < cfg.trees.follow_min_score {
            continue;
        }
        for &i in holding.iter().rev() {
            let merged = out.remove(i);
            confirmed_now.retain(|c| (c.at - merged.centre_m.xy()).norm() > 1e-6);
        }
        out.push(detection(scene.window, &scene.floor, &f, pose, s, grid.points_of_cluster(&cluster), cfg));
    }
}

/// A cluster scored as a partial view of someone followed: its features, posture, score and
/// point indices.
type PartialView = (ClusterFeatures, PersonPose, f64, Vec<u32>);

/// How long a person confirmed by every gate is followed (ns).
fn follow_ns(cfg: &DetectConfig) -> u64 {
    (cfg.follow_s * 1e9) as u64
}

/// One window as its clusters see it: the floor, the ceiling cut and the people followed into
/// it. Fixed for the window, so every cluster is judged against the same.
struct Scene<'s, 'w> {
    window: &'s DetectWindow<'w>,
    now_ns: u64,
    follow_ns: u64,
    /// The confirmations followed into this window, and the tracks chained from them.
    followed: &'s [Shape],
    tracks: Vec<Track>,
    /// The sensor's position in the world.
    sensor: Vector3<f64>,
    floor: FloorModel,
    /// Height above the floor where the ceiling band starts (`f64::MAX` without a ceiling).
    top: f64,
    /// The learned scorer, when it replaces the posture gates (nobody is followed then).
    trees: Option<&'s TreeModel>,
}

impl<'s, 'w> Scene<'s, 'w> {
    fn new(
        window: &'s DetectWindow<'w>,
        cfg: &DetectConfig,
        followed: &'s [Shape],
        trees: Option<&'s TreeModel>,
    ) -> Self {
        let at: Vec<(Vector2<f64>, u64)> = followed.iter().map(|c| (c.at, c.t_ns)).collect();
        let tracks = tracks(&at, cfg.follow_radius_m, cfg.follow_walk_mps);
        let sensor = window.sensor_pose.translation.vector;
        let floor = estimate_floor(window.points, sensor.z, cfg);
        let top = floor.ceiling_above_floor_m.map_or(f64::MAX, |c| c - cfg.ceiling_band_m);
        let trees_follow = cfg.trees.follow_min_score < cfg.trees.min_score;
        let follow_ns = if trees.is_some() && !trees_follow { 0 } else { follow_ns(cfg) };
        Self { window, now_ns: window.stamp.ns, follow_ns, followed, tracks, sensor, floor, top, trees }
    }

    /// The score a person needs: the trees' probability or the gates' score.
    fn min_score(&self, cfg: &DetectConfig) -> f64 {
        if self.trees.is_some() {
            cfg.trees.min_score
        } else {
            cfg.min_score
        }
    }

    /// Whether someone every gate confirmed often and lately may have walked to `xy` by now.
    fn near_followed(&self, xy: Vector2<f64>, cfg: &DetectConfig) -> bool {
        self.tracks.iter().any(|tr| self.is_followed(tr, cfg) && tr.reaches(xy, self.now_ns, cfg.follow_radius_m))
    }

    /// Whether a track was confirmed often enough, and lately enough, to be followed now.
    fn is_followed(&self, tr: &Track, cfg: &DetectConfig) -> bool {
        tr.confirmations >= cfg.follow_min_confirmations && self.now_ns - tr.t_ns <= self.follow_ns
    }

    /// Whether a confirmation scored `s` counts towards a track: every one of the gates', the
    /// trees' from `trees.track_min_score`.
    fn tracks_on(&self, s: f64, cfg: &DetectConfig) -> bool {
        self.trees.is_none() || s >= cfg.trees.track_min_score
    }

    /// Whether the trees look for the people they follow inside the clusters they merged with.
    fn carving(&self, cfg: &DetectConfig) -> bool {
        self.trees.is_some() && self.follow_ns > 0 && cfg.trees.carve
    }

    /// The learned scorer's input vector of a cluster (its points with their height above the
    /// floor).
    fn inputs(&self, grid: &Grid, cluster: &[u32], f: &ClusterFeatures) -> [f32; trees::INPUTS] {
        let points: Vec<Vector3<f64>> = grid.points_of_cluster(cluster).filter_map(|i| self.above_floor(i)).collect();
        trees::inputs(f, &points, [self.sensor.x, self.sensor.y])
    }

    /// Anything reaching the ceiling band is structure (a wall, a shelf, a door lintel).
    fn is_structure(&self, f: &ClusterFeatures) -> bool {
        f.top_m > self.top - CEILING_CONTACT_M
    }

    /// Point `i` of the window with its height above the floor as z.
    fn above_floor(&self, i: u32) -> Option<Vector3<f64>> {
        self.window.points.get(i as usize).map(|p| {
            let (x, y) = (f64::from(p.x_m), f64::from(p.y_m));
            Vector3::new(x, y, self.floor.height(x, y, f64::from(p.z_m)))
        })
    }

    /// The face share only where it can decide: the scores fall as it grows, so a cluster that
    /// fails with a share of 0 (and is no structure a followed person could be) fails with any.
    fn worth_faces(&self, f: &ClusterFeatures, cfg: &DetectConfig) -> bool {
        let xy = Vector2::new(f.centre.x, f.centre.y);
        !self.is_structure(f)
            && (score(f, cfg).1 >= cfg.min_score
                || (self.follow_ns > 0 && score_followed(f, cfg).1 >= cfg.min_score && self.near_followed(xy, cfg)))
    }

    /// A cluster's features, posture and score as a person on its own (None when it has no
    /// features). `keep_all` measures every cluster's face share (tuning).
    fn rate(
        &self,
        grid: &Grid,
        cluster: &[u32],
        cfg: &DetectConfig,
        keep_all: bool,
        envelope: &mut Option<FovEnvelope>,
    ) -> Option<(ClusterFeatures, PersonPose, f64)> {
        let sensor_xy = [self.sensor.x, self.sensor.y];
        let worth_faces = |f: &ClusterFeatures| {
            keep_all || self.trees.map_or_else(|| self.worth_faces(f, cfg), |_| trees::worth_scoring(f))
        };
        let f = features(grid, cluster, &|i| self.above_floor(i), sensor_xy, cfg.face_tolerance_m, &worth_faces)?;
        let (pose, mut s) = self.posture_score(grid, cluster, &f, cfg);
        if may_be_cut(&f, pose, s >= self.min_score(cfg), cfg) {
            let env = envelope.get_or_insert_with(|| {
                FovEnvelope::new(self.window.points, &self.window.sensor_pose, self.window.stamp.ns)
            });
            if env.cuts(self.window.points, grid.points_of_cluster(cluster), cfg.fov_edge_margin_deg) {
                s = 0.0;
            }
        }
        Some((f, pose, s))
    }

    /// The posture and score of a cluster's features: structure scores 0; head and shoulders
    /// over something nearer are a person low behind it when the silhouette says so.
    fn posture_score(
        &self,
        grid: &Grid,
        cluster: &[u32],
        f: &ClusterFeatures,
        cfg: &DetectConfig,
    ) -> (PersonPose, f64) {
        let structure = self.is_structure(f);
        if let Some(model) = self.trees {
            if !trees::worth_scoring(f) {
                return (PersonPose::Upright, 0.0);
            }
            let (pose, s) = trees::score(model, &self.inputs(grid, cluster, f));
            return (pose, if structure { 0.0 } else { s });
        }
        let (mut pose, mut s) = score(f, cfg);
        if structure {
            s = 0.0;
        }
        if s < cfg.min_score && !structure && cfg.behind_min_edge_share > 0.0 {
            let behind = score_behind(f, cfg);
            if behind >= cfg.min_score && self.hidden_below(grid, cluster, cfg) {
                (pose, s) = (PersonPose::Low, behind);
            }
        }
        (pose, s)
    }

    /// Whether the cluster's silhouette (a cone of the window around it, for the few clusters
    /// shaped like head and shoulders) is free above and hidden below by something nearer.
    fn hidden_below(&self, grid: &Grid, cluster: &[u32], cfg: &DetectConfig) -> bool {
        let points = self.window.points;
        let idx: Vec<u32> = grid.points_of_cluster(cluster).collect();
        let seen = RangeImage::around(points, &self.window.sensor_pose, &idx)
            .map(|image| image.silhouette(points, idx.iter().copied()))
            .unwrap_or_default();
        let share = cfg.behind_min_edge_share;
        seen.top_columns > 0 && seen.top_free >= share && seen.bottom_hidden >= share
    }

    /// A cluster too weak alone (its posture and score `pose`, `s` on its own) but near someone
    /// followed (and no structure), scored as a partial view of them; None when that fails
    /// too. The trees keep their own judgement with the lower `follow_min_score`.
    fn as_followed(
        &self,
        f: &ClusterFeatures,
        pose: PersonPose,
        s: f64,
        cfg: &DetectConfig,
    ) -> Option<(PersonPose, f64)> {
        let xy = Vector2::new(f.centre.x, f.centre.y);
        if self.is_structure(f) || self.follow_ns == 0 || !self.near_followed(xy, cfg) {
            return None;
        }
        if self.trees.is_some() {
            return (s >= cfg.trees.follow_min_score).then_some((pose, s));
        }
        let (pose, s) = score_followed(f, cfg);
        (s >= cfg.min_score).then_some((pose, s))
    }
}

/// The points between the floor band and the ceiling cut, each with its height above the
/// floor as z (what the voxel clusters are built from).
fn keep_above_floor(kept: &mut Vec<(u32, Vector3<f64>)>, scene: &Scene<'_, '_>, cfg: &DetectConfig) {
    kept.clear();
    for (i, p) in scene.window.points.iter().enumerate() {
        let (x, y) = (f64::from(p.x_m), f64::from(p.y_m));
        let h = scene.floor.height(x, y, f64::from(p.z_m));
        // Beyond 10 km is garbage, and would overflow the voxel keys.
        let sane = x.abs() < 1e4 && y.abs() < 1e4 && h.abs() < 1e4;
        if h > cfg.floor_band_m && h < scene.top && sane {
            kept.push((i as u32, Vector3::new(x, y, h)));
        }
    }
}

/// Whether a cluster holds enough to be scored: a person at the far end of the window still
/// fills a few voxels and `min_points` points.
fn enough_to_score(grid: &Grid, cluster: &[u32], cfg: &DetectConfig) -> bool {
    const MIN_VOXELS: usize = 3;
    if cluster.len() < MIN_VOXELS {
        return false;
    }
    let npts: usize = cluster.iter().map(|&v| grid.points_of(v).len()).sum();
    npts >= cfg.min_points
}

/// Whether a candidate's height may be the field of view's rather than its own: cut by the top
/// of the view, only a cluster already as tall as a standing person can be one (checked for
/// candidates only: the check costs a transform per point).
fn may_be_cut(f: &ClusterFeatures, pose: PersonPose, candidate: bool, cfg: &DetectConfig) -> bool {
    let short_of_upright = pose != PersonPose::Upright || f.size.z < cfg.upright_height_m[0];
    candidate && pose != PersonPose::Lying && short_of_upright && cfg.fov_edge_margin_deg > 0.0
}

/// A cluster's silhouette and point indices, kept for tuning the scorer.
fn silhouette_of(window: &DetectWindow<'_>, grid: &Grid, cluster: &[u32]) -> (Silhouette, Vec<u32>) {
    let points = window.points;
    let idx: Vec<u32> = grid.points_of_cluster(cluster).collect();
    let image = RangeImage::around(points, &window.sensor_pose, &idx);
    (image.map(|im| im.silhouette(points, idx.iter().copied())).unwrap_or_default(), idx)
}

fn trace_cluster(now_ns: u64, f: &ClusterFeatures, s: f64) {
    tracing::trace!(
        stamp_ns = now_ns,
        x_m = f.centre.x,
        y_m = f.centre.y,
        size_m = ?[f.size.x, f.size.y, f.size.z],
        top_m = f.top_m,
        points = f.points,
        face_share = f.face_share,
        thickness_m = f.thickness_m,
        planarity = f.planarity,
        linearity = f.linearity,
        score = s,
        "cluster scored"
    );
}

/// The partial views of followed people, best score first, each pushed unless someone was
/// already taken within `follow_radius_m` of it.
fn push_partial_views(
    mut partial: Vec<PartialView>,
    confirmed_now: &[(Vector2<f64>, u64)],
    scene: &Scene<'_, '_>,
    cfg: &DetectConfig,
    out: &mut Vec<Detection>,
) {
    partial.sort_by(|a, b| b.2.total_cmp(&a.2));
    let mut taken: Vec<Vector2<f64>> = confirmed_now.iter().map(|c| c.0).collect();
    for (f, pose, s, idx) in partial {
        let xy = Vector2::new(f.centre.x, f.centre.y);
        if taken.iter().all(|at| (at - xy).norm() > cfg.follow_radius_m) {
            taken.push(xy);
            out.push(detection(scene.window, &scene.floor, &f, pose, s, idx.into_iter(), cfg));
        }
    }
}

/// Of the detections from `out[first..]`, keeps only the likeliest of any closer than
/// `min_separation_m` over the floor (pieces of one body split by the clustering).
fn keep_separate(out: &mut Vec<Detection>, first: usize, min_separation_m: f64) {
    let Some(mine) = out.get_mut(first..) else { return };
    mine.sort_by(|a, b| b.score.total_cmp(&a.score));
    let mut kept: Vec<Detection> = Vec::with_capacity(mine.len());
    for d in out.drain(first..) {
        let apart = |k: &Detection| (k.centre_m.xy() - d.centre_m.xy()).norm() >= min_separation_m;
        if kept.iter().all(apart) {
            kept.push(d);
        }
    }
    out.extend(kept);
}

/// A person's box from their cluster: one whose feet are at the floor band stands on the floor.
fn detection(
    window: &DetectWindow<'_>,
    floor: &FloorModel,
    f: &ClusterFeatures,
    pose: PersonPose,
    score: f64,
    points: impl Iterator<Item = u32>,
    cfg: &DetectConfig,
) -> Detection {
    let floor_touch = f.bottom_m <= cfg.floor_band_m + 0.15;
    let (bottom, height) = if floor_touch { (0.0, f.top_m) } else { (f.bottom_m, f.size.z) };
    let (cx, cy) = (f.centre.x, f.centre.y);
    let cz = floor.a * cx + floor.b * cy + floor.c + bottom + height / 2.0;
    let mut point_indices: Vec<u32> = points.collect();
    point_indices.sort_unstable();
    Detection {
        stamp: window.stamp,
        centre_m: Vector3::new(cx, cy, cz),
        size_m: Vector3::new(f.size.x, f.size.y, height),
        yaw_rad: f.yaw_rad,
        score,
        pose,
        point_indices,
    }
}

/// Highest minus lowest voxel centre of a cluster.
fn centre_height_span(grid: &Grid, cluster: &[u32]) -> f64 {
    let (mut lo, mut hi) = (f64::MAX, f64::MIN);
    for v in cluster.iter().filter_map(|&v| grid.voxels.get(v as usize)) {
        lo = lo.min(v.centre.z);
        hi = hi.max(v.centre.z);
    }
    hi - lo
}

/// The parts of a cluster bigger than any person, one level deeper. A mostly low cluster is a
/// person lying against something taller more often than a plane: cut the tall columns first;
/// otherwise peel the largest plane.
fn split(grid: &Grid, cluster: &[u32], cfg: &DetectConfig, depth: usize) -> Vec<(Vec<u32>, usize)> {
    let rest = drop_tall_columns(grid, cluster, cfg.lying_height_m[1], LOW_SHARE).or_else(|| {
        peel_plane(
            grid,
            cluster,
            cfg.plane_tolerance_m,
            cfg.plane_min_length_m,
            cfg.plane_min_width_m,
            cfg.lying_height_m[1],
            depth as u64,
        )
        .map(|(_, rest)| rest)
    });
    rest.map(|rest| grid.components(&rest).into_iter().map(|c| (c, depth + 1)).collect()).unwrap_or_default()
}
