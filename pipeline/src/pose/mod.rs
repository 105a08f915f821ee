//! The responder's pose in the world (the robot's map frame), as the paper composes it:
//! `wT_fpv(t) = wT_fpv(t0) · ΔT_fpv(t0 → t)`, with `ΔT` from the rig's own LIO.
//!
//! - [`PoseBuffer`]: timed poses with SE(3) interpolation (slerp + lerp) at a common render
//!   time, and a typed error outside the buffer.
//! - [`WorldPose`]: boot in any order (the world frame is always the robot's; the rig runs in
//!   its own odometry frame until its first accepted alignment), composition, and drift
//!   correction from periodic re-registration, applied in bounded steps per frame so the
//!   overlay never jumps.

mod buffer;
mod world;

pub use buffer::PoseBuffer;
pub use world::{Constraint, CorrectionStep, RegistrationOutcome, WorldPose, WorldPoseConfig, WorldPoseState};

#[cfg(test)]
mod tests;
