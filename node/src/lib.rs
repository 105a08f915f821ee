//! The live nodes: [`robot`] on the robot (`starc robot`), [`fpv`] on the responder's rig
//! (`starc fpv`), talking over the link (starc-link, zenoh). Each wires a live driver to its
//! side of the mission (`starc_pipeline::mission`, sans-IO) and to its outputs (the link, the
//! views, the recording): sockets, tasks and channels only. `starc sim` runs both against mock
//! devices.

mod background;
pub mod error;
pub use background::lower_this_thread;
pub use error::{NodeError, Result};
pub mod config;
pub mod explore;
pub mod fpv;
pub mod recording;
pub mod robot;
pub mod ros2;
pub mod teleop;
mod tiles;
pub mod wheels;

use recording::NodeRecorder;
use starc_bridge::livox::{lio_scan, reading_imu};
use starc_livox::live::LivoxEvent;
use starc_pipeline::lio::{ImuSample, LioScan};
use starc_time::Clock;
use std::net::Ipv4Addr;
use tokio::sync::watch;

/// What a node takes from its LiDAR.
pub enum Fed {
    /// A scan, the clock its points are stamped on, and the host time its last packet arrived.
    Scan {
        scan: LioScan,
        clock: Clock,
        last_host_ns: Option<u64>,
    },
    Imu(ImuSample),
}

/// The node's own LiDAR among the driver's events: the configured one, or the first that sends
/// data. Its scans and IMU samples are recorded and converted for the LIO; connects and losses
/// are logged.
pub struct LidarFeed {
    ours: Option<Ipv4Addr>,
    name: &'static str,
}

impl LidarFeed {
    pub fn new(ours: Option<Ipv4Addr>, name: &'static str) -> Self {
        Self { ours, name }
    }

    /// `ev` if it is ours, also handed to the recording and the ROS 2 bridge where there are.
    pub fn take(
        &mut self,
        ev: LivoxEvent,
        recorder: Option<&mut NodeRecorder>,
        ros2: Option<&mut ros2::Ros2Out>,
    ) -> Option<Fed> {
        match ev {
            LivoxEvent::Scan { ip, scan } if *self.ours.get_or_insert(ip) == ip => {
                let fed = Fed::Scan {
                    scan: lio_scan(&scan),
                    clock: scan.start.clock,
                    last_host_ns: scan.last_host_receive.map(|s| s.ns),
                };
                if let Some(b) = ros2 {
                    b.scan(&scan);
                }
                if let Some(r) = recorder {
                    r.scan(scan);
                }
                Some(fed)
            }
            LivoxEvent::Imu(r) if *self.ours.get_or_insert(r.ip) == r.ip => {
                let s = reading_imu(&r);
                if let Some(rec) = recorder {
                    rec.imu(&s);
                }
                if let Some(b) = ros2 {
                    b.imu(&s);
                }
                Some(Fed::Imu(s))
            }
            LivoxEvent::Connected { ip, .. } => {
                tracing::info!(%ip, "{} lidar connected", self.name);
                None
            }
            LivoxEvent::Lost { ip } => {
                tracing::warn!(%ip, "{} lidar lost", self.name);
                None
            }
            _ => None,
        }
    }
}

/// Stops a node: send `true` (or drop the sender).
pub type Stop = watch::Receiver<bool>;

pub async fn wait_stop(stop: &mut Stop) {
    let _ = stop.wait_for(|s| *s).await;
}

/// A stop signal that fires on SIGINT, SIGTERM or SIGHUP, so recordings are finalized: an
/// operator whose SSH session drops sends the node a SIGHUP.
pub fn stop_on_signals() -> Result<(watch::Sender<bool>, Stop)> {
    use tokio::signal::unix::{signal, SignalKind};
    let (tx, rx) = watch::channel(false);
    let mut term =
        signal(SignalKind::terminate()).map_err(|source| NodeError::Io { what: "waiting for SIGTERM", source })?;
    let mut hangup =
        signal(SignalKind::hangup()).map_err(|source| NodeError::Io { what: "waiting for SIGHUP", source })?;
    let signal_tx = tx.clone();
    tokio::spawn(async move {
        tokio::select! {
            _ = tokio::signal::ctrl_c() => {}
            _ = term.recv() => {}
            _ = hangup.recv() => {}
        }
        tracing::info!("stopping");
        let _ = signal_tx.send(true);
    });
    Ok((tx, rx))
}
