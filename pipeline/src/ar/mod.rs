//! The responder's first-person AR view: detected people (their points and, optionally, their
//! oriented boxes) projected from the world into the responder's camera and drawn in red over
//! the rig's own depth-shaded points, see-through (people are drawn on top of whatever walls
//! stand in between), with a status line (alignment, detection age, link).
//!
//! The paper's projection `p_fpv = fpvT_w(t) * wT_r(t) * p`: callers hand in person points
//! already in the world (the detector works in the world frame) and the camera's pose in the
//! world (`world_t_camera`, the responder's aligned pose composed with the camera mounting);
//! [`project_people`] applies its inverse and the pinhole [`CameraModel`].
//!
//! ```no_run
//! # use starc_pipeline::ar::*;
//! # fn f(people: &[ArPerson], rig: &[nalgebra::Vector3<f64>], pose: nalgebra::Isometry3<f64>) -> Result<(), starc_pipeline::PipelineError> {
//! let camera = CameraModel::default();
//! let status = ArStatus { aligned: true, detection_age_ms: Some(80.0), link: "OK".into(), text: String::new() };
//! let frame = render(&camera, &pose, rig, people, &status, &RenderConfig::default());
//! std::fs::write("ar.png", frame.to_png()?).ok();
//! # Ok(()) }
//! ```

mod camera;
mod config;
pub mod font;
mod frame;
pub mod inset;
pub mod labels;
mod mask;
mod render;

pub use camera::{CameraModel, NEAR_M};
pub use config::RenderConfig;
pub use frame::ArFrame;
pub use mask::{mask_inlier_ratio, read_mask_png};
pub use render::{box_corners, render, render_in, BOX_EDGES, COLOUR_PERSON, COLOUR_PERSON_STALE};

use nalgebra::{Isometry3, Point3, Vector3};

/// An oriented box in the world (z up): centre, size (length along `yaw_rad`, width, height) and
/// heading about z, as the detector reports it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OrientedBox {
    pub centre_m: Vector3<f64>,
    /// Length, width, height.
    pub size_m: Vector3<f64>,
    pub yaw_rad: f64,
}

/// One person to draw: their points in the world, their box if known, and how old the
/// detection is at render time.
#[derive(Clone, Debug, PartialEq)]
pub struct ArPerson {
    pub points_world: Vec<Vector3<f64>>,
    pub bbox: Option<OrientedBox>,
    pub age_ns: u64,
    /// The posture the detector judged, shown in the label (`None`: not known, e.g. from a
    /// robot whose link format does not carry it).
    pub pose: Option<crate::detect::PersonPose>,
}

/// What the status line shows.
#[derive(Clone, Debug, PartialEq)]
pub struct ArStatus {
    /// Whether the responder is aligned to the robot's map; people are only drawn when true.
    pub aligned: bool,
    /// Age of the newest detection, if there is one.
    pub detection_age_ms: Option<f64>,
    /// Link state to the robot, shown as given (e.g. "OK", "LOST 2.1 S").
    pub link: String,
    /// Anything else (e.g. why alignment is off); may be empty.
    pub text: String,
}

/// One projected human point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ProjectedPoint {
    pub u: f64,
    pub v: f64,
    pub depth_m: f64,
    /// Index of the person in the slice handed to [`project_people`].
    pub person: usize,
}

/// Projects every person's points into the image; points behind the camera or outside the
/// image are left out. `world_t_camera` maps camera-frame points into the world (the camera's
/// pose in the world). Appends to `out` (not cleared here).
pub fn project_people(
    camera: &CameraModel,
    world_t_camera: &Isometry3<f64>,
    people: &[ArPerson],
    out: &mut Vec<ProjectedPoint>,
) {
    let camera_t_world = world_t_camera.inverse();
    for (person, p) in people.iter().enumerate() {
        for q in &p.points_world {
            let c = camera_t_world.transform_point(&Point3::from(*q)).coords;
            if let Some((u, v)) = camera.project(&c) {
                out.push(ProjectedPoint { u, v, depth_m: c.z, person });
            }
        }
    }
}

#[cfg(test)]
mod tests;
