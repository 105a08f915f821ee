//! The aligner: a prepared target (NDT grids and ICP normals), attempts of NDT then ICP from a
//! seed, acceptance, and the yaw-grid reseeding around the circle.

use super::config::AlignConfig;
use super::correlative::{CorrelativeParams, KnownFit, Peak, SourceBand, TargetGrid};
use super::coverage::{Coverage, Overlap};
use super::free_space::{FreeSpace, Ray, RayParams, SurfelGrid};
use super::geometry::{estimate_normals, pose_rows, thin, Vec3, VoxelIndex};
use super::global::{self, Described};
use super::icp::{self, IcpParams, IcpTarget};
use super::ndt::{self, NdtGrid};
use super::rejection::{AlignFailure, Rejection};
use super::seen_from::{reduce_by_side, SeenFrom};
use crate::timing::Lap;
use crate::voxel_hash::{voxel_downsample, voxel_downsample_every};
use crate::PipelineError;
use nalgebra::{Isometry3, UnitQuaternion};
use serde::Serialize;

/// Quality of one attempt's result (all measured on the ICP-reduced source).
#[derive(Clone, Debug, Serialize)]
pub struct AlignMetrics {
    /// RMS point-to-plane residual of the correspondences ICP keeps after trimming (the paper's ε).
    pub rms_residual_m: f64,
    /// Reduced source points whose nearest target point is within `inlier_distance_m`, over all
    /// reduced source points (the paper's η).
    pub inlier_ratio: f64,
    /// Norm of ICP's last Gauss-Newton update, rotation (rad) and translation (m) as one 6-vector
    /// (the paper's δ): small when ICP has settled.
    pub update_norm: f64,
    /// Smallest eigenvalue of the normalised point-to-plane information matrix at the result:
    /// `λmin(Σ JᵢᵀJᵢ / N)` with `Jᵢ = [((qᵢ - c) × nᵢ)/ρ, nᵢ]`, `c` the centroid of the matched points
    /// and `ρ` their RMS distance from it; the sum over the kept correspondences whose residual is
    /// within `degeneracy_residual_m`, N all of them. Unit-free, in [0, 1/3]; near 0 means a
    /// degenerate direction.
    pub degeneracy_index: f64,
    /// Correspondences ICP kept at the result.
    pub correspondences: usize,
    /// The matrix behind the degeneracy index, expressed in the SOURCE frame (the rig's):
    /// row-major 6x6 over (rotation about `information_centre_m` times `information_radius_m`,
    /// translation). Its eigenvectors say which directions the result pins down and how well;
    /// `pose::Constraint::from_rows` turns it into a per-direction drift correction.
    pub information: [[f64; 6]; 6],
    pub information_centre_m: [f64; 3],
    pub information_radius_m: f64,
}

/// Where a seed came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum SeedOrigin {
    /// The guess turned on the yaw grid (and moved to a seed position).
    YawGrid,
    /// Proposed by the global stage's descriptor matches ([`crate::align::global`]), with the
    /// matches that agreed with it.
    Global { votes: usize },
    /// Found by the correlative stage ([`crate::align::correlative`]), with its rank there.
    Correlative { rank: usize },
}

/// A pose a seed starts from, before its coarse refinement.
#[derive(Clone, Debug)]
pub(super) struct SeedStart {
    pub pose: Isometry3<f64>,
    pub yaw_offset_deg: f64,
    pub shift_m: [f64; 2],
    pub origin: SeedOrigin,
}

/// One seed of the search after its coarse refinement (the first `seed_levels` NDT levels on the
/// thinned source).
#[derive(Clone, Debug, Serialize)]
pub struct Seed {
    pub origin: SeedOrigin,
    /// Yaw added to the initial guess (degrees).
    pub yaw_offset_deg: f64,
    /// Offset of the seed's position from the guess's, in the target frame (m).
    pub shift_m: [f64; 2],
    /// NDT score on the last seed level, per seed point (lower is better; 0 matches nothing).
    pub score: f64,
    /// Seed points near a Gaussian of that level, over all seed points.
    pub matched_ratio: f64,
    /// The coarse pose a full attempt starts from.
    #[serde(skip)]
    pub pose: Isometry3<f64>,
}

/// One NDT+ICP run from one seed.
#[derive(Clone, Debug, Serialize)]
pub struct Attempt {
    /// Yaw added to the initial guess for this seed (0 for the initial guess itself).
    pub seed_yaw_offset_deg: f64,
    /// Offset of the seed's position from the guess's (m, target frame).
    pub seed_shift_m: [f64; 2],
    /// The result: a 4x4 row-major transform mapping source points into the target frame.
    pub transform: [[f64; 4]; 4],
    #[serde(skip)]
    pub pose: Isometry3<f64>,
    pub metrics: AlignMetrics,
    /// Gauss-Newton iterations of each NDT level this attempt ran, coarse to fine (the seed
    /// levels are not repeated when the attempt starts from a ranked seed).
    pub ndt_iterations: Vec<u32>,
    pub icp_iterations: u32,
    pub ndt_ms: f64,
    pub icp_ms: f64,
    pub accepted: bool,
    /// Which acceptance tests failed (empty when accepted).
    pub rejected_because: Vec<Rejection>,
    /// The consistency check's ICP runs from perturbed starts (only for attempts that passed
    /// the other tests, and only when `verify_shift_m > 0`).
    pub probes: Vec<Probe>,
    /// Times the check moved the result to a better neighbouring minimum.
    pub verify_hops: u32,
    /// Time of the consistency and ambiguity checks.
    pub verify_ms: f64,
    /// The ambiguity check's other seeds, refined (`ambiguity_seeds`).
    pub alternatives: Vec<Probe>,
    /// Rejected because another seed fits about as well elsewhere.
    pub ambiguous: bool,
    /// The free-space check at the result (only for attempts that passed the other tests, and
    /// only when the source came with rays).
    pub free_space: Option<FreeSpace>,
    /// The check of a result refused for its degeneracy index alone (`pinned_slides_m`).
    pub pinned: Option<PinnedCheck>,
    /// The source against the robot's map and coverage (only when the aligner has coverage).
    pub overlap: Option<Overlap>,
    /// Other places judged on what the map knows there (`correlative_rivals`; only for an
    /// attempt that passed every other test).
    pub rivals: Vec<Rival>,
    /// This attempt's own fit on what the map knows (with `rivals`).
    pub known_fit: Option<KnownFit>,
}

/// Another place of the view, judged on the part of the map it lands on.
#[derive(Clone, Debug, Serialize)]
pub struct Rival {
    /// Its score in the rival search (a share of the view's points).
    pub score: f64,
    pub fit: KnownFit,
    /// How far from the accepted place (m, deg).
    pub off_m: f64,
    pub off_deg: f64,
    #[serde(skip)]
    pub pose: Isometry3<f64>,
}

/// Whether what a degenerate result explains pins it down: the result is moved along each of
/// its weak directions (eigenvectors of the information matrix below `min_degeneracy_index`),
/// far enough that the source's points move `pinned_slides_m` on average, both ways and without
/// refitting, and must explain clearly fewer of them every time. A bare corridor fits as well
/// anywhere along itself; one whose far end is in view loses that end's points when slid. A turn
/// about a long corridor's axis looks weak to the index only because the index scales turns by
/// the points' spread along it.
#[derive(Clone, Debug, Serialize)]
pub struct PinnedCheck {
    /// Reduced source points, and those with a target point within `inlier_distance_m`.
    pub points: usize,
    pub explained: usize,
    pub directions: Vec<WeakDirection>,
    pub pinned: bool,
}

