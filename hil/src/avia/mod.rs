//! A mock Livox Avia: a real device in all but hardware.
//!
//! - [`device`]: the sans-IO core ([`AviaDevice`]): datagrams and time in, [`Action`]s out.
//! - [`stream`]: point and IMU packets at the real rates, stamped from the device clock.
//! - [`source`]: what the device sees ([`PointSource`]): [`SyntheticScene`] or [`CaptureSource`].
//! - [`faults`]: seeded drop/duplicate/reorder/corrupt of data packets, heartbeat silence,
//!   time-source switches.
//! - [`run`]: the tokio transport ([`MockAvia`]) and its TOML/serde configuration.

pub mod capture;
pub mod device;
pub mod faults;
pub mod run;
pub mod source;
pub mod stream;
pub mod synthetic;

#[cfg(test)]
mod tests;

pub use capture::CaptureSource;
pub use device::{Action, AviaDevice, DeviceConfig, DeviceEvent, DeviceStats, WorkState};
pub use faults::{FaultConfig, FaultStats, TimeSourceSwitch};
pub use run::{MockAvia, MockAviaConfig, MockStats, SourceConfig};
pub use source::{FiringRequest, PointSource};
pub use stream::{Packet, PacketKind, ReturnSetting, Streamer, TimeSource, Timebase};
pub use synthetic::SyntheticScene;
