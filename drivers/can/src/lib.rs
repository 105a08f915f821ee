//! CAN frames and transports for STARC.
//!
//! - [`frame`]: classic CAN frames, valid by construction.
//! - [`bus`]: the [`CanBus`] trait every transport implements (send, time-stamped receive,
//!   bus faults).
//! - [`socketcan`]: SocketCAN, the production transport (gs_usb/candleLight, slcand, on-board).
//! - [`slcan`]: the Lawicel ASCII protocol (sans-IO codec for both sides) and its transport on a
//!   serial port or any byte stream.
//!
//! Parsers take untrusted bytes and return [`CanError`]; they never panic.

pub mod any;
pub mod bus;
pub mod candump;
pub mod error;
pub mod frame;
pub mod slcan;
pub mod socketcan;

pub use any::AnyBus;
pub use bus::{BusEvent, BusFault, BusStats, CanBus, RxFrame};
pub use error::{CanError, Result};
pub use frame::{CanFrame, CanId};
