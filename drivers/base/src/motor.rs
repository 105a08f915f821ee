//! What every motor protocol reports about its wheels.

use serde::Serialize;
use starc_time::Stamp;

/// Where a wheel's motor stands.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum MotorPhase {
    /// Being brought up (CANopen: NMT, SDO configuration, enable sequence).
    Starting,
    /// Ready and driven.
    Running,
    /// Stopped by a fault on this motor.
    Faulted,
    /// Never heard from, or silent.
    Silent,
}

/// One wheel's motor, for status output.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct WheelState {
    /// Index in the kinematics model.
    pub wheel: usize,
    /// ESC id (C620, 1-8) or node id (CANopen).
    pub motor: u8,
    pub phase: MotorPhase,
    /// The wheel rate last sent (rad/s, wheel frame, after inversion).
    pub target_rad_s: f64,
    /// The wheel rate last measured.
    pub measured_rad_s: Option<f64>,
    /// Motor current (C620) when known.
    pub current_a: Option<f64>,
    pub temperature_c: Option<f64>,
    /// CiA 402 statusword when known.
    pub statusword: Option<u16>,
    /// When the last feedback arrived.
    pub last_feedback: Option<Stamp>,
}

impl WheelState {
    pub fn new(wheel: usize, motor: u8) -> Self {
        Self {
            wheel,
            motor,
            phase: MotorPhase::Silent,
            target_rad_s: 0.0,
            measured_rad_s: None,
            current_a: None,
            temperature_c: None,
            statusword: None,
            last_feedback: None,
        }
    }
}

/// Milliseconds from `earlier` to `now` on the same clock (0 when the clocks differ or time
/// went back).
pub fn elapsed_ms(now: Stamp, earlier: Stamp) -> u64 {
    now.since(earlier).map(|ns| ns.max(0) as u64 / 1_000_000).unwrap_or(0)
}
