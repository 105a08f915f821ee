//! LiDAR-inertial odometry in the style of FAST-LIO2: IMU propagation with covariance, per-point
//! de-skew, an iterated error-state Kalman update with point-to-plane residuals against a local
//! voxel-hash map (iVox style).
//!
//! Feed IMU samples and scans in time order with [`Lio::push_imu`] and [`Lio::push_scan`]; each
//! scan comes out as a [`ScanOutput`] once the IMU has passed its end. The first `init_window_ns`
//! of IMU must be static ([`InitStatus::MotionDetected`] says when it was not; the window
//! restarts). The world frame is gravity-aligned (z up) with the IMU's yaw at initialization.

mod config;
mod deskew;
mod health;
mod init;
mod ivox;
mod kalman;
mod level;
mod odometry;
mod plane;
mod propagate;
mod scan_points;
mod so3;
mod stand;
mod start;
mod state;
mod still;
mod types;
mod update;
mod wheel;

pub use config::{ExtrinsicsSection, ImuSection, ImuSource, LioFile, MapSection, ScanSection, UpdateSection};
pub use health::{uncertain_axes, Health, HealthConfig, HealthMonitor, Refusal, ScanFit, Verdict};
pub use init::{InitResult, InitStatus, StaticInit};
pub use ivox::VoxelMap;
pub use odometry::{Lio, LioConfig, LioStatus, ScanOutput};
pub use plane::Plane;
pub use propagate::ImuNoise;
pub use scan_points::ScanReduction;
pub use state::State;
pub use types::{Clock, ImuSample, LioScan, TimedPoint};
pub use update::{weak_axes_names, UpdateConfig, UpdateReport};
pub use wheel::{mean_twist, wheel_update, WheelFusion, WheelSample, WheelUse};
