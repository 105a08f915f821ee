//! The LIO on the simulator: the robot's Avia (points and internal IMU) from a `lab` run,
//! decoded from the pcap as a real capture would be, against the simulator's ground truth.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use nalgebra::{Rotation3, Vector3};
use starc_hil::sim::run::{run, SimOptions};
use starc_hil::sim::scenario::Scenario;
use starc_livox::capture;
use starc_livox::data::DataPacket;
use starc_livox::scan::{ScanAssembler, ScanConfig};
use starc_pipeline::lio::{ImuSample, Lio, LioConfig, LioScan, LioStatus, TimedPoint};
use std::net::Ipv4Addr;
use std::path::Path;

const ROBOT_AVIA: Ipv4Addr = Ipv4Addr::new(192, 168, 1, 101);

#[path = "support/tum.rs"]
mod tum;
use tum::{read_tum, truth_at};

/// The robot's IMU samples and scans, decoded from the capture.
fn decode(pcap: &Path) -> (Vec<ImuSample>, Vec<LioScan>) {
    let mut assembler = ScanAssembler::new(ScanConfig::default()).unwrap();
    let (mut imu, mut scans) = (Vec::new(), Vec::new());
    let mut done = Vec::new();
    for d in capture::open(pcap).unwrap() {
        let d = d.unwrap();
        let (Some(src), Some(dst)) = (d.src, d.dst) else { continue };
        if *src.ip() != ROBOT_AVIA || src.port() == 65000 || dst.port() == 65000 {
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
    scans.extend(done.drain(..).map(|s| {
        LioScan {
            start_ns: s.start.ns,
            end_ns: s.end().ns,
            points: s
                .points
                .iter()
                .map(|p| TimedPoint { x_m: p.x_m, y_m: p.y_m, z_m: p.z_m, t_ns: s.start.ns + u64::from(p.offset_ns) })
                .collect(),
        }
    }));
    (imu, scans)
}

#[test]
fn lio_tracks_the_robot_in_the_lab() {
    let secs = 12.0;
    let dir = tempfile::tempdir().unwrap();
    let (scenario, text) = Scenario::load("lab").unwrap();
    let opts =
        SimOptions { out: dir.path().to_path_buf(), duration_s: Some(secs), seed: 1, realtime: false, camera: false };
    run(&scenario, &text, &opts, &mut |_, _| {}).unwrap();
    let truth = read_tum(&dir.path().join("gt_robot.tum"));
    let (imu, scans) = decode(&dir.path().join("avia.pcap"));
    assert!(imu.len() > 2000 && scans.len() > 100, "{} IMU samples, {} scans", imu.len(), scans.len());

    // The Avia's IMU in its LiDAR frame, as extrinsics.json gives it: axes aligned.
    let cfg = LioConfig {
        pos_imu_lidar: Vector3::new(0.04165, 0.02326, -0.0284),
        rot_imu_lidar: Rotation3::identity(),
        ..LioConfig::default()
    };
    let mut lio = Lio::new(cfg);
    let mut out = Vec::new();
    let mut next_scan = scans.into_iter().peekable();
    for s in imu {
        while let Some(scan) = next_scan.next_if(|sc| sc.start_ns <= s.t_ns) {
            lio.push_scan(scan, &mut out);
        }
        lio.push_imu(s, &mut out);
    }
    assert_eq!(lio.status(), LioStatus::Running);
    assert!(out.len() > 100, "{} scans out", out.len());

    let first = &out[0];
    let align = truth_at(&truth, first.end_ns) * first.lidar_pose.inverse();
    let (mut sq, mut worst, mut times) = (0.0, 0.0f64, Vec::new());
    for o in &out {
        let e = ((align * o.lidar_pose).translation.vector - truth_at(&truth, o.end_ns).translation.vector).norm();
        sq += e * e;
        worst = worst.max(e);
        times.push(o.elapsed_us);
    }
    let rmse = (sq / out.len() as f64).sqrt();
    times.sort_unstable();
    let last = out.last().unwrap();
    let travelled =
        (truth_at(&truth, last.end_ns).translation.vector - truth_at(&truth, first.end_ns).translation.vector).norm();
    println!(
        "lab {secs} s: {} scans, travelled {travelled:.2} m, APE RMSE {:.1} mm, max {:.1} mm; per scan (test profile) median {} us, p99 {} us; \
         last: {} points in, {} used, {} matched, degeneracy {:.3}, map {}",
        out.len(),
        rmse * 1e3,
        worst * 1e3,
        times[times.len() / 2],
        times[times.len() * 99 / 100],
        last.points_in,
        last.points_used,
        last.update.matched,
        last.update.degeneracy_index,
        last.map_points
    );
    assert!(travelled > 1.0, "the robot moved: {travelled} m");
    // Measured 11.3 mm (seed 1); FAST-LIO2-class odometry should stay well inside 3 cm here.
    assert!(rmse < 0.03, "APE RMSE {rmse} m");
}