/// One weak direction of a [`PinnedCheck`].
#[derive(Clone, Debug, Serialize)]
pub struct WeakDirection {
    /// Its eigenvalue (as the degeneracy index).
    pub eigenvalue: f64,
    /// Share of the (unit) eigenvector that is translation; the rest is a turn.
    pub translation_share: f64,
    /// Each move (mean point displacement, m, signed) and the points explained there.
    pub moves: Vec<(f64, usize)>,
}

/// ICP re-run from a start perturbed off an attempt's result (the consistency check).
#[derive(Clone, Debug, Serialize)]
pub struct Probe {
    /// The perturbation: shift (m, target frame x/y) and yaw (deg) applied to the result.
    pub shift_m: [f64; 2],
    pub yaw_deg: f64,
    /// Where ICP took it, relative to the attempt's result (m, deg).
    pub moved_m: f64,
    pub moved_deg: f64,
    pub rms_residual_m: f64,
    pub inlier_ratio: f64,
    pub iterations: u32,
    #[serde(skip)]
    pub pose: Isometry3<f64>,
}

/// Everything one call to [`Aligner::align`] did.
#[derive(Clone, Debug, Serialize)]
pub struct AlignReport {
    /// Whether the chosen attempt passed every acceptance test.
    pub accepted: bool,
    /// The chosen attempt (the accepted one; when none was accepted, the one with the highest
    /// inlier ratio, for diagnosis only).
    pub best_attempt: usize,
    pub transform: [[f64; 4]; 4],
    #[serde(skip)]
    pub pose: Isometry3<f64>,
    pub source_points: usize,
    pub source_reduce_ms: f64,
    /// Every seed of the search, best score first (empty when the search is off).
    pub seeds: Vec<Seed>,
    /// Time spent refining and ranking the seeds (the correlative stage's search included, when
    /// its places are seeds).
    pub seed_ms: f64,
    /// Time spent in the correlative stage: its search, the elsewhere and rival checks.
    pub correlative_ms: f64,
    pub total_ms: f64,
    pub attempts: Vec<Attempt>,
    /// Why nothing was accepted (None when accepted).
    pub failure: Option<AlignFailure>,
}

impl AlignReport {
    pub fn best(&self) -> Option<&Attempt> {
        self.attempts.get(self.best_attempt)
    }
}

/// A target prepared once for many alignments (the map side).
pub struct Aligner {
    config: AlignConfig,
    grids: Vec<NdtGrid>,
    icp_target: IcpTarget,
    surfels: SurfelGrid,
    /// The target's keypoints and descriptors for the global stage (empty when it is off).
    global_target: Described,
    /// The space the target's sensor saw through; with it, acceptance judges the overlap.
    coverage: Option<std::sync::Arc<Coverage>>,
    /// Time spent preparing the target.
    pub prepare_ms: f64,
}

/// Fewer contradicted points than this never refuse a fit on their own (a person who stepped
/// where the robot saw through, a few noisy returns): the overlap ratio of a small window is
/// noise.
const MIN_CONTRADICTED_POINTS: usize = 20;

/// The correlative stage's queue is worked at most this long (nodes), bounding its time on a
/// map of many equal places.
const CORRELATIVE_MAX_EXPANSIONS: usize = 200_000;
/// A correlative peak this close (m, deg) to an attempt is the attempt's own place.
const CORRELATIVE_SAME_M: f64 = 1.0;
const CORRELATIVE_SAME_DEG: f64 = 10.0;

/// The correlative stage's result for one window: the grids, the window's band and the places.
struct CorrelativeSearch {
    grid: TargetGrid,
    band: SourceBand,
    peaks: Vec<Peak>,
}

/// Only weak directions at least this much translation are settled: a weak turn (about a long
/// corridor's axis) is left to ICP.
const SETTLE_MIN_TRANSLATION_SHARE: f64 = 0.9;

impl Aligner {
    pub fn new(target: &[Vec3], config: AlignConfig) -> Result<Self, PipelineError> {
        Self::new_seen_from(target, &[], config)
    }

    /// [`Aligner::new`] knowing which side the target's surfaces were seen from:
    /// `towards_sensor[i]` is the direction from `target[i]` towards the sensor that saw it (zero
    /// where unknown; another length: none known). ICP's target then keeps each voxel's sides
    /// apart (the two faces of a thin wall stay two surfaces) and pairs a source surface only
    /// with one seen from the same side (`icp_opposite_min_side`, with the source's rays).
    pub fn new_seen_from(target: &[Vec3], towards_sensor: &[Vec3], config: AlignConfig) -> Result<Self, PipelineError> {
        config.validate()?;
        let t0 = config.stopwatch.start();
        let sides_known = towards_sensor.len() == target.len() && config.icp_opposite_min_side > 0.0;
        // Each voxel's sides kept apart where they are known; their mean directions beside.
        let reduce = |voxel_m: f64| {
            if sides_known {
                reduce_by_side(target, towards_sensor, voxel_m)
            } else {
                (voxel_downsample(target, voxel_m), Vec::new())
            }
        };
        let (ndt_target, ndt_sides) = reduce(config.ndt_target_voxel_m);
        let grids: Vec<NdtGrid> = config
            .ndt_resolutions_m
            .iter()
            .map(|&r| {
                NdtGrid::new_sided(&ndt_target, &ndt_sides, r, config.ndt_outlier_ratio, config.icp_opposite_min_side)
            })
            .collect();
        let (icp_points, seen_from) = reduce(config.icp_voxel_m);
        let normals = estimate_normals(&icp_points, config.normal_radius_m, config.normal_neighbours);
        let surfels = if config.free_space_rays > 0 {
            SurfelGrid::new(&icp_points, &normals, config.icp_voxel_m)
                .with_points(&ndt_target, config.free_space_point_m)
        } else {
            SurfelGrid::new(&[], &[], config.icp_voxel_m)
        };
        let index = VoxelIndex::new(icp_points, config.icp_max_correspondence_m);
        if grids.iter().all(|g| g.cell_count() == 0) || normals.iter().all(Option::is_none) {
            return Err(PipelineError::BadFile {
                format: "align target",
                reason: format!("too few points ({}) to align against", target.len()),
            });
        }
        let global_target = if config.global_candidates > 0 && config.reseed_yaw_step_deg > 0.0 {
            global::describe(target, &config, config.global_target_keypoints)
        } else {
            Described { points: Vec::new(), descriptors: Vec::new() }
        };
        Ok(Self {
            config,
            grids,
            icp_target: IcpTarget { index, normals, seen_from },
            surfels,
            global_target,
            coverage: None,
            prepare_ms: t0.ms(),
        })
    }

    pub fn config(&self) -> &AlignConfig {
        &self.config
    }

    /// Judges results on the part of the source the target's sensor covered (see
    /// [`crate::align::coverage`]): the inlier ratio over covered points (`overlap_min_ratio`)
    /// and enough explained points to judge by (`overlap_min_share`) replace the inlier ratio
    /// over every point (`min_inlier_ratio`).
    pub fn with_coverage(mut self, coverage: std::sync::Arc<Coverage>) -> Self {
        self.coverage = Some(coverage);
        self
    }

    /// Aligns `source` to the target from `initial` (a guess of the transform mapping source into
    /// target). With the seed search on (`reseed_yaw_step_deg > 0`), every yaw seed (at every
    /// seed position) is refined cheaply on the coarse NDT levels and ranked by its NDT score; full
    /// attempts (the finer NDT levels, then ICP) run on the best-ranked distinct seeds until one is
    /// accepted. With it off, one full attempt runs from `initial`.
    pub fn align(&self, source: &[Vec3], initial: &Isometry3<f64>) -> AlignReport {
        self.align_with_rays(source, &[], initial)
    }

