//! The one place where decoded device data becomes the pipeline's inputs.
//!
//! The drivers (`starc-livox`, `starc-imu`) know nothing of the pipeline, and the pipeline knows
//! no devices: this crate sits between them. The CLI, the live nodes, the benches and the tests
//! all convert through it, so a scan or an IMU reading means the same thing everywhere.
//!
//! - [`livox`]: an assembled Avia scan to a [`LioScan`](starc_pipeline::lio::LioScan), an Avia
//!   IMU packet or live reading to an [`ImuSample`](starc_pipeline::lio::ImuSample);
//! - [`external_imu`]: an external IMU's file (MicroStrain MIP bytes or CSV);
//! - [`recorded`]: scans and IMU samples read back from a node's MCAP recording;
//! - [`wheels`]: the base's wheel feedback (a `candump -l` log) as the body's twist;
//! - [`inputs`]: both devices' inputs of a mission in time order, from a capture or recordings.

pub mod error;
pub mod external_imu;
pub mod inputs;
pub mod livox;
pub mod recorded;
pub mod wheels;

pub use error::BridgeError;
pub use inputs::{decode_avia, from_capture, from_recordings, is_mcap, AviaInputs, Inputs};
pub use starc_pipeline::mission::{MissionInput, Side};
