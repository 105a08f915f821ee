//! The aligner: a prepared target (NDT grids and ICP normals), attempts of NDT then ICP from a
//! seed, acceptance, and the yaw-grid reseeding around the circle.

use super::config::AlignConfig;
use super::geometry::{estimate_normals, pose_rows, voxel_downsample, Vec3, VoxelIndex};
use super::icp::{self, IcpParams, IcpTarget};
use super::ndt::{self, NdtGrid};
use crate::PipelineError;
use nalgebra::{Isometry3, UnitQuaternion};
use serde::Serialize;
use std::time::Instant;

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
    /// and `ρ` their RMS distance from it. Unit-free, in [0, 1/3]; near 0 means a degenerate direction.
    pub degeneracy_index: f64,
    /// Correspondences ICP kept at the result.
    pub correspondences: usize,
}

/// One NDT+ICP run from one seed.
#[derive(Clone, Debug, Serialize)]
pub struct Attempt {
    /// Yaw added to the initial guess for this seed (0 for the initial guess itself).
    pub seed_yaw_offset_deg: f64,
    /// The result: a 4x4 row-major transform mapping source points into the target frame.
    pub transform: [[f64; 4]; 4],
    #[serde(skip)]
    pub pose: Isometry3<f64>,
    pub metrics: AlignMetrics,
    /// Gauss-Newton iterations of each NDT level, coarse to fine.
    pub ndt_iterations: Vec<u32>,
    pub icp_iterations: u32,
    pub ndt_ms: f64,
    pub icp_ms: f64,
    pub accepted: bool,
    /// Which acceptance tests failed (empty when accepted).
    pub rejected_because: Vec<String>,
}

/// Everything one call to [`Aligner::align`] did.
#[derive(Clone, Debug, Serialize)]
pub struct AlignReport {
    /// Whether the chosen attempt passed every acceptance test.
    pub accepted: bool,
    /// The chosen attempt (best accepted one; when none was accepted, the one with the highest
    /// inlier ratio, for diagnosis only).
    pub best_attempt: usize,
    pub transform: [[f64; 4]; 4],
    #[serde(skip)]
    pub pose: Isometry3<f64>,
    pub source_points: usize,
    pub source_reduce_ms: f64,
    pub total_ms: f64,
    pub attempts: Vec<Attempt>,
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
    /// Time spent preparing the target.
    pub prepare_ms: f64,
}

fn ms_since(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

impl Aligner {
    pub fn new(target: &[Vec3], config: AlignConfig) -> Result<Self, PipelineError> {
        config.validate()?;
        let t0 = Instant::now();
        let ndt_target = voxel_downsample(target, config.ndt_target_voxel_m);
        let grids: Vec<NdtGrid> =
            config.ndt_resolutions_m.iter().map(|&r| NdtGrid::new(&ndt_target, r, config.ndt_outlier_ratio)).collect();
        let icp_points = voxel_downsample(target, config.icp_voxel_m);
        let normals = estimate_normals(&icp_points, config.normal_radius_m, config.normal_neighbours);
        let index = VoxelIndex::new(icp_points, config.icp_max_correspondence_m);
        if grids.iter().all(|g| g.cell_count() == 0) || normals.iter().all(Option::is_none) {
            return Err(PipelineError::BadFile {
                format: "align target",
                reason: format!("too few points ({}) to align against", target.len()),
            });
        }
        Ok(Self { config, grids, icp_target: IcpTarget { index, normals }, prepare_ms: ms_since(t0) })
    }

    pub fn config(&self) -> &AlignConfig {
        &self.config
    }

    /// Aligns `source` to the target from `initial` (a guess of the transform mapping source into
    /// target); when that attempt is rejected and reseeding is on, tries yaw seeds around the
    /// circle (rotating the guess about its own position) and keeps the best accepted one.
    pub fn align(&self, source: &[Vec3], initial: &Isometry3<f64>) -> AlignReport {
        let t0 = Instant::now();
        let ndt_source = voxel_downsample(source, self.config.ndt_source_voxel_m);
        let icp_source = voxel_downsample(source, self.config.icp_voxel_m);
        let source_reduce_ms = ms_since(t0);
        let mut attempts = vec![self.attempt(&ndt_source, &icp_source, initial, 0.0)];
        let step = self.config.reseed_yaw_step_deg;
        if !attempts.iter().any(|a| a.accepted) && step > 0.0 {
            for offset in yaw_offsets_deg(step) {
                let rot = UnitQuaternion::from_euler_angles(0.0, 0.0, offset.to_radians());
                let seed = Isometry3::from_parts(initial.translation, rot * initial.rotation);
                attempts.push(self.attempt(&ndt_source, &icp_source, &seed, offset));
            }
        }
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
        AlignReport {
            accepted,
            best_attempt: best,
            transform: pose_rows(&pose),
            pose,
            source_points: icp_source.len(),
            source_reduce_ms,
            total_ms: ms_since(t0),
            attempts,
        }
    }

    fn attempt(
        &self,
        ndt_source: &[Vec3],
        icp_source: &[Vec3],
        seed: &Isometry3<f64>,
        seed_yaw_offset_deg: f64,
    ) -> Attempt {
        let c = &self.config;
        let t0 = Instant::now();
        let mut pose = *seed;
        let mut ndt_iterations = Vec::with_capacity(self.grids.len());
        for grid in &self.grids {
            let level = ndt::refine_level(grid, ndt_source, pose, c.ndt_max_iterations);
            pose = level.pose;
            ndt_iterations.push(level.iterations);
        }
        let ndt_ms = ms_since(t0);
        let t1 = Instant::now();
        let params = IcpParams {
            max_correspondence_m: c.icp_max_correspondence_m,
            trim_ratio: c.icp_trim_ratio,
            huber_m: c.icp_huber_m,
            max_iterations: c.icp_max_iterations,
            converged_update: c.icp_converged_update,
            inlier_distance_m: c.inlier_distance_m,
        };
        let r = icp::refine(&self.icp_target, icp_source, pose, &params);
        let icp_ms = ms_since(t1);
        let metrics = AlignMetrics {
            rms_residual_m: r.rms_residual_m,
            inlier_ratio: r.inlier_ratio,
            update_norm: r.update_norm,
            degeneracy_index: r.degeneracy_index,
            correspondences: r.correspondences,
        };
        let rejected_because = self.rejections(&metrics);
        Attempt {
            seed_yaw_offset_deg,
            transform: pose_rows(&r.pose),
            pose: r.pose,
            metrics,
            ndt_iterations,
            icp_iterations: r.iterations,
            ndt_ms,
            icp_ms,
            accepted: rejected_because.is_empty(),
            rejected_because,
        }
    }

    fn rejections(&self, m: &AlignMetrics) -> Vec<String> {
        let c = &self.config;
        let mut why = Vec::new();
        if !at_most(m.rms_residual_m, c.max_rms_m) {
            why.push(format!("rms residual {:.4} m > {} m", m.rms_residual_m, c.max_rms_m));
        }
        if !at_most(c.min_inlier_ratio, m.inlier_ratio) {
            why.push(format!("inlier ratio {:.3} < {}", m.inlier_ratio, c.min_inlier_ratio));
        }
        if !at_most(m.update_norm, c.max_update_norm) {
            why.push(format!("update norm {:.2e} > {:.0e}", m.update_norm, c.max_update_norm));
        }
        if !at_most(c.min_degeneracy_index, m.degeneracy_index) {
            why.push(format!("degeneracy index {:.2e} < {:.0e}", m.degeneracy_index, c.min_degeneracy_index));
        }
        why
    }
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
