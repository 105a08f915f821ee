//! Serial IMUs for STARC: MicroStrain MIP and WitMotion.
//!
//! - [`mip`], [`witmotion`]: sans-IO codecs (frames, commands, config writes) and stream
//!   decoders that take bytes in any chunking with their host receive time and hand out
//!   [`ImuEvent`]s, resynchronising after garbage without losing the next good frame.
//! - [`sample`]: [`ImuSample`] in SI units (rad/s, m/s^2) with the raw values beside them.
//! - [`timing`]: host receive time, a serial/USB latency model, and [`timing::HostClockMap`],
//!   the hook that maps host time onto the LiDAR's PTP clock.
//! - [`stats`]: decoder counters and dropped samples found from gaps.
//! - [`serial`]: the tokio-serial transport (open at a baud, stream events, MIP commands with
//!   ACK/timeout/retries, WitMotion writes verified by the observed rate).
//! - [`config`]: the TOML settings (`config/imu.toml`).
//!
//! Parsers take untrusted bytes and return [`ImuError`]; they never panic and never allocate
//! from a length on the wire beyond the protocol's maximum.

pub mod config;
pub mod decoder;
pub mod error;
pub mod mip;
pub mod sample;
pub mod serial;
pub mod stats;
pub(crate) mod stream;
pub mod timing;
pub mod witmotion;

#[cfg(test)]
mod tests;

pub use decoder::ImuDecoder;
pub use error::{ImuError, Result};
pub use sample::{ImuEvent, ImuSample, Incomplete, Protocol, RawSample, STANDARD_GRAVITY_M_S2};
pub use stats::{DecoderStats, GapDetector};