    /// [`Aligner::align`] with the source's rays (sensor position to point, in the source's
    /// frame): a result that passes the other tests must also leave them clear of the map's
    /// surfaces (the free-space check, `free_space_*`). Without rays the check is skipped.
    pub fn align_with_rays(&self, source: &[Vec3], rays: &[Ray], initial: &Isometry3<f64>) -> AlignReport {
        let c = &self.config;
        // A guess whose quaternion is off unit length would keep that error through every
        // product below (and scale the points it turns): renormalised first.
        let initial =
            &Isometry3::from_parts(initial.translation, UnitQuaternion::new_normalize(*initial.rotation.quaternion()));
        let t0 = self.config.stopwatch.start();
        // Finest reduction first; the coarser ones are taken from it (cheaper than from the raw scan).
        let stride = if c.source_max_points == 0 { 1 } else { source.len().div_ceil(c.source_max_points).max(1) };
        let icp_source = voxel_downsample_every(source, c.icp_voxel_m, stride);
        let ndt_source = voxel_downsample(&icp_source, c.ndt_source_voxel_m);
        let source_reduce_ms = t0.ms();
        let first_level = self.first_level(&ndt_source);
        // Which side each surface was seen from, only where the target's sides are known.
        let sided = c.icp_opposite_min_side > 0.0 && !self.icp_target.seen_from.is_empty();
        let seen_from_at = |voxel_m: f64| {
            if sided {
                SeenFrom::from_rays(rays, voxel_m)
            } else {
                SeenFrom::new(voxel_m)
            }
        };
        let (seen_from, ndt_seen_from) = (seen_from_at(c.icp_voxel_m), seen_from_at(c.ndt_source_voxel_m));
        let src =
            Sources { ndt: &ndt_source, icp: &icp_source, rays, seen_from: &seen_from, ndt_seen_from: &ndt_seen_from };
        let searched = if c.reseed_yaw_step_deg > 0.0 {
            self.search_seeds(&src, initial, first_level)
        } else {
            let attempts = vec![self.attempt(&src, initial, first_level, 0.0, [0.0; 2])];
            Searched { attempts, seeds: Vec::new(), seed_ms: 0.0, correlative_ms: 0.0 }
        };
        self.report(initial, searched, icp_source.len(), source_reduce_ms, t0)
    }

    /// The seed search: every seed ranked on the coarse NDT levels, then full attempts on the
    /// best-ranked until one settles (accepted or ambiguous); when none does from the guess's
    /// position, the same again at positions `escalate_shift_m` around it. Returns the
    /// attempts, every seed ranked, and the time spent ranking them and in the correlative stage.
    fn search_seeds(&self, src: &Sources, initial: &Isometry3<f64>, first_level: usize) -> Searched {
        let c = &self.config;
        let mut attempts = Vec::new();
        let t1 = self.config.stopwatch.start();
        let seed_source = thin(voxel_downsample(src.icp, c.seed_source_voxel_m), c.seed_max_points);
        let mut starts = self.grid_starts(initial, &self.shifts(c.reseed_shift_m, true));
        starts.extend(self.global_starts(src.icp, initial));
        // Only judging, the correlative stage runs once an attempt has been accepted.
        let tc = self.config.stopwatch.start();
        let search = if c.correlative_as_seeds { self.correlative_search(src.icp) } else { None };
        let mut correlative_ms = tc.ms();
        let correlative = self.correlative_seeds(search.as_ref(), initial, &seed_source, first_level);
        let mut seeds = self.rank_seeds(&seed_source, starts, first_level);
        let mut seed_ms = t1.ms();
        let mut tried: Vec<Isometry3<f64>> = Vec::new();
        // The correlative stage has searched every place: its seeds go first, unmoved by the
        // coarse NDT levels (whose large cells slide a seed off a place they blur).
        if c.correlative_as_seeds {
            self.try_seeds(&correlative, src, first_level, &mut tried, &mut attempts);
        }
        if !attempts.iter().any(|a| a.accepted || a.ambiguous) {
            self.try_seeds(&seeds, src, first_level, &mut tried, &mut attempts);
        }
        seeds.splice(0..0, correlative);
        // Nothing passed from the guess's position: search again at positions around it.
        let settled = attempts.iter().any(|a| a.accepted || a.ambiguous);
        if !settled && c.escalate_shift_m > 0.0 && c.reseed_shift_m == 0.0 {
            let t2 = self.config.stopwatch.start();
            let more = self.rank_seeds(
                &seed_source,
                self.grid_starts(initial, &self.shifts(c.escalate_shift_m, false)),
                first_level,
            );
            seed_ms += t2.ms();
            let before = attempts.len();
            self.try_seeds(&more, src, first_level, &mut tried, &mut attempts);
            if attempts.len() == before {
                tracing::debug!("escalated seed search found no new basin");
            }
            seeds.extend(more);
        }
        if let Some(a) = attempts.iter_mut().find(|a| a.accepted) {
            let tc = self.config.stopwatch.start();
            if let Some(search) = search.or_else(|| self.correlative_search(src.icp)) {
                self.check_elsewhere(&search, a);
                if a.accepted {
                    self.check_rivals(&search, a);
                }
            }
            correlative_ms += tc.ms();
        }
        Searched { attempts, seeds, seed_ms, correlative_ms }
    }

    /// Translation seeds: the guess's position (when `centre`) and positions `d` away along ±x, ±y.
    fn shifts(&self, d: f64, centre: bool) -> Vec<[f64; 2]> {
        let mut shifts = if centre { vec![[0.0, 0.0]] } else { Vec::new() };
        if d > 0.0 {
            shifts.extend([[d, 0.0], [-d, 0.0], [0.0, d], [0.0, -d]]);
        }
        shifts
    }

    /// Full attempts on the best-ranked seeds not yet tried, until one is accepted or
    /// `max_full_attempts` more have run.
    fn try_seeds(
        &self,
        seeds: &[Seed],
        src: &Sources,
        first_level: usize,
        tried: &mut Vec<Isometry3<f64>>,
        attempts: &mut Vec<Attempt>,
    ) {
        let c = &self.config;
        let limit = attempts.len() + c.max_full_attempts;
        for s in seeds {
            if attempts.len() >= limit {
                break;
            }
            // Seeds that fell into the same basin would repeat the same attempt.
            if tried.iter().any(|t| {
                let (dt, da) = super::geometry::pose_error(t, &s.pose);
                dt < 0.5 && da < 5.0
            }) {
                continue;
            }
            tried.push(s.pose);
            let after_seeds = (first_level + c.seed_levels).min(self.grids.len().saturating_sub(1));
            let mut a = self.attempt(src, &s.pose, after_seeds, s.yaw_offset_deg, s.shift_m);
            let done = a.accepted;
            if done && c.ambiguity_seeds > 0 {
                self.check_ambiguity(seeds, s.score, src, after_seeds, tried, &mut a);
            }
            let stop = done || a.ambiguous;
            attempts.push(a);
            if stop {
                break;
            }
        }
    }

