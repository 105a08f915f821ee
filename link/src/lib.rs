//! The robot-to-rig link over zenoh: the robot publishes map tiles, detections (with each
//! person's points), its pose and heartbeats; the rig answers heartbeats and clock probes and
//! fetches the whole map when it joins or comes back. Message format, clock offset and health
//! are sans-IO in `starc_pipeline::link`; this crate is the transport (docs/link.md).

pub mod acl;
pub mod certs;
pub mod config;
pub mod error;
pub mod keys;
pub mod node;
mod queue;
pub mod ros2;
pub mod stats;

pub use config::{LinkConfig, Mode, TlsConfig};
pub use error::LinkError;
pub use node::{host_now_ns, LinkNode, LinkReport, Received, Refused};
pub use starc_pipeline::link::{LinkMessage, LinkPerson, LinkState, OffsetEstimate, Role};
pub use stats::{LatencySummary, LatencyWindow};
