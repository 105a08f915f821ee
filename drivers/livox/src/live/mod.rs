//! The live driver: a sans-IO host session per device ([`session`]) and a tokio transport
//! ([`driver`]) that finds devices by their broadcast or by address, handshakes, keeps them alive
//! with heartbeats, reconnects after 3 s of silence, and streams typed packets, scans and IMU
//! samples with device and host time. The device table is bounded ([`table`]): only configured
//! devices by default, at most `max_devices`, silent ones forgotten, scans capped.

pub mod driver;
pub mod session;
pub mod socket;
pub mod table;

pub use driver::{DriverConfig, ImuReading, LivoxDriver, LivoxEvent, PointPacket};
pub use session::{
    DeviceSession, HostEndpoint, ReturnModeSetting, SessionConfig, SessionEvent, SessionOutput, SessionState,
};
pub use table::DriverStats;