    /// Ambiguity check of an accepted attempt: the next `ambiguity_seeds` distinct seeds of the
    /// ranking whose coarse NDT score is at least `ambiguity_score_ratio` of the accepted seed's, each refined (the remaining NDT levels, then ICP on the thinned source), must not
    /// land elsewhere with a fit about as good or better (RMS at most `ambiguity_margin` above,
    /// inlier ratio at most `ambiguity_inlier_margin` below, on the same thinned points): a corridor or a repeated structure fits in several places, and a place the map lacks
    /// can fit somewhere else; either way the first good fit is a coin toss, so it is rejected.
    fn check_ambiguity(
        &self,
        seeds: &[Seed],
        accepted_score: f64,
        src: &Sources,
        first_level: usize,
        tried: &[Isometry3<f64>],
        a: &mut Attempt,
    ) {
        let c = &self.config;
        let t0 = self.config.stopwatch.start();
        let source = thin(src.icp.to_vec(), c.verify_max_points);
        let params = self.icp_params(src.seen_from);
        let here = icp::refine(&self.icp_target, &source, a.pose, &IcpParams { max_iterations: 0, ..params });
        let distinct = |p: &Isometry3<f64>, q: &Isometry3<f64>| {
            let (dt, da) = super::geometry::pose_error(p, q);
            dt >= 0.5 || da >= 5.0
        };
        let mut checked: Vec<Isometry3<f64>> = Vec::new();
        for s in seeds {
            if a.alternatives.len() >= c.ambiguity_seeds {
                break;
            }
            // Only seeds whose coarse score comes close to the accepted seed's are contenders
            // (scores are negative, lower is better).
            if s.score > accepted_score * c.ambiguity_score_ratio
                || !distinct(&s.pose, &a.pose)
                || tried.iter().any(|t| !distinct(t, &s.pose))
                || checked.iter().any(|t| !distinct(t, &s.pose))
            {
                continue;
            }
            checked.push(s.pose);
            let mut pose = s.pose;
            for grid in self.grids.iter().skip(first_level) {
                pose = ndt::refine_level(grid, src.ndt, src.ndt_seen_from, pose, c.ndt_max_iterations).pose;
            }
            let r = icp::refine(&self.icp_target, &source, pose, &params);
            let (moved_m, moved_deg) = super::geometry::pose_error(&a.pose, &r.pose);
            a.alternatives.push(Probe {
                shift_m: s.shift_m,
                yaw_deg: s.yaw_offset_deg,
                moved_m,
                moved_deg,
                rms_residual_m: r.rms_residual_m,
                inlier_ratio: r.inlier_ratio,
                iterations: r.iterations,
                pose: r.pose,
            });
            let as_good = distinct(&a.pose, &r.pose)
                && r.rms_residual_m <= here.rms_residual_m * (1.0 + c.ambiguity_margin)
                && r.inlier_ratio >= here.inlier_ratio - c.ambiguity_inlier_margin;
            if as_good {
                a.ambiguous = true;
                a.accepted = false;
                a.rejected_because.push(Rejection::Ambiguous {
                    seed_yaw_deg: s.yaw_offset_deg,
                    moved_m,
                    moved_deg,
                    rms_m: r.rms_residual_m,
                    here_rms_m: here.rms_residual_m,
                    inliers: r.inlier_ratio,
                    here_inliers: here.inlier_ratio,
                });
                break;
            }
        }
        a.verify_ms += t0.ms();
    }

    fn ray_params(&self) -> RayParams {
        let c = &self.config;
        RayParams {
            max_rays: c.free_space_rays,
            step_m: c.free_space_step_m,
            near_m: c.free_space_near_m,
            end_margin_m: c.free_space_end_margin_m,
            stopwatch: c.stopwatch,
        }
    }

