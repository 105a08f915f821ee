//! The STARC pipeline. It works on decoded, timed data and knows no sockets, serial ports or
//! mock devices.
//!
//! - [`cloud`]: point clouds and their files (PCD, PLY, KITTI .bin).
//! - [`align`]: registration of one cloud against another (NDT, then point-to-plane ICP).
//! - [`lio`]: LiDAR-inertial odometry (IMU propagation, de-skew, iterated Kalman update, iVox map).

pub mod align;
pub mod cloud;
pub mod error;
pub mod lio;

pub use error::PipelineError;
