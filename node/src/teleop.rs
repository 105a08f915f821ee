//! `/cmd_vel` drives the base (`[ros2] cmd_vel`, robot only): each `geometry_msgs/Twist` the ROS
//! 2 bridge takes becomes one velocity command to the base driver, which applies its limits
//! (speed, acceleration, wheel speed) and its watchdog. When `/cmd_vel` falls silent for
//! `[ros2] cmd_vel_timeout_ms` the base is commanded to stop (it ramps down at its acceleration
//! limits), and nothing more is sent, so the base's own watchdog brakes too. The node's end
//! halts the base.

use crate::error::{NodeError, Result};
use starc_base::config::BaseConfig;
use starc_base::runner::{open_bus, spawn, BaseHandle};
use starc_base::{Base, Twist as BaseTwist};
use starc_pipeline::record::msgs::Twist;
use std::path::Path;
use std::time::Duration;
use tokio::sync::mpsc;
use tokio::time::Instant;

/// A ROS twist as the base's: x forward, y left, yaw rate (REP 103, the base's own axes).
pub fn base_twist(t: &Twist) -> BaseTwist {
    BaseTwist { vx_m_s: t.linear.x, vy_m_s: t.linear.y, wz_rad_s: t.angular.z }
}

/// Opens the base `base_config` names and drives it from `twists` until they end; `silent`:
/// after this long without a twist, the base is told to stop.
pub async fn drive(base_config: &Path, twists: mpsc::Receiver<Twist>, silent: Duration) -> Result<()> {
    let config = BaseConfig::load(base_config)
        .map_err(|e| NodeError::Config(format!("[ros2] base_config {}: {e}", base_config.display())))?;
    let (bus, options) = open_bus(&config.can).await.map_err(|e| NodeError::Config(format!("the base's bus: {e}")))?;
    let base = Base::new(config).map_err(|e| NodeError::Config(format!("the base: {e}")))?;
    let (handle, _events) = spawn(bus, base, options);
    tracing::info!(config = %base_config.display(), "the base takes /cmd_vel");
    forward(&handle, twists, silent).await;
    if let Err(e) = handle.stop().await {
        tracing::warn!("the base: {e}");
    }
    Ok(())
}

/// Each twist to the base; after `silent` without one, a single stop.
pub async fn forward(base: &BaseHandle, mut twists: mpsc::Receiver<Twist>, silent: Duration) {
    let mut last: Option<Instant> = None;
    loop {
        let wake = last.map_or_else(|| Instant::now() + Duration::from_secs(3600), |t| t + silent);
        tokio::select! {
            got = twists.recv() => {
                let Some(t) = got else { break };
                if base.command(base_twist(&t)).await.is_err() {
                    break;
                }
                last = Some(Instant::now());
            }
            _ = tokio::time::sleep_until(wake), if last.is_some() => {
                tracing::info!("/cmd_vel silent for {} ms: stopping the base", silent.as_millis());
                let _ = base.command(BaseTwist::ZERO).await;
                last = None;
            }
        }
    }
}
