//! What a two-device mission takes in: each device's IMU samples and scans, tagged by side.

use crate::lio::{ImuSample, LioScan, WheelSample};

/// Which device an input comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Side {
    Robot,
    Rig,
}

pub enum MissionInput {
    Imu(Side, ImuSample),
    Scan(Side, LioScan),
    /// The base's wheel odometry (the robot's only).
    Wheel(Side, WheelSample),
}

impl MissionInput {
    /// When the input is complete: a scan at its end, an IMU sample at its time.
    pub fn time_ns(&self) -> u64 {
        match self {
            MissionInput::Imu(_, s) => s.t_ns,
            MissionInput::Scan(_, s) => s.end_ns,
            MissionInput::Wheel(_, s) => s.t_ns,
        }
    }
}
