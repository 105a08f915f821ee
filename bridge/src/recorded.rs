//! Scans, IMU samples and wheel odometry read back from a node's MCAP recording
//! (`/DEVICE/points` as `sensor_msgs/PointCloud2` with per-point `t`, `/DEVICE/imu` as
//! `sensor_msgs/Imu`, `/DEVICE/wheel_odom` as `nav_msgs/Odometry`: its twist).

use crate::BridgeError;
use nalgebra::Vector3;
use starc_pipeline::lio::{ImuSample, LioScan, TimedPoint, WheelSample};
use starc_pipeline::record::reader::cloud_from_msg;
use starc_pipeline::record::{Decoded, RecordedMessage};
use starc_time::Clock;

/// One LIO input from a recording; the device is the topic's first name (`/robot/points` and
/// `/robot/imu` are device `robot`).
pub enum Recorded {
    Imu(String, ImuSample),
    Scan(String, LioScan),
    /// The base's twist as the robot node fed it to its LIO (already on the LiDAR's clock).
    Wheel(String, WheelSample),
}

/// Reads a recorded scan (stamped at its start, with per-point `t`; it ends `period_ns` later,
/// as the live scans do) or IMU sample; other messages give `None`.
pub fn recorded(m: &RecordedMessage, period_ns: u64) -> Result<Option<Recorded>, BridgeError> {
    let device = m.topic.trim_start_matches('/').split('/').next().unwrap_or("").to_string();
    let leaf = m.topic.rsplit('/').next().unwrap_or("");
    if leaf != "points" && leaf != "imu" && leaf != "wheel_odom" {
        return Ok(None);
    }
    let bad = |source| BridgeError::Message { topic: m.topic.clone(), sequence: m.sequence, source };
    Ok(match m.decode().map_err(bad)? {
        Decoded::PointCloud2(msg) => {
            let cloud = cloud_from_msg(&msg, Clock::Ptp).map_err(bad)?;
            let Some(start) = cloud.start else { return Ok(None) };
            let points: Vec<TimedPoint> = cloud
                .points
                .iter()
                .map(|p| TimedPoint { x_m: p.x_m, y_m: p.y_m, z_m: p.z_m, t_ns: start.ns + u64::from(p.offset_ns) })
                .collect();
            let last = points.iter().map(|p| p.t_ns).max().unwrap_or(start.ns);
            let end_ns = (start.ns + period_ns).max(last + 1);
            Some(Recorded::Scan(device, LioScan { start_ns: start.ns, end_ns, clock: start.clock, points }))
        }
        Decoded::Imu(msg) => {
            let Some(t_ns) = msg.header.stamp.to_ns() else { return Ok(None) };
            let (g, a) = (&msg.angular_velocity, &msg.linear_acceleration);
            let sample = ImuSample {
                t_ns,
                clock: Clock::Ptp,
                gyro_rad_s: Vector3::new(g.x, g.y, g.z),
                acc_m_s2: Vector3::new(a.x, a.y, a.z),
            };
            Some(Recorded::Imu(device, sample))
        }
        Decoded::Odometry(msg) if leaf == "wheel_odom" => {
            let Some(t_ns) = msg.header.stamp.to_ns() else { return Ok(None) };
            let (v, w) = (&msg.twist.0, &msg.twist.1);
            Some(Recorded::Wheel(
                device,
                WheelSample { t_ns, clock: Clock::Ptp, vx_m_s: v.x, vy_m_s: v.y, wz_rad_s: w.z },
            ))
        }
        _ => None,
    })
}
