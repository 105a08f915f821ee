//! The STARC pipeline. It works on decoded, timed data and knows no sockets, serial ports or
//! mock devices.
//!
//! - [`cloud`]: point clouds and their files (PCD, PLY, KITTI .bin).
//! - [`align`]: registration of one cloud against another (NDT, then point-to-plane ICP).
//! - [`lio`]: LiDAR-inertial odometry (IMU propagation, de-skew, iterated Kalman update, iVox map).
//! - [`pose`]: the responder's world pose (composition, interpolation, drift correction).
//! - [`record`]: MCAP recordings of ROS 2 messages (CDR), written crash-safe and read back.
//! - [`detect`]: people in a window of points (oriented boxes, scores, their points).
//! - [`ar`]: the responder's first-person AR frame (people projected in red, see-through).
//! - [`link`]: the robot-to-rig link's messages, clock offset and health (sans-IO).
//! - [`mission`]: the robot's and the rig's sides of the mission, shared by every runner.

pub mod align;
pub mod ar;
pub mod cloud;
pub mod detect;
pub mod error;
pub mod explore;
pub mod link;
pub mod lio;
pub mod mission;
pub mod pose;
pub mod record;
pub mod rng;
pub mod timing;
pub mod voxel_hash;

pub use error::PipelineError;
