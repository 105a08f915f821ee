//! Hardware in the loop for STARC: mock devices that speak the real wire protocols.
//!
//! - [`avia`]: a Livox Avia (SDK1) that broadcasts, handshakes, answers every control command and
//!   streams point and IMU packets at the real rates, from a synthetic scene or a capture file,
//!   with injectable faults. A sans-IO core ([`avia::AviaDevice`]) and a tokio transport
//!   ([`avia::MockAvia`]).
//! - [`motors`]: DJI C620 ESCs or CiA 402 drives behind a mock slcan adapter on a pty.
//! - [`imu`]: serial IMUs (MicroStrain MIP, WitMotion) on a pty, answering commands and
//!   config writes, with injectable faults.
//! - [`gen`]: generated buildings (flats, offices, warehouses, halls, labs) for held-out
//!   evaluation, with routes planned on their floor plans.
//! - [`rng`]: the small deterministic PRNG behind every seeded choice.
//! - [`tum`]: TUM trajectory files (written, read, interpolated).

pub mod avia;
pub mod error;
pub mod gen;
pub mod imu;
pub mod motors;
pub mod rng;
pub mod sim;
pub mod tum;

pub use error::{HilError, Result};
