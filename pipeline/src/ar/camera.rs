//! The responder's display camera: a pinhole without distortion (the simulator's camera model;
//! a real display camera is undistorted upstream).

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use crate::PipelineError;

/// Points nearer than this in front of the camera are not projected (they would blow up to huge
/// pixel coordinates and are inside the responder's head anyway).
pub const NEAR_M: f64 = 0.05;

/// Pinhole intrinsics. Pixel coordinates are continuous: pixel (i, j) covers
/// `[i, i + 1) x [j, j + 1)`, so its centre is at `(i + 0.5, j + 0.5)` (the simulator's mask
/// renderer uses the same convention).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraModel {
    pub width: u32,
    pub height: u32,
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
}

impl Default for CameraModel {
    /// The simulator's default camera: 640 x 480, fx = fy = 460 px, principal point centred.
    fn default() -> Self {
        Self { width: 640, height: 480, fx: 460.0, fy: 460.0, cx: 320.0, cy: 240.0 }
    }
}

impl CameraModel {
    /// Pixel (u right, v down) of a point in the camera's optical frame (x right, y down, z
    /// forward); None when behind (z < 0.05 m) or outside the image.
    pub fn project(&self, p_cam: &Vector3<f64>) -> Option<(f64, f64)> {
        let (u, v) = self.project_unclipped(p_cam)?;
        let inside = (0.0..f64::from(self.width)).contains(&u) && (0.0..f64::from(self.height)).contains(&v);
        inside.then_some((u, v))
    }

    /// Like [`Self::project`] but keeps pixels outside the image (line clipping needs them);
    /// still None behind the near plane or for non-finite results.
    pub fn project_unclipped(&self, p_cam: &Vector3<f64>) -> Option<(f64, f64)> {
        if p_cam.z.is_nan() || p_cam.z < NEAR_M {
            return None;
        }
        let u = self.fx * p_cam.x / p_cam.z + self.cx;
        let v = self.fy * p_cam.y / p_cam.z + self.cy;
        (u.is_finite() && v.is_finite()).then_some((u, v))
    }

    /// Rejects models no image can come from.
    pub fn validate(&self) -> Result<(), PipelineError> {
        let bad = |reason: String| PipelineError::BadFile { format: "camera model", reason };
        if self.width == 0 || self.height == 0 || u64::from(self.width) * u64::from(self.height) > 1 << 26 {
            return Err(bad(format!("image size {} x {} out of range", self.width, self.height)));
        }
        let focal_ok = |f: f64| f.is_finite() && f > 0.0;
        if !focal_ok(self.fx) || !focal_ok(self.fy) {
            return Err(bad(format!("focal lengths {} / {} must be positive", self.fx, self.fy)));
        }
        if !(self.cx.is_finite() && self.cy.is_finite()) {
            return Err(bad("principal point must be finite".into()));
        }
        Ok(())
    }
}
