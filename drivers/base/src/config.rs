//! The base's TOML configuration (see config/base.toml for a commented example).

use crate::c620::C620Config;
use crate::cia402::Cia402Config;
use crate::error::{BaseError, Result};
use crate::kinematics::KinematicsConfig;
use crate::limits::LimitsConfig;
use serde::{Deserialize, Serialize};
use starc_can::slcan::SlcanOptions;
use std::path::Path;

/// Everything about one base.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BaseConfig {
    /// Control period: one command frame per motor group each period.
    #[serde(default = "default_control_period_ms")]
    pub control_period_ms: u64,
    /// Without a velocity command for this long the base brakes to zero.
    #[serde(default = "default_watchdog_ms")]
    pub watchdog_ms: u64,
    /// A CAN adapter error (slcan `F` flags, error frames, refused transmits) stops the base.
    #[serde(default = "default_true")]
    pub stop_on_bus_fault: bool,
    /// A frame the transport has not taken within this long latches a fault (the base halts),
    /// so that a stalled adapter cannot hold the control loop, and its watchdog, hostage.
    #[serde(default = "default_send_timeout_ms")]
    pub send_timeout_ms: u64,
    pub can: CanConfig,
    pub kinematics: KinematicsConfig,
    pub limits: LimitsConfig,
    pub motors: MotorsConfig,
}

fn default_control_period_ms() -> u64 {
    10
}
fn default_watchdog_ms() -> u64 {
    200
}
fn default_send_timeout_ms() -> u64 {
    50
}
fn default_true() -> bool {
    true
}

/// Which CAN transport.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, tag = "transport", rename_all = "snake_case")]
pub enum CanConfig {
    /// A SocketCAN interface (`can0`: gs_usb/candleLight, or slcand-attached).
    Socketcan { interface: String },
    /// An slcan adapter on a serial port, driven directly.
    Slcan {
        port: String,
        #[serde(default)]
        slcan: SlcanOptions,
        /// How often to poll the adapter's error flags (`F`); 0 = never.
        #[serde(default = "default_status_poll_ms")]
        status_poll_ms: u64,
    },
}

fn default_status_poll_ms() -> u64 {
    500
}

/// One wheel's motor.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WheelConfig {
    /// C620 ESC id (1-8) or CANopen node id (1-127).
    pub id: u8,
    /// The motor turns the other way round for a positive wheel rate.
    #[serde(default)]
    pub invert: bool,
}

/// The motor protocol.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Protocol {
    C620,
    Cia402,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MotorsConfig {
    pub protocol: Protocol,
    /// Wheels in kinematics order (mecanum: FL, FR, RL, RR).
    pub wheels: Vec<WheelConfig>,
    /// Feedback (C620 frames, CiA 402 TPDO1) older than this faults the base.
    #[serde(default = "default_feedback_timeout_ms")]
    pub feedback_timeout_ms: u64,
    #[serde(default)]
    pub c620: C620Config,
    #[serde(default)]
    pub cia402: Cia402Config,
}

fn default_feedback_timeout_ms() -> u64 {
    100
}

impl BaseConfig {
    pub fn from_toml(text: &str) -> Result<Self> {
        let c: Self = toml::from_str(text).map_err(|e| BaseError::config("toml", e.to_string()))?;
        c.validate()?;
        Ok(c)
    }

    pub fn load(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| BaseError::Io { context: format!("reading {}", path.display()), source: e })?;
        Self::from_toml(&text)
    }

    pub fn validate(&self) -> Result<()> {
        if self.control_period_ms == 0 || self.control_period_ms > 100 {
            return Err(BaseError::config("control_period_ms", "must be 1-100"));
        }
        if self.watchdog_ms < 2 * self.control_period_ms {
            return Err(BaseError::config("watchdog_ms", "must be at least two control periods"));
        }
        if self.send_timeout_ms == 0 || self.send_timeout_ms > self.watchdog_ms {
            return Err(BaseError::config("send_timeout_ms", "must be 1 ms up to watchdog_ms"));
        }
        if self.motors.protocol == Protocol::Cia402
            && u64::from(self.motors.cia402.host_heartbeat_ms) < self.control_period_ms
        {
            // The heartbeat goes out from the control tick: it cannot be more frequent.
            return Err(BaseError::config("motors.cia402.host_heartbeat_ms", "must be at least one control period"));
        }
        let deadline_ms = u64::from(self.motors.cia402.rpdo_deadline_ms);
        if self.motors.protocol == Protocol::Cia402 && deadline_ms > 0 && deadline_ms < 2 * self.control_period_ms {
            // One late command must not stop the base.
            return Err(BaseError::config(
                "motors.cia402.rpdo_deadline_ms",
                "must be 0 or at least two control periods",
            ));
        }
        if self.motors.feedback_timeout_ms < self.control_period_ms {
            return Err(BaseError::config("motors.feedback_timeout_ms", "must be at least one control period"));
        }
        self.limits.validate()?;
        let n = self.kinematics.wheel_count();
        if self.motors.wheels.len() != n {
            return Err(BaseError::config(
                "motors.wheels",
                format!("{} wheels listed, the kinematics model has {n}", self.motors.wheels.len()),
            ));
        }
        match self.motors.protocol {
            Protocol::C620 => self.motors.c620.validate()?,
            Protocol::Cia402 => self.motors.cia402.validate()?,
        }
        if let CanConfig::Slcan { slcan, .. } = &self.can {
            starc_can::slcan::bitrate::code_for(slcan.bitrate)?;
        }
        Ok(())
    }

    /// (id, invert) per wheel.
    pub fn motor_ids(&self) -> Vec<(u8, bool)> {
        self.motors.wheels.iter().map(|w| (w.id, w.invert)).collect()
    }
}
