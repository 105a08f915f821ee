//! The STARC pipeline. It works on decoded, timed data and knows no sockets, serial ports or
//! mock devices.
//!
//! - [`cloud`]: point clouds and their files (PCD, PLY, KITTI .bin).
//! - [`align`]: registration of one cloud against another (NDT, then point-to-plane ICP).

pub mod align;
pub mod cloud;
pub mod error;

pub use error::PipelineError;
