//! The tokio-serial transport: one task per port reads bytes, stamps each read with the host
//! clock, feeds the [`crate::ImuDecoder`] and sends events to a channel; commands go through an
//! [`ImuHandle`].
//!
//! ```no_run
//! # async fn demo() -> starc_imu::Result<()> {
//! use starc_imu::config::ImuConfig;
//! use starc_imu::serial::ImuPort;
//! use starc_imu::{ImuEvent, Protocol};
//! let (imu, mut events) = ImuPort::open(&ImuConfig::on("/dev/ttyACM0", Protocol::Mip, 115_200))?;
//! imu.mip_ping().await?;
//! let rate_hz = imu.set_mip_rate(200.0).await?;
//! while let Some(ImuEvent::Sample(s)) = events.recv().await {
//!     println!("{} {:?} {:?}", s.stamp, s.gyro_rad_s, s.accel_m_s2);
//! }
//! # Ok(()) }
//! ```

mod handle;
mod task;

pub use handle::{ImuHandle, ImuPort, PortStats};
