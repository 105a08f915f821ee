//! PTP v2 (IEEE 1588-2008) for STARC: messages, a grandmaster and a measure-only slave with
//! kernel timestamps.
//!
//! - [`message`]: the wire codec (sans-IO, untrusted bytes in, typed errors out).
//! - [`port`]: the grandmaster and slave state machines (sans-IO: bytes and time in, actions out).
//! - [`servo`]: the PI servo and the measure-only frequency estimate.
//! - [`transport`]: UDP/IPv4 multicast sockets with SO_TIMESTAMPING (the only code that touches
//!   sockets) and the tokio loop that drives a port.
//!
//! Written here rather than on the `statime` crate: statime keeps its message types private
//! (so its codec cannot be fuzzed or reused), and its port always steers a `Clock`, while
//! STARC's default slave must measure without ever adjusting one.

pub mod error;
pub mod message;

pub use error::{PtpError, Result};
pub mod config;
pub mod port;
pub mod servo;
pub mod status;
pub mod transport;

pub use config::{LocalTimescale, MasterConfig, PtpConfig, ServoConfig, SlaveConfig};