    fn icp_params<'a>(&self, source_seen_from: &'a SeenFrom) -> IcpParams<'a> {
        let c = &self.config;
        IcpParams {
            opposite_min_side: c.icp_opposite_min_side,
            source_seen_from,
            max_correspondence_m: c.icp_max_correspondence_m,
            trim_ratio: c.icp_trim_ratio,
            huber_m: c.icp_huber_m,
            max_iterations: c.icp_max_iterations,
            converged_update: c.icp_converged_update,
            inlier_distance_m: c.inlier_distance_m,
            degeneracy_residual_m: c.degeneracy_residual_m,
        }
    }

    fn report(
        &self,
        initial: &Isometry3<f64>,
        searched: Searched,
        source_points: usize,
        source_reduce_ms: f64,
        t0: Lap,
    ) -> AlignReport {
        let Searched { attempts, seeds, seed_ms, correlative_ms } = searched;
        let better = |a: &Attempt, b: &Attempt| {
            (a.accepted, a.metrics.inlier_ratio, -a.metrics.rms_residual_m)
                > (b.accepted, b.metrics.inlier_ratio, -b.metrics.rms_residual_m)
        };
        let mut best = 0;
        for (i, a) in attempts.iter().enumerate() {
            if let Some(b) = attempts.get(best) {
                if better(a, b) {
                    best = i;
                }
            }
        }
        let (accepted, pose) = attempts.get(best).map_or((false, *initial), |a| (a.accepted, a.pose));
        let failure = (!accepted).then(|| match attempts.get(best) {
            None => AlignFailure::NoAttempt,
            Some(a) => AlignFailure::NoneAccepted {
                attempts: attempts.len(),
                seeds: seeds.len().max(1),
                best_seed_yaw_deg: a.seed_yaw_offset_deg,
                because: a.rejected_because.clone(),
            },
        });
        AlignReport {
            accepted,
            best_attempt: best,
            transform: pose_rows(&pose),
            pose,
            source_points,
            source_reduce_ms,
            seeds,
            seed_ms,
            correlative_ms,
            total_ms: t0.ms(),
            attempts,
            failure,
        }
    }

    /// The first NDT level whose cell is not too large for the source (`ndt_max_cell_ratio`);
    /// the finest level is always kept.
    fn first_level(&self, ndt_source: &[Vec3]) -> usize {
        let ratio = self.config.ndt_max_cell_ratio;
        let last = self.config.ndt_resolutions_m.len().saturating_sub(1);
        if ratio <= 0.0 || ndt_source.is_empty() {
            return 0;
        }
        let n = ndt_source.len() as f64;
        let centroid = ndt_source.iter().sum::<Vec3>() / n;
        let radius = (ndt_source.iter().map(|p| (p - centroid).norm_squared()).sum::<f64>() / n).sqrt();
        self.config.ndt_resolutions_m.iter().position(|&r| r <= ratio * radius).unwrap_or(last).min(last)
    }

    /// The yaw grid's starts: the guess turned by each yaw offset, at each seed position.
    fn grid_starts(&self, initial: &Isometry3<f64>, shifts: &[[f64; 2]]) -> Vec<SeedStart> {
        let mut yaws = vec![0.0];
        yaws.extend(yaw_offsets_deg(self.config.reseed_yaw_step_deg));
        let mut starts = Vec::with_capacity(yaws.len() * shifts.len());
        for shift in shifts {
            for &yaw in &yaws {
                let rot = UnitQuaternion::from_euler_angles(0.0, 0.0, yaw.to_radians());
                let mut translation = initial.translation;
                translation.vector.x += shift[0];
                translation.vector.y += shift[1];
                let pose = Isometry3::from_parts(translation, rot * initial.rotation);
                starts.push(SeedStart { pose, yaw_offset_deg: yaw, shift_m: *shift, origin: SeedOrigin::YawGrid });
            }
        }
        starts
    }

    /// The global stage's starts (none when it is off or the target had no keypoints), each
    /// given as the yaw and shift that take the guess there.
    fn global_starts(&self, source: &[Vec3], initial: &Isometry3<f64>) -> Vec<SeedStart> {
        let c = &self.config;
        if c.global_candidates == 0 || self.global_target.points.is_empty() {
            return Vec::new();
        }
        let described = global::describe(source, c, c.global_source_keypoints);
        let pairs = global::matches(&described, &self.global_target, c.global_matches_per_point);
        global::consensus(&pairs, c)
            .into_iter()
            .map(|g| {
                // Both clouds are level, so the candidate (a turn about the vertical) is used as
                // it is; its yaw and shift from the guess are for the report.
                let yaw = g.pose.rotation.euler_angles().2 - initial.rotation.euler_angles().2;
                let yaw = yaw.sin().atan2(yaw.cos());
                let pose = g.pose;
                let shift = pose.translation.vector - initial.translation.vector;
                SeedStart {
                    pose,
                    yaw_offset_deg: yaw.to_degrees(),
                    shift_m: [shift.x, shift.y],
                    origin: SeedOrigin::Global { votes: g.votes },
                }
            })
            .collect()
    }

    /// The correlative stage over the whole target (none when it is off, or the target or the
    /// source has no structure in its band).
    fn correlative_search(&self, source: &[Vec3]) -> Option<CorrelativeSearch> {
        let c = &self.config;
        if c.correlative_seeds == 0 {
            return None;
        }
        let params = self.correlative_params();
        let grid = TargetGrid::new(&self.icp_target.index.points, self.coverage.as_deref(), &params)?;
        let band = grid.source_band(source, &params)?;
        let peaks = grid.search_band(&band, &params);
        tracing::debug!(scores = ?peaks.iter().map(|p| p.score).collect::<Vec<_>>(), "correlative peaks");
        Some(CorrelativeSearch { grid, band, peaks })
    }

    fn correlative_params(&self) -> CorrelativeParams {
        let c = &self.config;
        CorrelativeParams {
            cell_m: c.correlative_cell_m,
            peaks: c.correlative_seeds,
            free_penalty: c.correlative_free_penalty,
            min_crossings: c.overlap_min_crossings,
            max_source_points: c.seed_max_points,
            min_score: c.correlative_min_score,
            max_expansions: CORRELATIVE_MAX_EXPANSIONS,
            within_best: c.correlative_within_best,
        }
    }

    /// The correlative stage's places, best first, as seeds scored (not refined) on the last
    /// seed level.
    fn correlative_seeds(
        &self,
        search: Option<&CorrelativeSearch>,
        initial: &Isometry3<f64>,
        seed_source: &[Vec3],
        first_level: usize,
    ) -> Vec<Seed> {
        let Some(search) = search else { return Vec::new() };
        let levels = (first_level + self.config.seed_levels).min(self.grids.len());
        let n = seed_source.len().max(1) as f64;
        search
            .peaks
            .iter()
            .enumerate()
            .map(|(rank, peak)| {
                let (score, matched) =
                    self.grids.get(levels.saturating_sub(1)).map_or((0.0, 0), |g| g.score(seed_source, &peak.pose));
                let yaw = peak.pose.rotation.euler_angles().2 - initial.rotation.euler_angles().2;
                let shift = peak.pose.translation.vector - initial.translation.vector;
                Seed {
                    origin: SeedOrigin::Correlative { rank },
                    yaw_offset_deg: yaw.sin().atan2(yaw.cos()).to_degrees(),
                    shift_m: [shift.x, shift.y],
                    score: score / n,
                    matched_ratio: matched as f64 / n,
                    pose: peak.pose,
                }
            })
            .collect()
    }

    /// An accepted attempt must be the best place over the whole map by the correlative score,
    /// ahead of every other place by `correlative_margin`: a symmetric building or two rooms
    /// alike fit the view equally, and then the first fit found is a coin toss.
    fn check_elsewhere(&self, search: &CorrelativeSearch, a: &mut Attempt) {
        let margin = self.config.correlative_margin;
        let near = |p: &Isometry3<f64>| {
            let (m, deg) = super::geometry::pose_error(p, &a.pose);
            m < CORRELATIVE_SAME_M && deg < CORRELATIVE_SAME_DEG
        };
        let here = search
            .peaks
            .iter()
            .filter(|p| near(&p.pose))
            .map(|p| p.score)
            .fold(search.grid.score(&search.band, &a.pose), f64::max);
        let best_other = search.peaks.iter().filter(|p| !near(&p.pose)).max_by(|x, y| x.score.total_cmp(&y.score));
        if let Some(other) = best_other.filter(|o| o.score > here - margin) {
            let (off_m, off_deg) = super::geometry::pose_error(&other.pose, &a.pose);
            a.accepted = false;
            a.rejected_because.push(Rejection::ElsewhereAsGood {
                off_m,
                off_deg,
                score: other.score,
                here_score: here,
                margin,
            });
        }
    }

    /// An accepted attempt must fit what the map knows at least as well as any other place, where
    /// the rig could stand, fits what the map knows there (`correlative_rivals`): where the
    /// robot mapped one half of a symmetric building and only glimpsed the other, a view of the
    /// glimpsed half fits the mapped half fully and its own place only where the robot looked,
    /// and both are consistent.
    fn check_rivals(&self, search: &CorrelativeSearch, a: &mut Attempt) {
        let c = &self.config;
        if c.correlative_rivals == 0 {
            return;
        }
        let here = search.grid.known_fit(&search.band, &a.pose);
        a.known_fit = Some(here);
        a.rivals = self.rivals(search, &a.pose, here);
        let rival = a.rivals.iter().find(|r| {
            r.fit.known_share >= c.correlative_rival_min_known
                && r.fit.score_on_known >= here.score_on_known - c.correlative_rival_margin
        });
        if let Some(r) = rival {
            a.accepted = false;
            a.rejected_because.push(Rejection::PartlyMappedRival {
                off_m: r.off_m,
                off_deg: r.off_deg,
                known_share: r.fit.known_share,
                score_on_known: r.fit.score_on_known,
                here_score_on_known: here.score_on_known,
            });
        }
    }

    /// Places other than `pose` where the rig could stand (its origin where the robot saw
    /// through), searched with seen-through space costing `correlative_rival_free_penalty`, each
    /// judged on what the map knows there. Only places that could refuse `pose` (whose fit on
    /// what the map knows is `here`) are searched for: see [`rival_min_score`].
    fn rivals(&self, search: &CorrelativeSearch, pose: &Isometry3<f64>, here: KnownFit) -> Vec<Rival> {
        let c = &self.config;
        let params = CorrelativeParams {
            peaks: c.correlative_rivals,
            min_score: c.correlative_rival_min_score.max(rival_min_score(c, here)),
            within_best: f64::INFINITY,
            ..self.correlative_params()
        };
        let Some(grid) = search.grid.standing(c.correlative_rival_free_penalty) else { return Vec::new() };
        grid.search_band(&search.band, &params)
            .into_iter()
            .map(|peak| {
                let (off_m, off_deg) = super::geometry::pose_error(&peak.pose, pose);
                let fit = search.grid.known_fit(&search.band, &peak.pose);
                Rival { score: peak.score, fit, off_m, off_deg, pose: peak.pose }
            })
            .filter(|r| r.off_m >= CORRELATIVE_SAME_M || r.off_deg >= CORRELATIVE_SAME_DEG)
            .collect()
    }

    /// The seeds refined on the coarse levels, best score first.
    fn rank_seeds(&self, seed_source: &[Vec3], starts: Vec<SeedStart>, first_level: usize) -> Vec<Seed> {
        let c = &self.config;
        let levels = (first_level + c.seed_levels).min(self.grids.len());
        let n = seed_source.len().max(1) as f64;
        // Seeds are ranked on coarse cells, every side alike.
        let unsided = SeenFrom::new(1.0);
        let mut seeds: Vec<Seed> = starts
            .into_iter()
            .map(|start| {
                let mut pose = start.pose;
                for grid in self.grids.iter().take(levels).skip(first_level) {
                    pose = ndt::refine_level(grid, seed_source, &unsided, pose, c.seed_max_iterations).pose;
                }
                let (score, matched) =
                    self.grids.get(levels.saturating_sub(1)).map_or((0.0, 0), |g| g.score(seed_source, &pose));
                Seed {
                    origin: start.origin,
                    yaw_offset_deg: start.yaw_offset_deg,
                    shift_m: start.shift_m,
                    score: score / n,
                    matched_ratio: matched as f64 / n,
                    pose,
                }
            })
            .collect();
        seeds.sort_by(|a, b| a.score.total_cmp(&b.score));
        // Scores are negative (more negative is better): "within the margin" of the best.
        let best = seeds.first().map_or(0.0, |s| s.score);
        let at_guess = |s: &Seed| s.origin == SeedOrigin::YawGrid && s.yaw_offset_deg == 0.0 && s.shift_m == [0.0, 0.0];
        if let Some(i) = seeds.iter().position(at_guess) {
            if i > 0 && seeds.get(i).is_some_and(|s| s.score <= best * (1.0 - c.seed_prior_margin)) {
                let guess = seeds.remove(i);
                seeds.insert(0, guess);
            }
        }
        seeds
    }

    /// One full attempt from `seed`: the NDT levels from `first_level`, ICP, the acceptance
    /// tests, then the consistency and free-space checks of a result that passed them.
    fn attempt(
        &self,
        src: &Sources,
        seed: &Isometry3<f64>,
        first_level: usize,
        seed_yaw_offset_deg: f64,
        seed_shift_m: [f64; 2],
    ) -> Attempt {
        let c = &self.config;
        let t0 = self.config.stopwatch.start();
        let (pose, ndt_iterations) = self.ndt_stage(src.ndt, src.ndt_seen_from, seed, first_level);
        let ndt_ms = t0.ms();
        let t1 = self.config.stopwatch.start();
        let params = self.icp_params(src.seen_from);
        let r = self.icp_stage(src.icp, pose, &params);
        let icp_ms = t1.ms();
        let mut judged = self.judged(r, src.icp);
        let t2 = self.config.stopwatch.start();
        let (probes, verify_hops) = if judged.rejected_because.is_empty() && c.verify_shift_m > 0.0 {
            self.verify_consistency(src.icp, &params, &mut judged)
        } else {
            (Vec::new(), 0)
        };
        let free_space = self.check_free_space(src.rays, &mut judged);
        let verify_ms = t2.ms();
        let Judged { r, rejected_because, pinned, overlap } = judged;
        Attempt {
            seed_yaw_offset_deg,
            seed_shift_m,
            transform: pose_rows(&r.pose),
            pose: r.pose,
            metrics: metrics_of(&r),
            ndt_iterations,
            icp_iterations: r.iterations,
            ndt_ms,
            icp_ms,
            accepted: rejected_because.is_empty(),
            rejected_because,
            probes,
            verify_hops,
            verify_ms,
            alternatives: Vec::new(),
            ambiguous: false,
            free_space,
            pinned,
            overlap,
            rivals: Vec::new(),
            known_fit: None,
        }
    }

    /// NDT from `seed` through every level from `first_level`, coarse to fine: the pose after
    /// the last and the iterations of each.
    fn ndt_stage(
        &self,
        source: &[Vec3],
        seen: &SeenFrom,
        seed: &Isometry3<f64>,
        first_level: usize,
    ) -> (Isometry3<f64>, Vec<u32>) {
        let mut pose = *seed;
        let mut ndt_iterations = Vec::with_capacity(self.grids.len());
        for grid in self.grids.iter().skip(first_level) {
            let level = ndt::refine_level(grid, source, seen, pose, self.config.ndt_max_iterations);
            pose = level.pose;
            ndt_iterations.push(level.iterations);
        }
        (pose, ndt_iterations)
    }

    /// ICP from the NDT result. A degenerate result that explains (nearly) the whole source, so
    /// that no misfit drags it, has its weak directions settled by every pair and ICP runs again
    /// from there, before it is judged.
    fn icp_stage(&self, source: &[Vec3], pose: Isometry3<f64>, params: &IcpParams) -> icp::IcpResult {
        let c = &self.config;
        let r = icp::refine(&self.icp_target, source, pose, params);
        let settle = !at_most(c.min_degeneracy_index, r.degeneracy_index)
            && at_most(c.pinned_min_inlier_ratio, r.inlier_ratio)
            && !c.pinned_slides_m.is_empty();
        if settle {
            if let Some(settled) = self.settle_weak(&r, source, params) {
                return icp::refine(&self.icp_target, source, settled, params);
            }
        }
        r
    }

    /// An ICP result with the acceptance tests' verdict on it ([`Aligner::judge`]).
    fn judged(&self, r: icp::IcpResult, source: &[Vec3]) -> Judged {
        let overlap = self.coverage.as_ref().map(|c| self.overlap(c, source, &r.pose));
        let (rejected_because, pinned) = self.judge(&r, source, overlap.as_ref());
        Judged { r, rejected_because, pinned, overlap }
    }

    /// How `source` placed by `pose` sits against the target and its coverage.
    fn overlap(&self, coverage: &Coverage, source: &[Vec3], pose: &Isometry3<f64>) -> Overlap {
        let c = &self.config;
        let mut o = Overlap { points: source.len(), ..Overlap::default() };
        for s in source {
            let q = (pose * nalgebra::Point3::from(*s)).coords;
            if self.icp_target.index.nearest(&q, c.inlier_distance_m).is_some() {
                o.explained += 1;
            } else if coverage.crossings(&q) >= c.overlap_min_crossings {
                o.contradicted += 1;
            }
        }
        o
    }

    /// Consistency check of a result that passed the tests: from starts around it, ICP must not
    /// settle elsewhere with a clearly lower residual (a neighbouring minimum passes every other
    /// test: 9.7 cm off in the office grid). When one does, ICP continues from there and the new
    /// result is judged again, at most `verify_hops` times; one more such landing rejects it.
    /// Returns the last round of probes and the hops made.
    fn verify_consistency(&self, source: &[Vec3], params: &IcpParams, judged: &mut Judged) -> (Vec<Probe>, u32) {
        let probe_source = thin(source.to_vec(), self.config.verify_max_points);
        let mut hops: u32 = 0;
        loop {
            let (here, found) = self.probe(&probe_source, &judged.r.pose, params);
            let Some(better) = self.better_landing(&here, &found) else { return (found, hops) };
            if hops >= self.config.verify_hops {
                judged.rejected_because.push(inconsistent(&better, &here));
                return (found, hops);
            }
            hops += 1;
            *judged = self.judged(icp::refine(&self.icp_target, source, better.pose, params), source);
            if !judged.rejected_because.is_empty() {
                return (found, hops);
            }
        }
    }

    /// Of the probes, the one with the lowest residual among those that settled away from the
    /// result (beyond `verify_agree_*`) with a residual clearly below its (`verify_margin`) and
    /// enough inliers.
    fn better_landing(&self, here: &Probe, found: &[Probe]) -> Option<Probe> {
        let c = &self.config;
        found
            .iter()
            .filter(|p| {
                (p.moved_m > c.verify_agree_m || p.moved_deg > c.verify_agree_deg)
                    && p.rms_residual_m < here.rms_residual_m * (1.0 - c.verify_margin)
                    && p.inlier_ratio >= c.min_inlier_ratio
            })
            .min_by(|a, b| a.rms_residual_m.total_cmp(&b.rms_residual_m))
            .cloned()
    }

    /// The free-space check of a result that passed every other test, when the source came with
    /// rays: too many rays crossing a mapped surface before their end reject it.
    fn check_free_space(&self, rays: &[Ray], judged: &mut Judged) -> Option<FreeSpace> {
        let c = &self.config;
        let free_space = (judged.rejected_because.is_empty() && c.free_space_rays > 0 && !rays.is_empty())
            .then(|| self.surfels.check(rays, &judged.r.pose, &self.ray_params()));
        if let Some(f) = free_space.as_ref().filter(|f| f.blocked_ratio > c.free_space_max_blocked) {
            judged.rejected_because.push(Rejection::SeesThroughMap {
                blocked: f.blocked,
                rays: f.rays,
                max_ratio: c.free_space_max_blocked,
            });
        }
        free_space
    }

    /// The acceptance tests of an ICP result; one refused for its degeneracy index alone gets
    /// the check of [`PinnedCheck`], and passes when it is pinned.
    fn judge(
        &self,
        r: &icp::IcpResult,
        source: &[Vec3],
        overlap: Option<&Overlap>,
    ) -> (Vec<Rejection>, Option<PinnedCheck>) {
        let c = &self.config;
        let m = metrics_of(r);
        let mut why = self.rejections(&m, overlap);
        let degenerate_only = why.len() == 1 && !at_most(c.min_degeneracy_index, m.degeneracy_index);
        if !degenerate_only || c.pinned_slides_m.is_empty() {
            return (why, None);
        }
        let check = self.pinned_check(r, source);
        if check.pinned {
            why.clear();
            return (why, Some(check));
        }
        let share = check.explained as f64 / check.points.max(1) as f64;
        // The move that lost the fewest points, in the direction it was made along.
        let closest = check
            .directions
            .iter()
            .flat_map(|d| d.moves.iter().map(move |m| (d.translation_share, *m)))
            .max_by_key(|(_, (_, n))| *n);
        why.push(match closest {
            None => Rejection::NotPinnedExplains { share, asked: c.pinned_min_inlier_ratio },
            Some((translation_share, (moved_m, still))) => {
                Rejection::NotPinnedSlides { moved_m, translation_share, still, explained: check.explained }
            }
        });
        (why, Some(check))
    }

    /// A degenerate result's weak directions that are mostly translation, each settled by every
    /// correspondence ([`icp::settle_along`]); `None` when it has none.
    fn settle_weak(&self, r: &icp::IcpResult, source: &[Vec3], params: &IcpParams) -> Option<Isometry3<f64>> {
        let eigen = nalgebra::SymmetricEigen::new(r.information);
        let mut pose = None;
        for (k, &eigenvalue) in eigen.eigenvalues.iter().enumerate() {
            let v = eigen.eigenvectors.column(k);
            let slide = Vec3::new(v[3], v[4], v[5]);
            if at_most(self.config.min_degeneracy_index, eigenvalue) || slide.norm() < SETTLE_MIN_TRANSLATION_SHARE {
                continue;
            }
            let from = pose.unwrap_or(r.pose);
            pose = Some(icp::settle_along(&self.icp_target, source, &from, &slide.normalize(), params));
        }
        pose
    }

    fn pinned_check(&self, r: &icp::IcpResult, source: &[Vec3]) -> PinnedCheck {
        let c = &self.config;
        let points = source.len();
        let explained = icp::explained(&self.icp_target, source, &r.pose, c.inlier_distance_m);
        let mut check = PinnedCheck { points, explained, directions: Vec::new(), pinned: false };
        // A result that leaves part of the source unexplained may be held by its misfits.
        if points == 0 || (explained as f64) < c.pinned_min_inlier_ratio * points as f64 {
            return check;
        }
        let need = ((c.pinned_min_lost * points as f64).ceil() as usize).max(c.pinned_min_lost_points);
        let moved: Vec<Vec3> = source.iter().map(|s| (r.pose * nalgebra::Point3::from(*s)).coords).collect();
        let centre = r.info_centre;
        let radius = r.info_radius_m.max(1e-6);
        let eigen = nalgebra::SymmetricEigen::new(r.information);
        for (k, &eigenvalue) in eigen.eigenvalues.iter().enumerate() {
            if at_most(c.min_degeneracy_index, eigenvalue) {
                continue;
            }
            let v = eigen.eigenvectors.column(k);
            // The information matrix's turns are about `centre`, scaled by `radius`.
            let turn = Vec3::new(v[0], v[1], v[2]) / radius;
            let slide = Vec3::new(v[3], v[4], v[5]);
            let unit_rms = (moved.iter().map(|q| (turn.cross(&(q - centre)) + slide).norm_squared()).sum::<f64>()
                / points as f64)
                .sqrt();
            if unit_rms.is_nan() || unit_rms <= 0.0 {
                continue;
            }
            let mut moves = Vec::with_capacity(2 * c.pinned_slides_m.len());
            for &d in &c.pinned_slides_m {
                for signed in [d, -d] {
                    let e = signed / unit_rms;
                    let rot = UnitQuaternion::from_scaled_axis(turn * e);
                    let shift = centre - rot * centre + slide * e;
                    let step = Isometry3::from_parts(nalgebra::Translation3::from(shift), rot);
                    moves.push((
                        signed,
                        icp::explained(&self.icp_target, source, &(step * r.pose), c.inlier_distance_m),
                    ));
                }
            }
            check.directions.push(WeakDirection { eigenvalue, translation_share: slide.norm(), moves });
        }
        check.pinned = !check.directions.is_empty()
            && check.directions.iter().flat_map(|d| &d.moves).all(|&(_, n)| explained.saturating_sub(n) >= need);
        check
    }

    /// ICP on the thinned `source` from starts perturbed off `pose`: ±`verify_shift_m` along x
    /// and y of the target frame and ±`verify_yaw_deg` about the result's own position. Also the
    /// metrics at `pose` itself on the same points (what the landings are compared with).
    fn probe(&self, source: &[Vec3], pose: &Isometry3<f64>, params: &IcpParams) -> (Probe, Vec<Probe>) {
        let c = &self.config;
        let d = c.verify_shift_m;
        let y = c.verify_yaw_deg;
        let mut starts: Vec<([f64; 2], f64)> =
            vec![([d, 0.0], 0.0), ([-d, 0.0], 0.0), ([0.0, d], 0.0), ([0.0, -d], 0.0)];
        if y > 0.0 {
            starts.extend([([0.0, 0.0], y), ([0.0, 0.0], -y)]);
        }
        let at = Isometry3::from_parts(pose.translation, UnitQuaternion::identity());
        let run = |shift: [f64; 2], yaw: f64, max_iterations: u32| {
            let turn = Isometry3::from_parts(
                nalgebra::Translation3::new(shift[0], shift[1], 0.0),
                UnitQuaternion::from_euler_angles(0.0, 0.0, yaw.to_radians()),
            );
            let start = at * turn * at.inverse() * pose;
            let probe_params = IcpParams {
                max_iterations,
                converged_update: c.verify_converged_update.max(params.converged_update),
                ..*params
            };
            let r = icp::refine(&self.icp_target, source, start, &probe_params);
            let (moved_m, moved_deg) = super::geometry::pose_error(pose, &r.pose);
            Probe {
                shift_m: shift,
                yaw_deg: yaw,
                moved_m,
                moved_deg,
                rms_residual_m: r.rms_residual_m,
                inlier_ratio: r.inlier_ratio,
                iterations: r.iterations,
                pose: r.pose,
            }
        };
        let here = run([0.0, 0.0], 0.0, 0);
        let found = starts.into_iter().map(|(shift, yaw)| run(shift, yaw, c.verify_max_iterations)).collect();
        (here, found)
    }

    fn rejections(&self, m: &AlignMetrics, overlap: Option<&Overlap>) -> Vec<Rejection> {
        let c = &self.config;
        let mut why = Vec::new();
        if !at_most(m.rms_residual_m, c.max_rms_m) {
            why.push(Rejection::Residual { rms_m: m.rms_residual_m, max_m: c.max_rms_m });
        }
        match overlap {
            None if !at_most(c.min_inlier_ratio, m.inlier_ratio) => {
                why.push(Rejection::InlierRatio { ratio: m.inlier_ratio, min: c.min_inlier_ratio });
            }
            None => {}
            Some(o) => {
                if o.contradicted >= MIN_CONTRADICTED_POINTS && !at_most(c.overlap_min_ratio, o.ratio()) {
                    why.push(Rejection::Contradicted {
                        ratio: o.ratio(),
                        min: c.overlap_min_ratio,
                        contradicted: o.contradicted,
                    });
                }
                if !at_most(c.overlap_min_share, o.explained_share()) {
                    why.push(Rejection::TooLittleOverlap { share: o.explained_share(), min: c.overlap_min_share });
                }
            }
        }
        if !at_most(m.update_norm, c.max_update_norm) {
            why.push(Rejection::NotSettled { update_norm: m.update_norm, max: c.max_update_norm });
        }
        if !at_most(c.min_degeneracy_index, m.degeneracy_index) {
            why.push(Rejection::Degenerate {
                index: m.degeneracy_index,
                min: c.min_degeneracy_index,
                slide: weakest_slide(m),
            });
        }
        why
    }
}

