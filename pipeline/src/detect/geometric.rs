//! The classical detector: floor and ceiling out, voxel clusters, planes peeled off oversized
//! clusters, each cluster scored as a person.

use super::classify::{score, score_behind, score_followed, tallest_scorable_m, too_big};
use super::cluster::{drop_tall_columns, peel_plane, Grid};
use super::features::features;
use super::floor::estimate_floor;
use super::follow::tracks;
use super::fov::FovEnvelope;
use super::occlusion::{RangeImage, Silhouette};
use super::{ClusterFeatures, DetectConfig, DetectWindow, Detection, Detector, FloorModel, PersonPose};
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
    /// Where every gate last confirmed someone (x, y in the world) and when (window stamp, ns).
    confirmed: Vec<(Vector2<f64>, u64)>,
    kept: Vec<(u32, Vector3<f64>)>,
    /// The last window's floor and clusters, for diagnosis and tuning.
    last_floor: Option<FloorModel>,
    last_clusters: Vec<(ClusterFeatures, f64)>,
    /// When set, the points of every scored cluster are kept too (tuning; costs allocations).
    keep_cluster_points: bool,
    last_cluster_points: Vec<Vec<u32>>,
    last_silhouettes: Vec<Silhouette>,
}

impl GeometricDetector {
    pub fn new(cfg: DetectConfig) -> Result<Self, PipelineError> {
        cfg.validate()?;
        Ok(Self {
            cfg,
            confirmed: Vec::new(),
            kept: Vec::new(),
            last_floor: None,
            last_clusters: Vec::new(),
            keep_cluster_points: false,
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
        "geometric"
    }

    fn detect(&mut self, window: &DetectWindow<'_>, out: &mut Vec<Detection>) {
        let cfg = &self.cfg;
        self.last_clusters.clear();
        self.last_cluster_points.clear();
        self.last_silhouettes.clear();
        let now_ns = window.stamp.ns;
        let follow_ns = (cfg.follow_s * 1e9) as u64;
        // A window older than one already seen (a replay restarted) follows nobody.
        // Confirmations are kept twice as long as a person is followed: all of them count
        // towards the track, the last one starts the time it is followed for.
        self.confirmed.retain(|&(_, t)| t <= now_ns && now_ns - t <= 2 * follow_ns);
        let followed = std::mem::take(&mut self.confirmed);
        let tracks = tracks(&followed, cfg.follow_radius_m, cfg.follow_walk_mps);
        let near_followed = |xy: Vector2<f64>| {
            tracks.iter().any(|tr| {
                tr.confirmations >= cfg.follow_min_confirmations
                    && now_ns - tr.t_ns <= follow_ns
                    && tr.reaches(xy, now_ns, cfg.follow_radius_m)
            })
        };
        // Partial views of followed people, kept once every full confirmation of this window is
        // known: a piece of someone confirmed whole here is not a second person.
        let mut partial: Vec<(ClusterFeatures, PersonPose, f64, Vec<u32>)> = Vec::new();
        let mut confirmed_now: Vec<(Vector2<f64>, u64)> = Vec::new();
        let sensor = window.sensor_pose.translation.vector;
        let floor = estimate_floor(window.points, sensor.z, cfg);
        self.last_floor = Some(floor);
        let top = floor.ceiling_above_floor_m.map_or(f64::MAX, |c| c - cfg.ceiling_band_m);

        self.kept.clear();
        for (i, p) in window.points.iter().enumerate() {
            let (x, y) = (f64::from(p.x_m), f64::from(p.y_m));
            let h = floor.height(x, y, f64::from(p.z_m));
            // Beyond 10 km is garbage, and would overflow the voxel keys.
            let sane = x.abs() < 1e4 && y.abs() < 1e4 && h.abs() < 1e4;
            if h > cfg.floor_band_m && h < top && sane {
                self.kept.push((i as u32, Vector3::new(x, y, h)));
            }
        }
        let grid = Grid::new(&self.kept, cfg.voxel_m);
        // Built for the first candidate that needs it (most windows have none).
        let mut envelope: Option<FovEnvelope> = None;
        let points = window.points;
        let lookup = |i: u32| {
            points.get(i as usize).map(|p| {
                let (x, y) = (f64::from(p.x_m), f64::from(p.y_m));
                Vector3::new(x, y, floor.height(x, y, f64::from(p.z_m)))
            })
        };
        // Voxels needed before a cluster is worth scoring: a person at the far end of the
        // window still fills a few.
        let min_voxels = 3;
        let mut stack: Vec<(Vec<u32>, usize)> = grid.all_components().into_iter().map(|c| (c, 0)).collect();
        while let Some((cluster, depth)) = stack.pop() {
            if cluster.len() < min_voxels {
                continue;
            }
            let npts: usize = cluster.iter().map(|&v| grid.points_of(v).len()).sum();
            if npts < cfg.min_points {
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
            // The face share only where it can decide: the scores fall as it grows, so one
            // that fails with a share of 0 (and is no structure a followed person could be)
            // fails with any.
            let worth_faces = |f: &ClusterFeatures| {
                let xy = Vector2::new(f.centre.x, f.centre.y);
                let structure = f.top_m > top - CEILING_CONTACT_M;
                self.keep_cluster_points
                    || (!structure
                        && (score(f, cfg).1 >= cfg.min_score
                            || (follow_ns > 0 && score_followed(f, cfg).1 >= cfg.min_score && near_followed(xy))))
            };
            let Some(f) = features(&grid, &cluster, &lookup, [sensor.x, sensor.y], cfg.face_tolerance_m, &worth_faces)
            else {
                continue;
            };
            let (mut pose, mut s) = score(&f, cfg);
            // Anything reaching the ceiling band is structure (a wall, a shelf, a door lintel).
            let structure = f.top_m > top - CEILING_CONTACT_M;
            if structure {
                s = 0.0;
            }
            // Head and shoulders over something nearer: the silhouette decides (a cone of the
            // window around the cluster, for the few clusters shaped like one).
            if s < cfg.min_score && !structure && cfg.behind_min_edge_share > 0.0 {
                let behind = score_behind(&f, cfg);
                if behind >= cfg.min_score {
                    let idx: Vec<u32> = grid.points_of_cluster(&cluster).collect();
                    let seen = RangeImage::around(points, &window.sensor_pose, &idx)
                        .map(|image| image.silhouette(points, idx.iter().copied()))
                        .unwrap_or_default();
                    let share = cfg.behind_min_edge_share;
                    if seen.top_columns > 0 && seen.top_free >= share && seen.bottom_hidden >= share {
                        (pose, s) = (PersonPose::Low, behind);
                    }
                }
            }
            if self.keep_cluster_points {
                let idx: Vec<u32> = grid.points_of_cluster(&cluster).collect();
                let image = RangeImage::around(points, &window.sensor_pose, &idx);
                self.last_silhouettes
                    .push(image.map(|im| im.silhouette(points, idx.iter().copied())).unwrap_or_default());
                self.last_cluster_points.push(idx);
            }
            // Cut by the top of the field of view, its height is the view's: only a cluster
            // already as tall as a standing person can be one (checked for candidates only: it
            // costs a transform per point).
            let short_of_upright = pose != PersonPose::Upright || f.size.z < cfg.upright_height_m[0];
            if s >= cfg.min_score && pose != PersonPose::Lying && short_of_upright && cfg.fov_edge_margin_deg > 0.0 {
                let env =
                    envelope.get_or_insert_with(|| FovEnvelope::new(points, &window.sensor_pose, window.stamp.ns));
                if env.cuts(points, grid.points_of_cluster(&cluster), cfg.fov_edge_margin_deg) {
                    s = 0.0;
                }
            }
            let xy = Vector2::new(f.centre.x, f.centre.y);
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
            if s >= cfg.min_score {
                confirmed_now.push((xy, now_ns));
                out.push(detection(window, &floor, &f, pose, s, grid.points_of_cluster(&cluster), cfg));
                self.last_clusters.push((f, s));
                continue;
            }
            if !structure && follow_ns > 0 && near_followed(xy) {
                // Someone every gate saw here moments ago: judged as a partial view of them.
                let (followed_pose, followed_score) = score_followed(&f, cfg);
                if followed_score >= cfg.min_score {
                    partial.push((
                        f.clone(),
                        followed_pose,
                        followed_score,
                        grid.points_of_cluster(&cluster).collect(),
                    ));
                    self.last_clusters.push((f, followed_score));
                    continue;
                }
            }
            let split_it = depth < cfg.max_planes && too_big(&f, cfg);
            self.last_clusters.push((f, s));
            if split_it {
                stack.extend(split(&grid, &cluster, cfg, depth));
            }
        }
        partial.sort_by(|a, b| b.2.total_cmp(&a.2));
        let mut taken: Vec<Vector2<f64>> = confirmed_now.iter().map(|c| c.0).collect();
        for (f, pose, s, idx) in partial {
            let xy = Vector2::new(f.centre.x, f.centre.y);
            if taken.iter().all(|at| (at - xy).norm() > cfg.follow_radius_m) {
                taken.push(xy);
                out.push(detection(window, &floor, &f, pose, s, idx.into_iter(), cfg));
            }
        }
        self.confirmed = followed;
        self.confirmed.extend(confirmed_now);
    }
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
