//! Tunables of the aligner, loaded from TOML (`config/align.toml`); every field has a default.

use serde::{Deserialize, Serialize};

/// Alignment settings. The defaults fit the real scan pair in `shared/data/registration`
/// (a 360-degree spinning LiDAR, about 69k points per scan, ranges up to tens of metres).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct AlignConfig {
    /// Coarse stage: NDT grid sizes, coarse to fine.
    pub ndt_resolutions_m: Vec<f64>,
    /// NDT levels whose cell is larger than this times the source's RMS radius (distance of its
    /// reduced points from their centroid) are skipped: cells as large as the room blur it into
    /// false minima. 0 keeps every level.
    pub ndt_max_cell_ratio: f64,
    /// Voxel size the source is reduced to before NDT.
    pub ndt_source_voxel_m: f64,
    /// Voxel size the target is reduced to before its NDT cells are fitted.
    pub ndt_target_voxel_m: f64,
    /// Gauss-Newton iterations per NDT level, at most.
    pub ndt_max_iterations: u32,
    /// Share of outliers assumed by the NDT score (Magnusson's p_o).
    pub ndt_outlier_ratio: f64,
    /// Fine stage: voxel size both clouds are reduced to before ICP.
    pub icp_voxel_m: f64,
    /// A raw source of more points than this is reduced from every n-th point, n the smallest
    /// that brings it under (0: every point, always). Off by default: at 2 million the 12 s
    /// windows of docs/align.md reduce in half the time, at a cost in success (see there).
    pub source_max_points: usize,
    /// Radius (and neighbour count) of the PCA normals of the target.
    pub normal_radius_m: f64,
    pub normal_neighbours: usize,
    /// Correspondences farther than this are not used by ICP.
    pub icp_max_correspondence_m: f64,
    /// Share of the correspondences (smallest point-to-plane residuals) ICP keeps each iteration.
    pub icp_trim_ratio: f64,
    /// Huber threshold on the point-to-plane residual.
    pub icp_huber_m: f64,
    pub icp_max_iterations: u32,
    /// ICP stops when the update norm (|rotation, rad| + |translation, m| as one 6-vector) is below this.
    pub icp_converged_update: f64,
    /// A source point is an inlier when its nearest target point is within this distance.
    pub inlier_distance_m: f64,
    /// Acceptance: RMS point-to-plane residual of the kept correspondences, at most.
    pub max_rms_m: f64,
    /// Acceptance: inlier ratio (inliers over all reduced source points), at least.
    pub min_inlier_ratio: f64,
    /// Acceptance with the robot's coverage ([`crate::align::Aligner::with_coverage`]), instead
    /// of `min_inlier_ratio`: explained points over those the coverage can judge (explained, or
    /// in a voxel that at least `overlap_min_crossings` of the robot's rays crossed), at least
    /// `overlap_min_ratio`; and explained over all points at least `overlap_min_share`.
    pub overlap_min_ratio: f64,
    pub overlap_min_share: f64,
    pub overlap_min_crossings: u16,
    /// Acceptance: norm of ICP's last update, at most (an ICP that had not settled is rejected).
    pub max_update_norm: f64,
    /// Acceptance: degeneracy index (see [`crate::align::AlignMetrics::degeneracy_index`]), at least.
    pub min_degeneracy_index: f64,
    /// Only correspondences whose residual is within this (m) count towards the degeneracy index
    /// (still divided by all kept correspondences): a direction that only misfit points hold is
    /// not pinned down. A corridor placed metres off along itself, slightly turned, fits there
    /// at 4 cm RMS and looked constrained by its misfits (0.014 against 0.010 asked).
    pub degeneracy_residual_m: f64,
    /// ICP drops a pair whose two surfaces were seen from opposite sides of the target's plane,
    /// each with a mean cosine of at least this to its normal: the two faces of one wall, the
    /// robot's outside and the rig's inside (see [`crate::align::SeenFrom`]). Needs the
    /// source's rays and the target's directions ([`crate::align::Aligner::new_seen_from`]);
    /// 0: off.
    pub icp_opposite_min_side: f64,
    /// A result refused only for its degeneracy index is still accepted when what it explains
    /// pins it down (a corridor held by its far end, see [`crate::align::PinnedCheck`]): at least
    /// `pinned_min_inlier_ratio` of the source is within `inlier_distance_m` of the target (such a
    /// result first has its weak directions settled by every correspondence), and moved along
    /// each weak direction far enough that its points shift by each of `pinned_slides_m` (both
    /// ways) it explains at least `pinned_min_lost` (a share of the source) and
    /// `pinned_min_lost_points` fewer points. Empty: off (the index alone decides).
    pub pinned_slides_m: Vec<f64>,
    pub pinned_min_inlier_ratio: f64,
    pub pinned_min_lost: f64,
    pub pinned_min_lost_points: usize,
    /// Yaw-grid seed search: spacing of the yaw seeds around the circle (degrees); 0 disables the
    /// search (one attempt from the initial guess). The seeds are the guess turned about its own
    /// position by multiples of this step (the guess itself included).
    pub reseed_yaw_step_deg: f64,
    /// Translation seeds: besides the guess's position, positions this far from it along +-x and
    /// +-y of the target frame (0: none). Each yaw seed is tried at each position.
    pub reseed_shift_m: f64,
    /// Seed scoring: the source reduced to this voxel size, then thinned to at most
    /// `seed_max_points` (evenly through the voxel order), is refined on the first `seed_levels`
    /// NDT levels with at most `seed_max_iterations` each, and the seeds are ranked by the NDT
    /// score on the last of those levels.
    pub seed_source_voxel_m: f64,
    pub seed_max_points: usize,
    pub seed_levels: usize,
    pub seed_max_iterations: u32,
    /// The seed at the guess itself goes first when its score is within this share of the best
    /// one: in a near-symmetric place (a box room, a corridor) a flipped seed can score a little
    /// better, and the guess is the better bet.
    pub seed_prior_margin: f64,
    /// Full attempts (the remaining NDT levels, then ICP) on the best-ranked seeds, at most; the
    /// search stops at the first accepted one.
    pub max_full_attempts: usize,
    /// When no seed at the guess's position passes, the search runs again (up to
    /// `max_full_attempts` more) at positions this far away along ±x, ±y; 0: never. Off when
    /// `reseed_shift_m` already seeds positions.
    pub escalate_shift_m: f64,
    /// Consistency check of a result that passed the other tests: ICP is run again from starts
    /// this far off it along ±x and ±y (m, target frame) and `verify_yaw_deg` off in yaw either
    /// way; 0: off.
    pub verify_shift_m: f64,
    pub verify_yaw_deg: f64,
    /// The check runs on the ICP source thinned to this many points (it only has to tell basins apart).
    pub verify_max_points: usize,
    /// Each probe's ICP stops after this many iterations or below this update norm (it only has
    /// to show which minimum it falls into).
    pub verify_max_iterations: u32,
    pub verify_converged_update: f64,
    /// A probe that settles farther than this from the result (m or deg) with an RMS residual
    /// more than `verify_margin` (a share) below the result's found a better minimum: ICP goes on
    /// from there, at most `verify_hops` times; after that the attempt is rejected as inconsistent.
    pub verify_agree_m: f64,
    pub verify_agree_deg: f64,
    pub verify_margin: f64,
    pub verify_hops: u32,
    /// Ambiguity check of an accepted result in the seed search: this many more distinct seeds
    /// are refined; one that fits about as well or better elsewhere (RMS at most `ambiguity_margin`
    /// (a share) above the result's, inlier ratio at most `ambiguity_inlier_margin` below) rejects
    /// the result. 0: off.
    pub ambiguity_seeds: usize,
    pub ambiguity_margin: f64,
    pub ambiguity_inlier_margin: f64,
    /// Only seeds whose coarse NDT score reaches this share of the accepted seed's are refined by
    /// the ambiguity check (0: every seed; 1: only seeds scoring at least as well).
    pub ambiguity_score_ratio: f64,
    /// Global stage of the seed search ([`crate::align::global`]): this many distinct poses
    /// proposed by descriptor matches over the whole target join the yaw grid's seeds (0: off).
    /// Both clouds are reduced to `global_voxel_m`; normals come from neighbours within
    /// `global_normal_radius_m`, descriptors from those within `global_radius_m`; keypoints are
    /// the points whose curvature (smallest PCA eigenvalue over the sum) is at least
    /// `global_min_curvature`, at most `global_source_keypoints` / `global_target_keypoints`
    /// of them; each source keypoint is matched to `global_matches_per_point` target keypoints;
    /// `global_pair_samples` pairs of matches vote, a match agreeing within `global_inlier_m`.
    pub global_candidates: usize,
    pub global_voxel_m: f64,
    pub global_normal_radius_m: f64,
    pub global_radius_m: f64,
    pub global_min_curvature: f64,
    pub global_source_keypoints: usize,
    pub global_target_keypoints: usize,
    pub global_matches_per_point: usize,
    pub global_pair_samples: usize,
    pub global_inlier_m: f64,
    /// Correlative stage of the seed search ([`crate::align::correlative`]): the best
    /// `correlative_seeds` distinct level poses over the whole target, found by branch and bound
    /// on 2D grids of `correlative_cell_m` (0: off), judge an accepted result and, with
    /// `correlative_as_seeds`, are tried before every other seed. A window
    /// point landing where the target's coverage saw through costs `correlative_free_penalty`
    /// (one on the target's structure scores 1); a pose scoring under
    /// `correlative_min_score` of the window's points is no seed. An accepted result must
    /// score `correlative_margin` more than any other place the stage found. Once the best place
    /// is found, only places within `correlative_within_best` of its score are searched for: a
    /// place further below can neither rival it nor, accepted, survive beside it; proving that
    /// no such place exists cost most of the search on a large map; and as an ambiguity
    /// contender such a place only refused places the stage judges better (1: every place down
    /// to `correlative_min_score`).
    pub correlative_seeds: usize,
    pub correlative_cell_m: f64,
    pub correlative_free_penalty: f64,
    pub correlative_min_score: f64,
    pub correlative_margin: f64,
    pub correlative_within_best: f64,
    /// Whether the places the stage found are also tried as seeds (first), or only judge.
    pub correlative_as_seeds: bool,
    /// Places that fit only the part of the map they land on: the best `correlative_rivals`
    /// distinct places where the rig could stand (space the robot saw through), scoring at
    /// least `correlative_rival_min_score` with `correlative_rival_free_penalty` for each point
    /// where the robot saw through (0: off), are judged on the window's points that land on
    /// cells the map knows (its structure or the space the robot saw through). One with at least
    /// `correlative_rival_min_known` of the window on known cells and a mean value there within
    /// `correlative_rival_margin` of the accepted place's refuses it: a building whose mapped
    /// half mirrors the half the rig stands in fits the view there fully, and at the truth only
    /// where the robot has been, but as well.
    pub correlative_rivals: usize,
    pub correlative_rival_min_score: f64,
    pub correlative_rival_free_penalty: f64,
    pub correlative_rival_min_known: f64,
    pub correlative_rival_margin: f64,
    /// Free-space check of a result that passed the other tests, when the source comes with its
    /// rays ([`crate::align::Aligner::align_with_rays`]): at most this many rays are walked
    /// through the map (0: off), and the result is rejected when more than
    /// `free_space_max_blocked` of them cross a mapped surface and end more than
    /// `free_space_end_margin_m` behind it (a ray that ends on the surface it crossed hit it).
    pub free_space_rays: usize,
    pub free_space_max_blocked: f64,
    /// Sample spacing along a ray; the first `free_space_near_m` of a ray (the rig's own body,
    /// its operator) are not checked.
    pub free_space_step_m: f64,
    pub free_space_near_m: f64,
    pub free_space_end_margin_m: f64,
    /// A crossing counts only this close to a point of the map (at `ndt_target_voxel_m`): a
    /// surfel stands for a disc a cell wide, which a rack's open shelves are not (0: the
    /// surfel alone).
    pub free_space_point_m: f64,
    /// The clock of the report's compute times (not a setting of the file).
    #[serde(skip)]
    pub stopwatch: crate::timing::Stopwatch,
}

