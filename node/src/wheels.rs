//! The base's wheels for the robot node's LIO: the motor controllers' feedback frames, heard on
//! the base's CAN bus beside `starc base` (SocketCAN lets any number of sockets listen), decoded
//! into the base's twist by the base driver's own kinematics, and moved from the host's clock
//! onto the LiDAR's. A simulated run replays its `robot_can.log` in real time instead.

use crate::error::{NodeError, Result};
use serde::Deserialize;
use starc_base::config::BaseConfig;
use starc_bridge::wheels::{BaseTwist, WheelDecoder, WheelFeedback};
use starc_can::candump::parse_line;
use starc_can::{BusEvent, CanBus, CanFrame};
use starc_link::host_now_ns;
use std::collections::VecDeque;
use std::path::{Path, PathBuf};
use std::time::Duration;
use tokio::sync::mpsc;

/// `[wheels]` in robot.toml.
#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WheelsConfig {
    /// The base driver's config (config/base.toml): protocol, wheel ids and kinematics.
    #[serde(default)]
    pub base_config: Option<PathBuf>,
    /// The base's SocketCAN interface (`can0`), listened to, never written.
    #[serde(default)]
    pub can: Option<String>,
    /// Or a `candump -l` log replayed in real time (a simulated run), its first frame at
    /// `replay_start_at_unix_ns` (default: now).
    #[serde(default)]
    pub replay: Option<PathBuf>,
    #[serde(default)]
    pub replay_start_at_unix_ns: Option<u64>,
    /// The base as the simulator builds it, in place of `base_config`.
    #[serde(skip)]
    pub feedback: Option<WheelFeedback>,
}

impl WheelsConfig {
    /// The base's feedback layout; an error names the key.
    pub fn feedback(&self) -> Result<WheelFeedback> {
        if let Some(f) = &self.feedback {
            return Ok(f.clone());
        }
        let path = self.base_config.as_deref().ok_or_else(|| {
            NodeError::Config("[wheels] needs base_config (the base driver's config, e.g. base.toml)".into())
        })?;
        let base = BaseConfig::load(path)
            .map_err(|e| NodeError::Config(format!("[wheels] base_config {}: {e}", path.display())))?;
        Ok(WheelFeedback::from_base(&base))
    }

    fn check(&self) -> Result<()> {
        match (&self.can, &self.replay) {
            (Some(_), None) | (None, Some(_)) => Ok(()),
            _ => {
                Err(NodeError::Config("[wheels] takes one of `can` (an interface) or `replay` (a candump log)".into()))
            }
        }
    }

    pub fn resolve_paths(&mut self, config: &Path) {
        let dir = config.parent().unwrap_or(Path::new("."));
        for p in [&mut self.base_config, &mut self.replay].into_iter().flatten() {
            if p.is_relative() {
                *p = dir.join(&*p);
            }
        }
    }
}

/// Frames received, each with its host receive time (ns).
pub type RxFrames = mpsc::Receiver<(u64, CanFrame)>;

/// Frames buffered between the bus and the node's loop; beyond, they are dropped (the wheels
/// are one of several inputs: a late frame is worth less than a scan on time).
const RX_QUEUE: usize = 4096;

/// Starts listening as configured; frames arrive on the receiver until the task ends.
pub async fn start(cfg: &WheelsConfig) -> Result<(RxFrames, tokio::task::JoinHandle<()>)> {
    cfg.check()?;
    let (tx, rx) = mpsc::channel(RX_QUEUE);
    let task = match (&cfg.can, &cfg.replay) {
        (Some(iface), _) => {
            let bus = starc_can::socketcan::SocketCanBus::open(iface)
                .map_err(|e| NodeError::Config(format!("[wheels] can = {iface:?}: {e}")))?;
            tokio::spawn(listen(bus, tx))
        }
        (None, Some(log)) => {
            let text = std::fs::read_to_string(log).map_err(|source| NodeError::Read { path: log.clone(), source })?;
            let start = cfg.replay_start_at_unix_ns.unwrap_or_else(host_now_ns);
            tokio::spawn(replay(text, start, tx))
        }
        (None, None) => return Err(NodeError::Config("[wheels] takes `can` or `replay`".into())),
    };
    Ok((rx, task))
}

async fn listen(mut bus: impl CanBus, tx: mpsc::Sender<(u64, CanFrame)>) {
    loop {
        match bus.recv().await {
            Ok(BusEvent::Frame(rx)) => {
                if tx.try_send((rx.host.ns, rx.frame)).is_err() && tx.is_closed() {
                    return;
                }
            }
            Ok(BusEvent::Fault { .. }) => {}
            Err(e) => {
                tracing::warn!("wheels: the CAN bus failed: {e}; no more wheel odometry");
                return;
            }
        }
    }
}

/// Sends each line's frame when its time comes (the log's first frame at `start_unix_ns`),
/// stamped with the host time it went out, as a bus would deliver it.
async fn replay(text: String, start_unix_ns: u64, tx: mpsc::Sender<(u64, CanFrame)>) {
    let mut first_ns = None;
    for line in text.lines().filter(|l| !l.trim().is_empty()) {
        let Ok(logged) = parse_line(line) else { continue };
        let first = *first_ns.get_or_insert(logged.t_ns);
        let due_ns = start_unix_ns.saturating_add(logged.t_ns.saturating_sub(first));
        let wait_ns = due_ns.saturating_sub(host_now_ns());
        if wait_ns > 0 {
            tokio::time::sleep(Duration::from_nanos(wait_ns)).await;
        }
        if tx.send((host_now_ns(), logged.frame)).await.is_err() {
            return;
        }
    }
}

