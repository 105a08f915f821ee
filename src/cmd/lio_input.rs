//! What `starc lio` feeds the filter besides the capture: an external IMU file (the MIP byte
//! stream of a MicroStrain device, or a CSV), and the conversion of Livox data into LIO inputs.

use anyhow::{bail, Context};
use nalgebra::Vector3;
use starc_imu::timing::{LatencyModel, Timestamper};
use starc_imu::{ImuDecoder, ImuEvent, Protocol};
use starc_livox::data::DataPacket;
use starc_livox::scan::Scan;
use starc_pipeline::lio::{ImuSample, LioScan, TimedPoint};
use starc_time::{Clock, Stamp};
use std::path::Path;

/// Unix time minus GPS time: the epochs 1970-01-01 and 1980-01-06 apart, less the 18 leap
/// seconds GPS has gained since.
const UNIX_MINUS_GPS_NS: i64 = (315_964_800 - 18) * 1_000_000_000;

/// An external IMU's samples, in time order, with `offset_ns` added to their stamps.
///
/// A file starting with the MIP sync bytes is decoded as a MicroStrain MIP stream; its GPS time
/// field (Unix time + 18 s leap seconds, as a PTP-disciplined device reports it) gives the stamp.
/// Otherwise it is read as the simulator's CSV: `time_s,gyro_x_rad_s,..,accel_z_m_s2`.
pub fn read_external_imu(path: &Path, offset_ns: i64) -> anyhow::Result<Vec<ImuSample>> {
    let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
    let mut samples = if bytes.starts_with(&[0x75, 0x65]) { mip(&bytes)? } else { csv(&bytes)? };
    if samples.is_empty() {
        bail!("{}: no IMU samples", path.display());
    }
    for s in &mut samples {
        s.t_ns = s.t_ns.saturating_add_signed(offset_ns);
    }
    samples.sort_by_key(|s| s.t_ns);
    Ok(samples)
}

fn mip(bytes: &[u8]) -> anyhow::Result<Vec<ImuSample>> {
    let mut decoder = ImuDecoder::new(Protocol::Mip, Timestamper::new(LatencyModel::new(0, 0)));
    let mut events = Vec::new();
    decoder.push(bytes, Stamp::new(0, Clock::Host), &mut events);
    let mut out = Vec::with_capacity(events.len());
    let mut untimed = 0u64;
    for e in events {
        let ImuEvent::Sample(s) = e else { continue };
        let Some(gps_ns) = s.device_ns else {
            untimed += 1;
            continue;
        };
        let Some(t_ns) = u64::try_from(gps_ns as i64 + UNIX_MINUS_GPS_NS).ok() else {
            untimed += 1;
            continue;
        };
        out.push(ImuSample { t_ns, gyro_rad_s: Vector3::from(s.gyro_rad_s), acc_m_s2: Vector3::from(s.accel_m_s2) });
    }
    let stats = decoder.stats();
    if stats.bad_checksums > 0 || untimed > 0 {
        tracing::warn!(bad_checksums = stats.bad_checksums, untimed, "external IMU: samples dropped");
    }
    Ok(out)
}

fn csv(bytes: &[u8]) -> anyhow::Result<Vec<ImuSample>> {
    let text = std::str::from_utf8(bytes).context("external IMU: neither a MIP stream nor UTF-8 CSV")?;
    let mut out = Vec::new();
    for (n, line) in text.lines().enumerate() {
        if n == 0 && line.starts_with("time_s") || line.trim().is_empty() {
            continue;
        }
        let v: Vec<f64> =
            line.split(',').map(|f| f.trim().parse::<f64>()).collect::<Result<_, _>>().with_context(|| {
                format!("external IMU CSV line {}: expected 7 numbers (time_s, gyro xyz, accel xyz)", n + 1)
            })?;
        let [t, gx, gy, gz, ax, ay, az] = v[..] else {
            bail!("external IMU CSV line {}: {} fields, expected 7", n + 1, v.len());
        };
        if !(t.is_finite() && t >= 0.0) {
            bail!("external IMU CSV line {}: bad time {t}", n + 1);
        }
        // Seconds with 6 decimals: round to the microsecond they were written with.
        let t_ns = ((t * 1e6).round() as u64).saturating_mul(1000);
        out.push(ImuSample { t_ns, gyro_rad_s: Vector3::new(gx, gy, gz), acc_m_s2: Vector3::new(ax, ay, az) });
    }
    Ok(out)
}

