//! The omni-wheel base of STARC.
//!
//! - [`kinematics`]: 3-/4-wheel omni and mecanum, inverse and least-squares forward.
//! - [`c620`]: DJI M3508 motors on C620 ESCs (current commands, feedback, host velocity loops).
//! - [`cia402`]: CANopen CiA 402 drives in profile velocity mode (NMT, SDO, PDO, heartbeat, EMCY).
//! - [`safety`], [`limits`], [`odometry`]: watchdog, latched faults, emergency stop; velocity and
//!   acceleration limits; wheel odometry.
//! - [`controller`]: the sans-IO [`Base`] that ties them together; [`runner`]: its tokio loop on
//!   any [`starc_can::CanBus`].
//! - [`config`]: the TOML configuration.
//!
//! Parsers take untrusted frames and return [`BaseError`]; they never panic.

pub mod c620;
pub mod cia402;
pub mod config;
pub mod controller;
pub mod error;
pub mod kinematics;
pub mod limits;
pub mod motor;
pub mod motors;
pub mod odometry;
pub mod runner;
pub mod safety;

pub use config::BaseConfig;
pub use controller::{Base, BaseEvent, BaseStatus};
pub use error::{BaseError, Result};
pub use kinematics::Twist;
pub use safety::{DriveMode, Fault};
