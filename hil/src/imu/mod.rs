//! Mock serial IMUs: MicroStrain MIP and WitMotion on a pty, in all but hardware.
//!
//! - [`source`]: what the device feels ([`ImuSource`]); [`Still`] by default.
//! - [`sensor`]: bias and white noise ([`SensorModel`]).
//! - [`faults`]: seeded garbage bytes, dropped samples, corrupted checksums, silence.
//! - [`device`]: the sans-IO core ([`ImuDevice`]): time and host bytes in, frames and replies out.
//! - [`pty`]: the pseudo-terminal pair a host opens as its serial port.
//! - [`run`]: the tokio transport ([`MockImu`]) and its TOML configuration.

pub mod device;
pub mod faults;
pub mod pty;
pub mod run;
pub mod sensor;
pub mod source;

#[cfg(test)]
mod tests;

pub use device::{DeviceConfig, DeviceStats, ImuDevice};
pub use faults::{ImuFaultConfig, ImuFaultStats};
pub use run::{MockImu, MockImuConfig, MockImuStats, Output};
pub use sensor::SensorModel;
pub use source::{ImuSource, Motion, Still};
