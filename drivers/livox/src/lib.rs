//! Livox SDK1 (Avia, Horizon, Tele-15, Mid-40/70) for STARC.
//!
//! - [`control`]: the command protocol (broadcast, handshake, heartbeat, ...), sans-IO.
//! - [`data`]: point and IMU packets with per-point firing times, sans-IO.
//! - [`scan`]: assembling packets into fixed-period scans, with FAST-LIO-style filters.
//! - [`capture`]: pcap, pcapng and .lvx files.
//! - [`live`]: the tokio driver (discovery, handshake, heartbeat, streams).
//!
//! Parsers take untrusted bytes and return [`LivoxError`]; they never panic.

pub mod capture;
pub mod control;
pub mod crc;
pub mod data;
pub mod error;
pub mod live;
pub mod ports;
pub mod scan;

pub use error::{LivoxError, Result};
