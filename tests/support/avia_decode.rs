//! One simulated Avia's IMU samples and scans, decoded from a `starc sim` pcap as a real capture
//! would be: for the tests and benches that feed the LIO directly.

use nalgebra::Vector3;
use starc_livox::capture;
use starc_livox::data::DataPacket;
use starc_livox::scan::{ScanAssembler, ScanConfig};
use starc_pipeline::lio::{ImuSample, LioScan, TimedPoint};
use std::net::Ipv4Addr;
use std::path::Path;

/// One Avia's IMU samples and 100 ms scans (points in the LiDAR frame, per-point PTP times).
pub struct Decoded {
    pub imu: Vec<ImuSample>,
    pub scans: Vec<LioScan>,
}

/// The IMU samples and scans of the Avia at `avia`, decoded from the capture (panics on a bad
/// capture: for tests and benches only).
pub fn decode(pcap: &Path, avia: Ipv4Addr) -> Decoded {
    let mut assembler = ScanAssembler::new(ScanConfig::default()).unwrap();
    let mut imu = Vec::new();
    let mut done = Vec::new();
    for d in capture::open(pcap).unwrap() {
        let d = d.unwrap();
        let (Some(src), Some(dst)) = (d.src, d.dst) else { continue };
        if *src.ip() != avia || src.port() == 65000 || dst.port() == 65000 {
            continue;
        }
        let packet = DataPacket::parse(&d.payload).unwrap();
        if let Some(s) = packet.imu() {
            imu.push(ImuSample {
                t_ns: packet.header.timestamp.ns,
                gyro_rad_s: Vector3::from(s.gyro_rad_s.map(f64::from)),
                acc_m_s2: Vector3::from(s.acc_m_s2().map(f64::from)),
            });
            continue;
        }
        assembler.push(&packet, None, &mut done);
    }
    let scans = done
        .drain(..)
        .map(|s| LioScan {
            start_ns: s.start.ns,
            end_ns: s.end().ns,
            points: s
                .points
                .iter()
                .map(|p| TimedPoint { x_m: p.x_m, y_m: p.y_m, z_m: p.z_m, t_ns: s.start.ns + u64::from(p.offset_ns) })
                .collect(),
        })
        .collect();
    Decoded { imu, scans }
}
