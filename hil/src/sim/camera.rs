//! The responder's first-person camera: a pinhole on the rig, and per frame the two person
//! masks the evaluation needs: see-through (people as if walls were glass) and visible-only.
//! Pixel values are person labels (1..=250), 0 for no one.

use crate::error::Result;
use crate::sim::human::Body;
use crate::sim::motion::mount_pose;
use crate::sim::scenario::Camera;
use crate::sim::shapes::V3;
use crate::sim::truth::out_err;
use crate::sim::world::World;
use nalgebra::{Isometry3, Matrix3, Point3, Rotation3, UnitQuaternion};
use std::path::Path;

/// The camera model and its mounting on the rig's LiDAR.
#[derive(Clone, Debug)]
pub struct PinholeCamera {
    pub model: Camera,
    /// Camera optical frame (x right, y down, z forward) in the LiDAR frame.
    pub lidar_camera: Isometry3<f64>,
}

/// The two masks of one frame.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Masks {
    pub width: u32,
    pub height: u32,
    pub see_through: Vec<u8>,
    pub visible: Vec<u8>,
}

impl Masks {
    /// Pixels of person `label` in the see-through and the visible mask.
    pub fn count(&self, label: u8) -> (usize, usize) {
        (self.see_through.iter().filter(|&&v| v == label).count(), self.visible.iter().filter(|&&v| v == label).count())
    }
}

impl PinholeCamera {
    pub fn new(model: Camera) -> Self {
        // Optical axes expressed in the LiDAR frame: x right = -y, y down = -z, z forward = +x.
        let optical = Matrix3::new(0.0, 0.0, 1.0, -1.0, 0.0, 0.0, 0.0, -1.0, 0.0);
        let optical = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(optical));
        let lidar_camera = mount_pose(&model.mount) * Isometry3::from_parts(Default::default(), optical);
        Self { model, lidar_camera }
    }

    /// Projects a world point into pixels, if it is in front of the camera.
    pub fn project(&self, world_camera: &Isometry3<f64>, p: &V3) -> Option<(f64, f64)> {
        let c = world_camera.inverse_transform_point(&Point3::from(*p));
        (c.z > 1e-3)
            .then(|| (self.model.fx_px * c.x / c.z + self.model.cx_px, self.model.fy_px * c.y / c.z + self.model.cy_px))
    }

    /// Renders both masks with the rig's LiDAR at `world_lidar`.
    pub fn render(&self, world: &World, bodies: &[Body], world_lidar: &Isometry3<f64>) -> Masks {
        let m = &self.model;
        let (w, h) = (m.width_px, m.height_px);
        let mut see_through = vec![0u8; (w * h) as usize];
        let mut visible = vec![0u8; (w * h) as usize];
        let world_camera = world_lidar * self.lidar_camera;
        let origin = world_camera.translation.vector;
        for body in bodies {
            // Only the pixels inside the projection of the body's bounding box can see it.
            let (lo, hi) = (body.bounds.min, body.bounds.max);
            let mut u_range = (f64::INFINITY, f64::NEG_INFINITY);
            let mut v_range = (f64::INFINITY, f64::NEG_INFINITY);
            let mut behind = false;
            for i in 0..8 {
                let corner = V3::new(
                    if i & 1 == 0 { lo.x } else { hi.x },
                    if i & 2 == 0 { lo.y } else { hi.y },
                    if i & 4 == 0 { lo.z } else { hi.z },
                );
                match self.project(&world_camera, &corner) {
                    Some((u, v)) => {
                        u_range = (u_range.0.min(u), u_range.1.max(u));
                        v_range = (v_range.0.min(v), v_range.1.max(v));
                    }
                    None => behind = true,
                }
            }
            if behind {
                // Part of the box is behind the camera: fall back to the whole image.
                u_range = (0.0, f64::from(w));
                v_range = (0.0, f64::from(h));
            }
            let u0 = u_range.0.floor().max(0.0) as u32;
            let u1 = (u_range.1.ceil().max(0.0) as u32).min(w);
            let v0 = v_range.0.floor().max(0.0) as u32;
            let v1 = (v_range.1.ceil().max(0.0) as u32).min(h);
            for v in v0..v1 {
                for u in u0..u1 {
                    let ray_c = V3::new(
                        (f64::from(u) + 0.5 - m.cx_px) / m.fx_px,
                        (f64::from(v) + 0.5 - m.cy_px) / m.fy_px,
                        1.0,
                    );
                    let d = (world_camera.rotation * ray_c).normalize();
                    let idx = (v * w + u) as usize;
                    let inv = d.map(|x| 1.0 / x);
                    let Some(hit) = body.cast(&origin, &d, &inv, 1e3) else { continue };
                    // A nearer person already claimed this pixel.
                    let nearer = World::cast_people(&origin, &d, hit.t, bodies).is_some_and(|o| o.label != body.label);
                    if nearer {
                        continue;
                    }
                    let label = u8::try_from(body.label).unwrap_or(u8::MAX);
                    if let Some(px) = see_through.get_mut(idx) {
                        *px = label;
                    }
                    if world.building.cast(&origin, &d, hit.t - 1e-6).is_none() {
                        if let Some(px) = visible.get_mut(idx) {
                            *px = label;
                        }
                    }
                }
            }
        }
        Masks { width: w, height: h, see_through, visible }
    }
}

/// Writes an 8-bit greyscale PNG.
pub fn write_png(path: &Path, width: u32, height: u32, pixels: &[u8]) -> Result<()> {
    let file = std::fs::File::create(path).map_err(|e| out_err(path, e))?;
    let mut encoder = png::Encoder::new(std::io::BufWriter::new(file), width, height);
    encoder.set_color(png::ColorType::Grayscale);
    encoder.set_depth(png::BitDepth::Eight);
    let mut writer = encoder.write_header().map_err(|e| out_err(path, e))?;
    writer.write_image_data(pixels).map_err(|e| out_err(path, e))?;
    writer.finish().map_err(|e| out_err(path, e))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::motion::pose_xyz_rpy;
    use crate::sim::scenario::Scenario;

    #[test]
    fn a_person_behind_a_wall_is_only_in_the_see_through_mask() {
        let text = format!(
            "{}[robot]\nwaypoints = [[0, 0, 0]]\n[responder]\nwaypoints = [[0, 0]]\n",
            crate::sim::fixtures::WALL_AND_DOORWAY
        );
        let scenario = match Scenario::parse(&text, "t") {
            Ok(s) => s,
            Err(e) => panic!("{e}"),
        };
        let world = World::new(&scenario);
        let bodies = world.bodies_at(0.0);
        let camera = PinholeCamera::new(Camera { mount: [0.0; 6], ..Camera::default() });
        let rig = pose_xyz_rpy(V3::new(0.0, 0.0, 1.5), 0.0, 0.0, 0.0);
        let masks = camera.render(&world, &bodies, &rig);
        let (hidden_see, hidden_vis) = masks.count(1);
        let (door_see, door_vis) = masks.count(2);
        assert!(hidden_see > 2000, "{hidden_see}");
        assert_eq!(hidden_vis, 0);
        assert!(door_see > 2000 && door_vis > door_see / 3 && door_vis < door_see, "{door_see} {door_vis}");
        // The hidden person's centre projects near the image centre (straight ahead, below eye level).
        let p = camera.project(&(rig * camera.lidar_camera), &V3::new(6.0, 0.0, 1.5));
        assert!(matches!(p, Some((u, v)) if (u - 320.0).abs() < 1e-6 && (v - 240.0).abs() < 1e-6), "{p:?}");
    }
}
