//! The LIO's inputs: IMU samples and timed points, already decoded. Each says which clock its
//! times are on; one filter takes one clock (its LiDAR's), and refuses the others.

use nalgebra::Vector3;
pub use starc_time::Clock;

/// One IMU sample in the IMU's own frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ImuSample {
    pub t_ns: u64,
    pub clock: Clock,
    pub gyro_rad_s: Vector3<f64>,
    /// Specific force in m/s^2 (convert a device's g first).
    pub acc_m_s2: Vector3<f64>,
}

/// One LiDAR return in the LiDAR frame at its own firing time.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct TimedPoint {
    pub x_m: f32,
    pub y_m: f32,
    pub z_m: f32,
    pub t_ns: u64,
}

impl TimedPoint {
    pub fn xyz(&self) -> Vector3<f64> {
        Vector3::new(f64::from(self.x_m), f64::from(self.y_m), f64::from(self.z_m))
    }
}

/// One sweep of the LiDAR: every point fired in `[start_ns, end_ns)`.
#[derive(Clone, Debug, PartialEq)]
pub struct LioScan {
    pub start_ns: u64,
    pub end_ns: u64,
    /// The clock of `start_ns`, `end_ns` and every point's time.
    pub clock: Clock,
    pub points: Vec<TimedPoint>,
}
