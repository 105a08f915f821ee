//! The simulator: indoor scenes, an Avia-faithful scan pattern, IMUs, motion and ground truth,
//! driving the mock devices over their real wire protocols.
//!
//! - [`scenario`]: the TOML scenario files (four shipped: lab, auditorium, tactical, corridor).
//! - [`world`]: the scene as solids ([`shapes`], [`bvh`]) and people ([`human`]) to cast rays at.
//! - [`motion`]: the omni base, the walking responder and the people, as smooth functions of time.
//! - [`pattern`]: the Avia's rosette, fitted to a real Avia frame.
//! - [`lidar`]: the simulated Avia, a [`crate::avia::PointSource`]; [`imu`]: the IMUs.

pub mod bvh;
pub mod camera;
pub mod clutter;
pub mod devices;
pub mod driven;
pub mod fixtures;
pub mod furniture;
pub mod human;
pub mod imu;
pub mod lan;
pub mod lidar;
pub mod motion;
pub mod obstacles;
pub mod pattern;
pub mod plan_svg;
pub mod route_check;
pub mod run;
pub mod scenario;
pub mod shapes;
pub mod truth;
pub mod wheels;
pub mod world;