impl Default for AlignConfig {
    fn default() -> Self {
        Self {
            ndt_resolutions_m: vec![8.0, 4.0, 2.0, 1.0],
            ndt_max_cell_ratio: 0.0,
            ndt_source_voxel_m: 1.0,
            ndt_target_voxel_m: 0.1,
            ndt_max_iterations: 20,
            ndt_outlier_ratio: 0.55,
            icp_voxel_m: 0.25,
            source_max_points: 0,
            normal_radius_m: 1.0,
            normal_neighbours: 12,
            icp_max_correspondence_m: 0.5,
            icp_trim_ratio: 0.8,
            icp_huber_m: 0.1,
            icp_max_iterations: 30,
            icp_converged_update: 1e-4,
            inlier_distance_m: 0.3,
            max_rms_m: 0.1,
            min_inlier_ratio: 0.5,
            overlap_min_ratio: 0.96,
            overlap_min_share: 0.3,
            overlap_min_crossings: 2,
            max_update_norm: 1e-3,
            min_degeneracy_index: 0.01,
            degeneracy_residual_m: 0.05,
            icp_opposite_min_side: 0.3,
            pinned_slides_m: vec![0.5, 1.0, 1.5, 2.0, 3.0],
            pinned_min_inlier_ratio: 0.99,
            pinned_min_lost: 0.005,
            pinned_min_lost_points: 20,
            reseed_yaw_step_deg: 30.0,
            reseed_shift_m: 0.0,
            seed_source_voxel_m: 1.5,
            seed_max_points: 600,
            seed_levels: 2,
            seed_max_iterations: 6,
            seed_prior_margin: 0.1,
            max_full_attempts: 3,
            escalate_shift_m: 1.5,
            verify_shift_m: 0.2,
            verify_yaw_deg: 2.0,
            verify_max_points: 500,
            verify_max_iterations: 15,
            verify_converged_update: 1e-3,
            verify_agree_m: 0.02,
            verify_agree_deg: 0.2,
            verify_margin: 0.1,
            verify_hops: 2,
            ambiguity_seeds: 2,
            ambiguity_margin: 0.25,
            ambiguity_inlier_margin: 0.01,
            ambiguity_score_ratio: 0.8,
            global_candidates: 6,
            global_voxel_m: 0.3,
            global_normal_radius_m: 0.75,
            global_radius_m: 1.5,
            global_min_curvature: 0.03,
            global_source_keypoints: 800,
            global_target_keypoints: 20_000,
            global_matches_per_point: 2,
            global_pair_samples: 20_000,
            global_inlier_m: 0.4,
            correlative_seeds: 3,
            correlative_cell_m: 0.15,
            correlative_free_penalty: 1.0,
            correlative_min_score: 0.2,
            correlative_margin: 0.05,
            correlative_within_best: 0.05,
            correlative_as_seeds: true,
            correlative_rivals: 12,
            correlative_rival_min_score: 0.05,
            correlative_rival_free_penalty: 4.0,
            correlative_rival_min_known: 0.4,
            correlative_rival_margin: 0.05,
            free_space_rays: 400,
            free_space_max_blocked: 0.05,
            free_space_step_m: 0.1,
            free_space_near_m: 0.5,
            free_space_end_margin_m: 0.3,
            free_space_point_m: 0.06,
            stopwatch: crate::timing::Stopwatch::Wall,
        }
    }
}