/// What the seed search did: its attempts, every seed ranked, and where the time went.
struct Searched {
    attempts: Vec<Attempt>,
    seeds: Vec<Seed>,
    seed_ms: f64,
    correlative_ms: f64,
}

/// The source at each reduction, its rays, and the side its surfaces were seen from.
struct Sources<'a> {
    ndt: &'a [Vec3],
    icp: &'a [Vec3],
    rays: &'a [Ray],
    seen_from: &'a SeenFrom,
    /// The same at the NDT source's reduction.
    ndt_seen_from: &'a SeenFrom,
}

/// An ICP result and the acceptance tests' verdict on it.
struct Judged {
    r: icp::IcpResult,
    /// Which tests failed (empty when it passed).
    rejected_because: Vec<Rejection>,
    pinned: Option<PinnedCheck>,
    overlap: Option<Overlap>,
}

/// The least search score (on the standing grid) of a place that could refuse an accepted
/// place whose fit on what the map knows is `here`. Such a rival has at least
/// `correlative_rival_min_known` of the window's points on known cells, and their mean value
/// (structure at most 1, seen-through space `-correlative_free_penalty`) at least
/// `m = here - correlative_rival_margin`. That caps the seen-through share of its known points
/// at `(1 - m) / (1 + free_penalty)`, and each of those costs the rival search
/// `rival_free_penalty - free_penalty` more than it costs the mean.
pub(super) fn rival_min_score(c: &AlignConfig, here: KnownFit) -> f64 {
    let m = here.score_on_known - c.correlative_rival_margin;
    let extra = (c.correlative_rival_free_penalty - c.correlative_free_penalty).max(0.0);
    let per_known = m - extra * (1.0 - m).max(0.0) / (1.0 + c.correlative_free_penalty);
    // Least over known shares from `min_known` to 1; a hair below, so that float sums of the
    // same points never drop a rival on the line.
    let least = if per_known >= 0.0 { c.correlative_rival_min_known * per_known } else { per_known };
    least - 1e-6
}

