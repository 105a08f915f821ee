//! Mock motor controllers on a mock slcan adapter: DJI C620 ESCs or CiA 402 drives, speaking
//! the real protocols over a pty, with first-order motors and injectable faults.
//!
//! - [`adapter`]: the Lawicel adapter (sans-IO).
//! - [`c620`], [`cia402`]: the controllers (sans-IO); [`dynamics`]: the motor model.
//! - [`device`]: adapter + bus + controllers + [`faults`] (sans-IO).
//! - [`pty`], [`run`]: the pty and the tokio task ([`MockMotors`]).

pub mod adapter;
pub mod c620;
pub mod cia402;
pub mod device;
pub mod dynamics;
pub mod faults;
pub mod pty;
pub mod run;

pub use device::{MockProtocol, MotorsDevice, MotorsStats};
pub use faults::{MotorFaultConfig, MotorFaultStats};
pub use run::{MockMotors, MockMotorsConfig};