/// The LiDAR clock minus the host clock, from recent scans: each scan's end (LiDAR clock) and
/// the host time its last packet arrived. The smallest difference is the one least delayed in
/// transit (host time only ever comes after), so it is the estimate.
#[derive(Debug, Default)]
pub struct HostToLidar {
    recent: VecDeque<i128>,
}

impl HostToLidar {
    const SCANS: usize = 50;

    pub fn scan(&mut self, end_ns: u64, last_packet_host_ns: u64) {
        self.recent.push_back(i128::from(end_ns) - i128::from(last_packet_host_ns));
        if self.recent.len() > Self::SCANS {
            self.recent.pop_front();
        }
    }

    /// `host_ns` on the LiDAR's clock; `None` before the first scan.
    pub fn to_lidar(&self, host_ns: u64) -> Option<u64> {
        let offset = self.recent.iter().copied().max()?;
        u64::try_from(i128::from(host_ns) + offset).ok()
    }
}

/// The base's feedback as the LIO takes it: decoded twists, and the pose the wheels alone
/// integrate (for the recording's `/robot/wheel_odom`).
pub struct WheelOdometry {
    decoder: WheelDecoder,
    pose: (f64, f64, f64),
    last_ns: Option<u64>,
    pub twists: u64,
}

/// One decoded twist on the LiDAR clock, with the wheels' integrated planar pose (x, y, yaw).
#[derive(Clone, Copy, Debug)]
pub struct WheelStep {
    pub twist: BaseTwist,
    pub pose: (f64, f64, f64),
}

impl WheelOdometry {
    pub fn new(feedback: &WheelFeedback) -> Result<Self> {
        let decoder = WheelDecoder::new(feedback).map_err(|e| NodeError::Config(format!("[wheels]: {e}")))?;
        Ok(Self { decoder, pose: (0.0, 0.0, 0.0), last_ns: None, twists: 0 })
    }

    /// A frame received at `t_ns` on the LiDAR clock ([`HostToLidar`]); the twist once its
    /// cycle is complete.
    pub fn frame(&mut self, t_ns: u64, frame: &CanFrame) -> Option<WheelStep> {
        let twist = self.decoder.push(t_ns, frame)?;
        if let Some(last) = self.last_ns {
            let dt = twist.t_ns.saturating_sub(last) as f64 * 1e-9;
            let (x, y, yaw) = self.pose;
            let (s, c) = yaw.sin_cos();
            self.pose = (
                x + (c * twist.vx_m_s - s * twist.vy_m_s) * dt,
                y + (s * twist.vx_m_s + c * twist.vy_m_s) * dt,
                yaw + twist.wz_rad_s * dt,
            );
        }
        self.last_ns = Some(twist.t_ns);
        self.twists += 1;
        Some(WheelStep { twist, pose: self.pose })
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use starc_base::kinematics::KinematicsConfig;
    use starc_bridge::wheels::MotorFeedback;

    #[test]
    fn host_times_move_onto_the_lidar_clock_by_the_least_delayed_scan() {
        let mut clock = HostToLidar::default();
        assert_eq!(clock.to_lidar(5), None);
        // The LiDAR runs 1 s behind the host; packets take 2-9 ms to arrive.
        for (k, delay_ms) in [5u64, 2, 9, 3].iter().enumerate() {
            let end = 10_000_000_000 + k as u64 * 100_000_000;
            clock.scan(end, end + 1_000_000_000 + delay_ms * 1_000_000);
        }
        assert_eq!(clock.to_lidar(12_000_000_000), Some(12_000_000_000 - 1_002_000_000));
    }

    #[test]
    fn c620_feedback_becomes_a_twist_and_a_pose() {
        let kinematics =
            KinematicsConfig::Omni3 { wheel_radius_m: 0.05, center_to_wheel_m: 0.2, wheel_angles_deg: None };
        let feedback = WheelFeedback::plain(kinematics, MotorFeedback::C620);
        let mut odo = WheelOdometry::new(&feedback).unwrap();
        let frame = |esc: u16, rpm: i16| {
            let mut d = [0u8; 8];
            d[2..4].copy_from_slice(&rpm.to_be_bytes());
            CanFrame::standard(0x200 + esc, &d).unwrap()
        };
        let wheels = feedback.wheels.len() as u16;
        let mut steps = Vec::new();
        for cycle in 0..3u64 {
            for esc in 1..=wheels {
                let t_ns = 2_000 + cycle * 10_000_000 + u64::from(esc);
                steps.extend(odo.frame(t_ns, &frame(esc, 0)));
            }
        }
        assert_eq!(steps.len(), 3);
        assert_eq!(odo.twists, 3);
        assert!(steps.iter().all(|s| s.twist.vx_m_s.abs() < 1e-12 && s.pose == (0.0, 0.0, 0.0)));
    }

    #[test]
    fn a_config_takes_one_source() {
        let both = WheelsConfig { can: Some("can0".into()), replay: Some("x.log".into()), ..Default::default() };
        assert!(both.check().is_err());
        assert!(WheelsConfig::default().check().is_err());
        assert!(WheelsConfig { can: Some("can0".into()), ..Default::default() }.check().is_ok());
        let e = WheelsConfig::default().feedback().unwrap_err().to_string();
        assert!(e.contains("base_config"), "{e}");
    }
}
