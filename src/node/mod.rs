//! The live nodes: `starc robot` on the robot, `starc fpv` on the responder's rig, talking over
//! the link (starc-link, zenoh). Each wires a live driver to its side of the mission
//! (`starc_pipeline::mission`) and its outputs; `starc sim` runs both against mock devices.

pub mod config;
pub mod fpv;
mod recording;
pub mod robot;

use nalgebra::Vector3;
use starc_livox::live::ImuReading;
use starc_pipeline::lio::ImuSample;
use tokio::sync::watch;

/// An Avia IMU reading as the LIO takes it (on the LiDAR's clock, acceleration in m/s²).
pub fn imu_sample(r: &ImuReading) -> ImuSample {
    ImuSample {
        t_ns: r.device_time.ns,
        gyro_rad_s: Vector3::from(r.sample.gyro_rad_s.map(f64::from)),
        acc_m_s2: Vector3::from(r.sample.acc_m_s2().map(f64::from)),
    }
}

/// Stops a node: send `true` (or drop the sender).
pub type Stop = watch::Receiver<bool>;

pub async fn wait_stop(stop: &mut Stop) {
    let _ = stop.wait_for(|s| *s).await;
}

/// A stop signal that fires on SIGINT or SIGTERM, so recordings are finalized.
pub fn stop_on_signals() -> anyhow::Result<(watch::Sender<bool>, Stop)> {
    let (tx, rx) = watch::channel(false);
    let mut term = tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate())?;
    let signal_tx = tx.clone();
    tokio::spawn(async move {
        tokio::select! {
            _ = tokio::signal::ctrl_c() => {}
            _ = term.recv() => {}
        }
        tracing::info!("stopping");
        let _ = signal_tx.send(true);
    });
    Ok((tx, rx))
}
