//! Settings of the AR renderer, loaded from TOML (`config/ar.toml`); every field has a default.

use crate::PipelineError;
use serde::{Deserialize, Serialize};

/// How [`crate::ar::render`] draws a frame.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RenderConfig {
    /// Draw each person's oriented box as a red wireframe (the paper's optional hint) besides
    /// their points.
    pub draw_boxes: bool,
    /// Radius of a person's point, in pixels (0: one pixel). The rig's own points are always one
    /// pixel.
    pub point_radius_px: u32,
    /// The rig's points farther than this are not drawn. People are drawn at any depth.
    pub max_depth_m: f64,
    /// The rig's points are shaded from bright (near) to dark at this depth and beyond: indoors
    /// most of what matters is within it, and the contrast shows the room's shape.
    pub shade_depth_m: f64,
    /// Each of the rig's points is drawn as a square this wide in the world (the view's voxel),
    /// so near surfaces stay surfaces: 1 to `MAX_SPLAT_PX` pixels on screen.
    pub point_size_m: f64,
    /// A person whose detection is older than this is drawn dimmed (the overlay may lag the
    /// person), and the status line flags the detection age as stale.
    pub stale_after_ms: f64,
    /// Over each person in view, their distance from the camera (and their detection's age once
    /// stale); for each person out of view, an arrow at the frame's edge with the distance.
    pub label_people: bool,
    /// Side of the top-down map in the lower right corner, pixels (0: none); it shows the
    /// robot's map `inset_range_m` around the responder, heading-up, once aligned.
    pub inset_px: u32,
    pub inset_range_m: f64,
    /// The inset with the map's +y up and the responder's arrow turning, instead of
    /// heading-up (the map turning with the responder).
    pub inset_north_up: bool,
}

impl Default for RenderConfig {
    fn default() -> Self {
        Self {
            draw_boxes: true,
            point_radius_px: 2,
            max_depth_m: 30.0,
            shade_depth_m: 6.0,
            point_size_m: 0.04,
            stale_after_ms: 500.0,
            label_people: true,
            inset_px: 160,
            inset_range_m: 8.0,
            inset_north_up: false,
        }
    }
}

impl RenderConfig {
    /// Parses and validates a TOML document.
    pub fn from_toml(text: &str) -> Result<Self, PipelineError> {
        let config: Self =
            toml::from_str(text).map_err(|e| PipelineError::BadFile { format: "AR config", reason: e.to_string() })?;
        config.validate()?;
        Ok(config)
    }

    /// Rejects settings the renderer cannot use.
    pub fn validate(&self) -> Result<(), PipelineError> {
        let bad = |reason: String| Err(PipelineError::BadFile { format: "AR config", reason });
        if !(self.max_depth_m.is_finite() && self.max_depth_m > 0.0) {
            return bad(format!("max_depth_m must be positive, not {}", self.max_depth_m));
        }
        if !(self.shade_depth_m.is_finite() && self.shade_depth_m > 0.0) {
            return bad(format!("shade_depth_m must be positive, not {}", self.shade_depth_m));
        }
        if !(self.point_size_m.is_finite() && self.point_size_m >= 0.0) {
            return bad(format!("point_size_m must be >= 0, not {}", self.point_size_m));
        }
        if self.stale_after_ms.is_nan() || self.stale_after_ms < 0.0 {
            return bad(format!("stale_after_ms must be >= 0, not {}", self.stale_after_ms));
        }
        if !(self.inset_range_m.is_finite() && self.inset_range_m > 0.0) {
            return bad(format!("inset_range_m must be positive, not {}", self.inset_range_m));
        }
        if self.point_radius_px > 32 {
            return bad(format!("point_radius_px must be <= 32, not {}", self.point_radius_px));
        }
        Ok(())
    }
}