/// Why a result is refused when ICP from a start off it still lands on a better fit after
/// every hop allowed.
fn inconsistent(better: &Probe, here: &Probe) -> Rejection {
    Rejection::Inconsistent {
        start_off_m: better.shift_m[0].hypot(better.shift_m[1]),
        start_off_deg: better.yaw_deg.abs(),
        moved_m: better.moved_m,
        moved_deg: better.moved_deg,
        rms_m: better.rms_residual_m,
        here_rms_m: here.rms_residual_m,
    }
}

fn metrics_of(r: &icp::IcpResult) -> AlignMetrics {
    // Into the source frame: J_target = B J_source with B = diag(R, R), so H_source = Bᵀ H B.
    let rot = r.pose.rotation.to_rotation_matrix().into_inner();
    let mut b = nalgebra::Matrix6::zeros();
    b.fixed_view_mut::<3, 3>(0, 0).copy_from(&rot);
    b.fixed_view_mut::<3, 3>(3, 3).copy_from(&rot);
    let h = b.transpose() * r.information * b;
    let mut information = [[0.0; 6]; 6];
    for (i, row) in information.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            *v = h[(i, j)];
        }
    }
    let centre = r.pose.inverse_transform_point(&nalgebra::Point3::from(r.info_centre)).coords;
    AlignMetrics {
        information,
        information_centre_m: [centre.x, centre.y, centre.z],
        information_radius_m: r.info_radius_m,
        rms_residual_m: r.rms_residual_m,
        inlier_ratio: r.inlier_ratio,
        update_norm: r.update_norm,
        degeneracy_index: r.degeneracy_index,
        correspondences: r.correspondences,
    }
}