impl AlignConfig {
    /// Reads a TOML file; fields left out keep their defaults, unknown fields are an error.
    pub fn from_toml(text: &str) -> Result<Self, crate::PipelineError> {
        let config: Self = toml::from_str(text)
            .map_err(|e| crate::PipelineError::BadFile { format: "align config", reason: e.to_string() })?;
        config.validate()?;
        Ok(config)
    }

    /// Rejects settings the solvers cannot work with.
    pub fn validate(&self) -> Result<(), crate::PipelineError> {
        let bad =
            |reason: &str| Err(crate::PipelineError::BadFile { format: "align config", reason: reason.to_string() });
        let positive = [
            self.ndt_source_voxel_m,
            self.ndt_target_voxel_m,
            self.icp_voxel_m,
            self.normal_radius_m,
            self.icp_max_correspondence_m,
            self.icp_huber_m,
            self.inlier_distance_m,
            self.degeneracy_residual_m,
            self.seed_source_voxel_m,
        ];
        if positive.iter().any(|v| !(v.is_finite() && *v > 0.0)) {
            return bad("voxel sizes, radii and distances must be positive");
        }
        if self.ndt_resolutions_m.is_empty() || self.ndt_resolutions_m.iter().any(|r| !(r.is_finite() && *r > 0.0)) {
            return bad("ndt_resolutions_m must list positive sizes");
        }
        let ratios_ok = self.icp_trim_ratio > 0.0
            && self.icp_trim_ratio <= 1.0
            && self.ndt_outlier_ratio > 0.0
            && self.ndt_outlier_ratio < 1.0;
        if !ratios_ok {
            return bad("icp_trim_ratio must be in (0, 1] and ndt_outlier_ratio in (0, 1)");
        }
        if !(self.reseed_yaw_step_deg >= 0.0 && self.reseed_yaw_step_deg <= 360.0) {
            return bad("reseed_yaw_step_deg must be in [0, 360]");
        }
        if !(self.ndt_max_cell_ratio.is_finite() && self.ndt_max_cell_ratio >= 0.0) {
            return bad("ndt_max_cell_ratio must be finite and not negative");
        }
        if !(0.0..=1.0).contains(&self.icp_opposite_min_side) {
            return bad("icp_opposite_min_side must be in [0, 1]");
        }
        if !(self.escalate_shift_m.is_finite() && self.escalate_shift_m >= 0.0) {
            return bad("escalate_shift_m must be finite and not negative");
        }
        if !(self.reseed_shift_m.is_finite() && self.reseed_shift_m >= 0.0) {
            return bad("reseed_shift_m must be finite and not negative");
        }
        if !(0.0..1.0).contains(&self.seed_prior_margin) {
            return bad("seed_prior_margin must be in [0, 1)");
        }
        if self.seed_levels == 0 || self.seed_levels > self.ndt_resolutions_m.len() {
            return bad("seed_levels must be between 1 and the number of NDT levels");
        }
        let checks = [
            self.verify_shift_m,
            self.verify_yaw_deg,
            self.verify_converged_update,
            self.verify_agree_m,
            self.verify_agree_deg,
            self.ambiguity_margin,
            self.ambiguity_inlier_margin,
            self.ambiguity_score_ratio,
        ];
        if checks.iter().any(|v| !(v.is_finite() && *v >= 0.0)) || !(0.0..1.0).contains(&self.verify_margin) {
            return bad("verify_* and ambiguity_* settings must be finite and not negative, verify_margin in [0, 1)");
        }
        if self.verify_shift_m > 0.0 && self.verify_max_points == 0 {
            return bad("verify_max_points must be at least 1 when the consistency check is on");
        }
        let free_space = [self.free_space_near_m, self.free_space_end_margin_m, self.free_space_point_m];
        if !(self.free_space_step_m.is_finite() && self.free_space_step_m > 0.0)
            || free_space.iter().any(|v| !(v.is_finite() && *v >= 0.0))
            || !(0.0..=1.0).contains(&self.free_space_max_blocked)
        {
            return bad("free_space_step_m must be positive, the free-space margins not negative, free_space_max_blocked in [0, 1]");
        }
        if self.pinned_slides_m.iter().any(|d| !(d.is_finite() && *d > 0.0))
            || !(0.0..=1.0).contains(&self.pinned_min_inlier_ratio)
            || !(0.0..=1.0).contains(&self.pinned_min_lost)
        {
            return bad("pinned_slides_m must be positive, pinned_min_inlier_ratio and pinned_min_lost in [0, 1]");
        }
        let global = [self.global_voxel_m, self.global_normal_radius_m, self.global_radius_m, self.global_inlier_m];
        if self.global_candidates > 0
            && (global.iter().any(|v| !(v.is_finite() && *v > 0.0))
                || !(self.global_min_curvature.is_finite() && self.global_min_curvature >= 0.0)
                || self.global_matches_per_point == 0
                || self.global_source_keypoints == 0
                || self.global_target_keypoints == 0)
        {
            return bad("global_* sizes must be positive, global_min_curvature not negative, global_matches_per_point and the keypoint counts at least 1");
        }
        if !(0.0..=1.0).contains(&self.overlap_min_ratio) || !(0.0..=1.0).contains(&self.overlap_min_share) {
            return bad("overlap_min_ratio and overlap_min_share must be in [0, 1]");
        }
        if self.correlative_seeds > 0 && !(self.correlative_cell_m >= 0.05 && self.correlative_cell_m.is_finite()) {
            return bad("correlative_cell_m must be at least 0.05 m");
        }
        let non_negative = [
            self.correlative_free_penalty,
            self.correlative_min_score,
            self.correlative_margin,
            self.correlative_within_best,
        ];
        if !non_negative.iter().all(|v| v.is_finite() && *v >= 0.0) {
            return bad("correlative_free_penalty, _min_score, _margin and _within_best must be finite and at least 0");
        }
        let rival = [self.correlative_rival_min_score, self.correlative_rival_min_known, self.correlative_rival_margin];
        let penalty_ok = self.correlative_rival_free_penalty.is_finite() && self.correlative_rival_free_penalty >= 0.0;
        if !(penalty_ok && rival.iter().all(|v| (0.0..=1.0).contains(v))) {
            return bad(
                "correlative_rival_min_score, _min_known and _margin must be in [0, 1], _free_penalty at least 0",
            );
        }
        if self.seed_max_points == 0 || self.max_full_attempts == 0 {
            return bad("seed_max_points and max_full_attempts must be at least 1");
        }
        Ok(())
    }
}
