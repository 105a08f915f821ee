//! Settings of one serial IMU, from TOML (`config/imu.toml`).

use crate::error::{ImuError, Result};
use crate::sample::Protocol;
use crate::timing::{LatencyModel, LinearClockMap};
use serde::{Deserialize, Serialize};

/// One serial IMU. Unknown keys are refused; missing ones take the defaults below.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ImuConfig {
    /// Serial device, e.g. `/dev/ttyACM0` or a udev symlink such as `/dev/starc-imu`.
    pub port: String,
    pub protocol: Protocol,
    /// Line rate the device is at now.
    pub baud: u32,
    /// Move the device to this baud rate after opening (MIP: command + ACK; WitMotion: write,
    /// then good frames at the new rate).
    pub switch_baud: Option<u32>,
    /// Output rate to set after opening (MIP: accel + gyro at base rate / decimation;
    /// WitMotion: register 0x03, verified by the observed rate). Absent: leave the device's.
    pub rate_hz: Option<f64>,
    /// Latency of the USB-serial path, added to the serial transfer time.
    pub usb_latency_ns: u64,
    /// Wait for a MIP ACK this long before sending again.
    pub command_timeout_ms: u64,
    /// Sends of one command before giving up.
    pub command_tries: u32,
    /// How long to measure the output rate after a WitMotion rate change.
    pub verify_window_ms: u64,
    /// Events buffered for a slow consumer (more are dropped and counted).
    pub channel_capacity: usize,
    /// Map host time onto the LiDAR's PTP clock (absent: stamps stay on the host clock).
    pub clock_map: Option<LinearClockMap>,
}

impl Default for ImuConfig {
    fn default() -> Self {
        Self {
            port: "/dev/ttyACM0".into(),
            protocol: Protocol::Mip,
            baud: 115_200,
            switch_baud: None,
            rate_hz: None,
            usb_latency_ns: 1_000_000,
            command_timeout_ms: 300,
            command_tries: 3,
            verify_window_ms: 1000,
            channel_capacity: 4096,
            clock_map: None,
        }
    }
}

impl ImuConfig {
    pub fn on(port: impl Into<String>, protocol: Protocol, baud: u32) -> Self {
        Self { port: port.into(), protocol, baud, ..Self::default() }
    }

    pub fn from_toml(text: &str) -> Result<Self> {
        let c: Self = toml_from_str(text)?;
        c.validate()?;
        Ok(c)
    }

    pub fn validate(&self) -> Result<()> {
        if self.port.is_empty() {
            return Err(ImuError::config("port", "empty"));
        }
        if self.baud == 0 {
            return Err(ImuError::config("baud", "0"));
        }
        if let Some(r) = self.rate_hz {
            if !r.is_finite() || r <= 0.0 {
                return Err(ImuError::config("rate_hz", format!("{r} is not a rate > 0")));
            }
        }
        if self.command_tries == 0 || self.command_timeout_ms == 0 {
            return Err(ImuError::config("command_tries", "tries and timeout must be > 0"));
        }
        if self.channel_capacity == 0 {
            return Err(ImuError::config("channel_capacity", "0"));
        }
        Ok(())
    }

    pub fn latency(&self) -> LatencyModel {
        LatencyModel::new(self.baud, self.usb_latency_ns)
    }
}

fn toml_from_str(text: &str) -> Result<ImuConfig> {
    toml::from_str(text).map_err(|e| ImuError::config("toml", e.to_string()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_shipped_example_loads() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/imu.toml");
        let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let c = ImuConfig::from_toml(&text).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(
            (c.port.as_str(), c.protocol, c.baud, c.rate_hz),
            ("/dev/starc-imu", Protocol::Mip, 115_200, Some(200.0))
        );
        assert_eq!(c.clock_map, None);
        let uncommented = text
            .replace("# [clock_map]", "[clock_map]")
            .replace("# target", "target")
            .replace("# offset_ns", "offset_ns");
        let c = ImuConfig::from_toml(&uncommented).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(c.clock_map.map(|m| m.offset_ns), Some(-37_000_000_000));
    }

    #[test]
    fn typos_and_bad_values_are_refused() {
        assert!(ImuConfig::from_toml("prot = \"mip\"").is_err());
        assert!(ImuConfig::from_toml("protocol = \"nmea\"").is_err());
        assert!(ImuConfig::from_toml("rate_hz = -1.0").is_err());
        assert!(ImuConfig::from_toml("baud = 0").is_err());
        assert_eq!(
            ImuConfig::from_toml("protocol = \"witmotion\"").map(|c| c.protocol).ok(),
            Some(Protocol::WitMotion)
        );
    }
}
