//! Tunables of the aligner, loaded from TOML (`config/align.toml`); every field has a default.

use serde::{Deserialize, Serialize};

/// Alignment settings. Defaults were tuned on the real scan pair in `shared/data/registration`
/// (a 360-degree spinning LiDAR, about 69k points per scan, ranges up to tens of metres).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct AlignConfig {
    /// Coarse stage: NDT grid sizes, coarse to fine.
    pub ndt_resolutions_m: Vec<f64>,
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
    /// Acceptance: norm of ICP's last update, at most (an ICP that had not settled is rejected).
    pub max_update_norm: f64,
    /// Acceptance: degeneracy index (see [`crate::align::AlignMetrics::degeneracy_index`]), at least.
    pub min_degeneracy_index: f64,
    /// Yaw-grid reseeding: spacing of the yaw seeds around the circle (degrees); 0 disables it.
    /// The default, 60, leaves every heading within 30 deg of a seed; on the real pair a single
    /// attempt converged from every yaw error up to 40 deg (with or without a 1 m shift).
    pub reseed_yaw_step_deg: f64,
}

impl Default for AlignConfig {
    fn default() -> Self {
        Self {
            ndt_resolutions_m: vec![8.0, 4.0, 2.0, 1.0, 0.5],
            ndt_source_voxel_m: 0.5,
            ndt_target_voxel_m: 0.1,
            ndt_max_iterations: 20,
            ndt_outlier_ratio: 0.55,
            icp_voxel_m: 0.25,
            normal_radius_m: 1.0,
            normal_neighbours: 12,
            icp_max_correspondence_m: 1.0,
            icp_trim_ratio: 0.8,
            icp_huber_m: 0.1,
            icp_max_iterations: 30,
            icp_converged_update: 1e-5,
            inlier_distance_m: 0.3,
            max_rms_m: 0.1,
            min_inlier_ratio: 0.5,
            max_update_norm: 1e-3,
            min_degeneracy_index: 1e-3,
            reseed_yaw_step_deg: 60.0,
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
        Ok(())
    }
}
