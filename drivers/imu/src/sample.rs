//! What the decoders hand out: [`ImuSample`]s in SI units with the raw values beside them, MIP
//! command replies, and incomplete data.

use crate::mip::{MipData, MipReply};
use crate::witmotion::WitGroup;
use serde::{Deserialize, Serialize};
use starc_time::Stamp;
use std::fmt;
use std::str::FromStr;

/// Standard gravity (m/s^2): both MIP (g) and WitMotion (16 g full scale) scale by it.
pub const STANDARD_GRAVITY_M_S2: f64 = 9.80665;

/// Which wire protocol a serial IMU speaks.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Protocol {
    /// MicroStrain MIP (3DM-GX5, CV7, ...): `0x75 0x65` packets, Fletcher-16.
    Mip,
    /// WitMotion (WT901, HWT905, ...): 11-byte `0x55` frames, 8-bit sum.
    #[serde(rename = "witmotion")]
    WitMotion,
}

impl Protocol {
    pub fn name(self) -> &'static str {
        match self {
            Protocol::Mip => "mip",
            Protocol::WitMotion => "witmotion",
        }
    }
}

impl fmt::Display for Protocol {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Protocol {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.to_ascii_lowercase().as_str() {
            "mip" | "microstrain" => Ok(Protocol::Mip),
            "witmotion" | "wit" => Ok(Protocol::WitMotion),
            other => Err(format!("unknown IMU protocol {other:?} (mip or witmotion)")),
        }
    }
}

/// The raw values a sample was made from, as the device sent them.
#[derive(Clone, Debug, PartialEq)]
pub enum RawSample {
    Mip(MipData),
    WitMotion(WitGroup),
}

/// One IMU measurement: angular rate and specific force in the sensor frame, in SI units.
#[derive(Clone, Debug, PartialEq)]
pub struct ImuSample {
    /// Estimated time of measurement: the host receive time less the latency model
    /// ([`crate::timing::LatencyModel`]), mapped onto another clock (PTP) when a
    /// [`crate::timing::HostClockMap`] is set and knows the mapping; else on the host clock.
    pub stamp: Stamp,
    /// Estimated arrival of the last byte of the sample's data on the host (host clock).
    pub host_receive: Stamp,
    /// The device's own time of the sample when it sends one (MIP GPS time 0x80/0x12,
    /// WitMotion time frame 0x50), as ns on [`starc_time::Clock::Device`]; used for gaps.
    pub device_ns: Option<u64>,
    pub gyro_rad_s: [f64; 3],
    pub accel_m_s2: [f64; 3],
    /// Orientation quaternion (w, x, y, z), when the device sends one.
    pub orientation_wxyz: Option<[f64; 4]>,
    /// Roll, pitch, yaw in radians, when the device sends them.
    pub euler_rad: Option<[f64; 3]>,
    pub raw: RawSample,
}

/// Data that did not make a sample (no gyro or no accel), e.g. after a lost frame.
#[derive(Clone, Debug, PartialEq)]
pub struct Incomplete {
    pub host_receive: Stamp,
    pub raw: RawSample,
}

/// What a decoder emits.
#[derive(Clone, Debug, PartialEq)]
pub enum ImuEvent {
    Sample(ImuSample),
    /// Data without both gyro and accel.
    Incomplete(Incomplete),
    /// A MIP reply (ACK/NACK and any reply data) to a command.
    MipReply(MipReply),
}
