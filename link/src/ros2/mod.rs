//! The ROS 2 bridge: STARC's topics on rmw_zenoh, so `ros2 topic echo`, RViz and Foxglove on a
//! ROS 2 system see them live, with no ROS installation here (docs/ros2.md).
//!
//! Made of zenoh's own primitives (the link's zenoh, no second stack): [`names`] are rmw_zenoh's
//! key expressions and liveliness tokens, [`type_hash`] computes RIHS01 hashes from the message
//! definitions we ship, [`attachment`] is rmw_zenoh's per-sample attachment (the pipeline's codec), and [`bridge`]
//! declares and puts. The payloads are the recorder's own CDR messages
//! (`starc_pipeline::record::MessageBuilder`).

pub mod bridge;
pub mod config;
pub mod names;
pub mod type_hash;

pub use bridge::{Ros2Bridge, Ros2Counts, TopicId};
pub use config::Ros2Config;
pub use names::{Distro, Qos};
/// rmw_zenoh's per-sample attachment (sans-IO, in the pipeline beside the messages).
pub use starc_pipeline::record::attachment;
