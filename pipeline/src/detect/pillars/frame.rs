//! The model frame of a detection window (docs/pillars.md): origin under the sensor, x along its
//! heading, z as height above the window's floor. The dataset exporter and the detector both
//! move points through this one type, so training and inference see the same numbers.

use super::super::{estimate_floor, DetectConfig, DetectWindow, FloorModel, WindowPoint};
use nalgebra::{Isometry3, Vector3};

/// A floor more than this far below the sensor is the estimator's "none found" (it puts the
/// floor 10 m down): no robot or rig carries its LiDAR that high.
const MAX_SENSOR_HEIGHT_M: f64 = 3.0;

/// One window's model frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ModelFrame {
    origin_x_m: f64,
    origin_y_m: f64,
    cos_yaw: f64,
    sin_yaw: f64,
    yaw_rad: f64,
    floor: FloorModel,
}

impl ModelFrame {
    /// The frame of a window whose floor is `floor`.
    pub fn new(sensor_pose: &Isometry3<f64>, floor: FloorModel) -> Self {
        let t = sensor_pose.translation.vector;
        // The heading: the sensor's x axis on the floor (roll and pitch dropped).
        let ahead = sensor_pose.rotation * Vector3::x();
        let yaw_rad = ahead.y.atan2(ahead.x);
        let (sin_yaw, cos_yaw) = yaw_rad.sin_cos();
        Self { origin_x_m: t.x, origin_y_m: t.y, cos_yaw, sin_yaw, yaw_rad, floor }
    }

    /// The frame of a window with its floor estimated as the geometric detector estimates it;
    /// without a floor below the sensor, one `sensor_height_m` under it.
    pub fn of_window(window: &DetectWindow<'_>, cfg: &DetectConfig, sensor_height_m: f64) -> Self {
        let sensor_z = window.sensor_pose.translation.vector.z;
        let mut floor = estimate_floor(window.points, sensor_z, cfg);
        if sensor_z - floor.c > MAX_SENSOR_HEIGHT_M || !floor.c.is_finite() {
            floor = FloorModel::flat(sensor_z - sensor_height_m);
        }
        Self::new(&window.sensor_pose, floor)
    }

    pub fn floor(&self) -> &FloorModel {
        &self.floor
    }

    /// The heading of the frame's x axis in the world.
    pub fn yaw_rad(&self) -> f64 {
        self.yaw_rad
    }

    /// A world point in the model frame: ahead, left, height above the floor.
    pub fn to_model(&self, x: f64, y: f64, z: f64) -> [f64; 3] {
        let (dx, dy) = (x - self.origin_x_m, y - self.origin_y_m);
        [self.cos_yaw * dx + self.sin_yaw * dy, -self.sin_yaw * dx + self.cos_yaw * dy, self.floor.height(x, y, z)]
    }

    pub fn point_to_model(&self, p: &WindowPoint) -> [f32; 3] {
        let [x, y, z] = self.to_model(f64::from(p.x_m), f64::from(p.y_m), f64::from(p.z_m));
        [x as f32, y as f32, z as f32]
    }

    /// A model-frame point back in the world.
    pub fn to_world(&self, m: [f64; 3]) -> Vector3<f64> {
        let x = self.origin_x_m + self.cos_yaw * m[0] - self.sin_yaw * m[1];
        let y = self.origin_y_m + self.sin_yaw * m[0] + self.cos_yaw * m[1];
        let z = m[2] + self.floor.a * x + self.floor.b * y + self.floor.c;
        Vector3::new(x, y, z)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion};

    #[test]
    fn a_point_goes_to_the_model_frame_and_back() {
        let pose = Isometry3::from_parts(
            Translation3::new(3.0, -2.0, 0.45),
            UnitQuaternion::from_euler_angles(0.02, -0.01, 1.2),
        );
        let frame = ModelFrame::new(&pose, FloorModel { a: 0.01, b: -0.02, c: 0.05, ceiling_above_floor_m: None });
        let m = frame.to_model(5.0, 1.0, 1.3);
        let back = frame.to_world(m);
        assert!((back - Vector3::new(5.0, 1.0, 1.3)).norm() < 1e-12);
        // Straight ahead of the sensor is +x in the model frame.
        let ahead = frame.to_model(3.0 + 2.0 * 1.2f64.cos(), -2.0 + 2.0 * 1.2f64.sin(), 0.05);
        assert!((ahead[0] - 2.0).abs() < 0.01 && ahead[1].abs() < 0.01, "{ahead:?}");
    }
}