/// The Avia's internal IMU sample in a data packet (acceleration converted from g), if it is one.
pub fn internal_imu(packet: &DataPacket<'_>) -> Option<ImuSample> {
    let s = packet.imu()?;
    Some(ImuSample {
        t_ns: packet.header.timestamp.ns,
        gyro_rad_s: Vector3::from(s.gyro_rad_s.map(f64::from)),
        acc_m_s2: Vector3::from(s.acc_m_s2().map(f64::from)),
    })
}

/// An assembled scan as the filter takes it: each point with its own firing time.
pub fn lio_scan(scan: &Scan) -> LioScan {
    let start = scan.start.ns;
    LioScan {
        start_ns: start,
        end_ns: scan.end().ns,
        points: scan
            .points
            .iter()
            .map(|p| TimedPoint { x_m: p.x_m, y_m: p.y_m, z_m: p.z_m, t_ns: start + u64::from(p.offset_ns) })
            .collect(),
    }
}

/// Whether `path` starts with the MCAP magic.
pub fn is_mcap(path: &Path) -> bool {
    let mut head = [0u8; 8];
    std::fs::File::open(path).and_then(|mut f| std::io::Read::read_exact(&mut f, &mut head)).is_ok()
        && head[..] == *starc_pipeline::record::scan::MAGIC
}

/// One input of the LIO from a recording: the device is the topic's first name
/// (`/robot/points` and `/robot/imu` are device `robot`).
pub enum Recorded {
    Imu(String, ImuSample),
    Scan(String, LioScan),
}

/// Reads a recorded `sensor_msgs/PointCloud2` scan (stamped at its start, with per-point `t`;
/// it ends `period_ns` later, as the live scans do) or `sensor_msgs/Imu`; other messages give
/// `None`.
pub fn recorded(m: &starc_pipeline::record::RecordedMessage, period_ns: u64) -> anyhow::Result<Option<Recorded>> {
    use starc_pipeline::record::reader::cloud_from_msg;
    use starc_pipeline::record::Decoded;
    let device = m.topic.trim_start_matches('/').split('/').next().unwrap_or("").to_string();
    let leaf = m.topic.rsplit('/').next().unwrap_or("");
    if leaf != "points" && leaf != "imu" {
        return Ok(None);
    }
    Ok(match m.decode().with_context(|| format!("{} message {}", m.topic, m.sequence))? {
        Decoded::PointCloud2(msg) => {
            let cloud = cloud_from_msg(&msg, Clock::Ptp)?;
            let Some(start) = cloud.start else { return Ok(None) };
            let points: Vec<TimedPoint> = cloud
                .points
                .iter()
                .map(|p| TimedPoint { x_m: p.x_m, y_m: p.y_m, z_m: p.z_m, t_ns: start.ns + u64::from(p.offset_ns) })
                .collect();
            let last = points.iter().map(|p| p.t_ns).max().unwrap_or(start.ns);
            let end_ns = (start.ns + period_ns).max(last + 1);
            Some(Recorded::Scan(device, LioScan { start_ns: start.ns, end_ns, points }))
        }
        Decoded::Imu(msg) => {
            let Some(t_ns) = msg.header.stamp.to_ns() else { return Ok(None) };
            let (g, a) = (&msg.angular_velocity, &msg.linear_acceleration);
            Some(Recorded::Imu(
                device,
                ImuSample { t_ns, gyro_rad_s: Vector3::new(g.x, g.y, g.z), acc_m_s2: Vector3::new(a.x, a.y, a.z) },
            ))
        }
        _ => None,
    })
}
