//! Livox Avia data as the LIO takes it: scans with each point at its own firing time, and the
//! Avia's built-in IMU with acceleration in m/s² (the device reports g).

use nalgebra::Vector3;
use starc_livox::data::DataPacket;
use starc_livox::live::ImuReading;
use starc_livox::scan::Scan;
use starc_pipeline::cloud::{CloudPoint, PointCloud};
use starc_pipeline::lio::{ImuSample, LioScan, TimedPoint};

/// An assembled scan: every point stamped `start + offset` on the scan's clock.
pub fn lio_scan(scan: &Scan) -> LioScan {
    let start_ns = scan.start.ns;
    LioScan {
        start_ns,
        end_ns: scan.end().ns,
        clock: scan.start.clock,
        points: scan
            .points
            .iter()
            .map(|p| TimedPoint {
                x_m: p.x_m,
                y_m: p.y_m,
                z_m: p.z_m,
                t_ns: start_ns.saturating_add(u64::from(p.offset_ns)),
            })
            .collect(),
    }
}

/// An assembled scan as a point cloud (reflectivity becomes intensity), for export and recording.
pub fn scan_to_cloud(scan: &Scan) -> PointCloud {
    let points = scan
        .points
        .iter()
        .map(|p| CloudPoint {
            x_m: p.x_m,
            y_m: p.y_m,
            z_m: p.z_m,
            intensity: f32::from(p.reflectivity),
            offset_ns: p.offset_ns,
            line: p.line,
            tag: p.tag,
        })
        .collect();
    PointCloud::new(Some(scan.start), points)
}

/// The IMU sample a data packet carries, if it is an IMU packet (stamped on the LiDAR's clock).
pub fn packet_imu(packet: &DataPacket<'_>) -> Option<ImuSample> {
    let s = packet.imu()?;
    Some(ImuSample {
        t_ns: packet.header.timestamp.ns,
        clock: packet.header.timestamp.clock,
        gyro_rad_s: Vector3::from(s.gyro_rad_s.map(f64::from)),
        acc_m_s2: Vector3::from(s.acc_m_s2().map(f64::from)),
    })
}

/// A live driver's IMU reading (stamped on the LiDAR's clock, like its points).
pub fn reading_imu(r: &ImuReading) -> ImuSample {
    ImuSample {
        t_ns: r.device_time.ns,
        clock: r.device_time.clock,
        gyro_rad_s: Vector3::from(r.sample.gyro_rad_s.map(f64::from)),
        acc_m_s2: Vector3::from(r.sample.acc_m_s2().map(f64::from)),
    }
}