/// Share of the weakest direction's (unit) eigenvector that must be translation for it to be
/// named a slide rather than a turn.
const SLIDE_MIN_TRANSLATION_SHARE: f64 = 0.7;

/// The weakest direction of a result, in the source's frame, when it is mostly a translation.
fn weakest_slide(m: &AlignMetrics) -> Option<[f64; 3]> {
    let h = nalgebra::Matrix6::from_fn(|i, j| m.information[i][j]);
    let eigen = nalgebra::SymmetricEigen::new(h);
    let k = eigen.eigenvalues.iter().enumerate().min_by(|a, b| a.1.total_cmp(b.1))?.0;
    let v = eigen.eigenvectors.column(k);
    let slide = Vec3::new(v[3], v[4], v[5]);
    (slide.norm() >= SLIDE_MIN_TRANSLATION_SHARE).then(|| slide.normalize()).map(|d| [d.x, d.y, d.z])
}

/// `a <= b`, false when either is NaN (so a NaN metric fails its acceptance test).
fn at_most(a: f64, b: f64) -> bool {
    a <= b
}

/// Yaw offsets of the reseeding grid (degrees, in (-180, 180], 0 left out), nearest first.
pub fn yaw_offsets_deg(step_deg: f64) -> Vec<f64> {
    let n = (360.0 / step_deg).round().max(1.0) as u32;
    let step = 360.0 / f64::from(n);
    let mut offsets: Vec<f64> =
        (1..n).map(|k| f64::from(k) * step).map(|o| if o > 180.0 { o - 360.0 } else { o }).collect();
    offsets.sort_by(|a, b| a.abs().total_cmp(&b.abs()).then(b.total_cmp(a)));
    offsets
}
