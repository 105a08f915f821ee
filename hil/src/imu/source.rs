//! What the mock IMU feels: the [`ImuSource`] trait behind every motion, and the still default.

use starc_imu::STANDARD_GRAVITY_M_S2;

/// The true motion of the sensor at one instant, in its own frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Motion {
    /// Angular rate, rad/s.
    pub gyro_rad_s: [f64; 3],
    /// Specific force (what an accelerometer reads: gravity's reaction plus acceleration), m/s^2.
    pub accel_m_s2: [f64; 3],
    /// Orientation (w, x, y, z) for devices that send one.
    pub orientation_wxyz: [f64; 4],
}

impl Motion {
    /// At rest and level with `up` the sensor axis against gravity (+z for a WitMotion lying flat;
    /// a MicroStrain's z points down, so at rest it reads -1 g on z).
    pub fn still(z_up: bool) -> Self {
        let g = if z_up { STANDARD_GRAVITY_M_S2 } else { -STANDARD_GRAVITY_M_S2 };
        Self { gyro_rad_s: [0.0; 3], accel_m_s2: [0.0, 0.0, g], orientation_wxyz: [1.0, 0.0, 0.0, 0.0] }
    }
}

/// The motion the mock measures. The simulator plugs its own in; [`Still`] is the default.
pub trait ImuSource: Send {
    /// The true motion at `t_ns` nanoseconds after the mock started (called in time order).
    fn motion(&mut self, t_ns: u64) -> Motion;
}

impl<S: ImuSource + ?Sized> ImuSource for Box<S> {
    fn motion(&mut self, t_ns: u64) -> Motion {
        (**self).motion(t_ns)
    }
}

/// A device at rest.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Still(pub Motion);

impl ImuSource for Still {
    fn motion(&mut self, _t_ns: u64) -> Motion {
        self.0
    }
}
