//! The robot node's explorer (`[explore]`) driving a base: mock CiA 402 drives behind slcan on a
//! pty (as tests/ros2_cmd_vel.rs) turn the wheels as the base driver tells them. The explorer
//! sweeps (every wheel the same way round), teleop takes over (the wheels follow its twist, the
//! explorer is held), teleop's silence stops the base, and the node's end halts it.
#![allow(clippy::unwrap_used, clippy::expect_used)]

#[path = "support/base_toml.rs"]
mod base_toml;
use base_toml::cia402_drives;
use nalgebra::{Isometry3, Translation3, Vector3};
use starc_base::Twist;
use starc_hil::motors::MockMotors;
use starc_node::explore::{ExploreDrive, ExploreNodeConfig};
use starc_pipeline::explore::ExploreState;
use std::time::Duration;

/// Drive 1's velocity (drive units: wheel rpm) now.
fn wheel_rpm(mock: &MockMotors, node: u8) -> f64 {
    mock.stats_now().drives.iter().find(|(id, _)| *id == node).map_or(0.0, |(_, d)| f64::from(d.actual_velocity))
}

/// A 6 x 4 m room around the LiDAR at (1, 2), 0.5 m up: floor every 10 cm, walls at 1 m.
fn room() -> Vec<Vector3<f64>> {
    let mut pts = Vec::new();
    for i in 1..60 {
        for j in 1..40 {
            pts.push(Vector3::new(f64::from(i) * 0.1, f64::from(j) * 0.1, 0.0));
        }
        pts.push(Vector3::new(f64::from(i) * 0.1, 0.0, 1.0));
        pts.push(Vector3::new(f64::from(i) * 0.1, 4.0, 1.0));
    }
    pts
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_explorer_drives_the_base_and_teleop_takes_over() {
    let dir = tempfile::tempdir().unwrap();
    let (mock, base_toml) = cia402_drives(dir.path(), (2.0, 4.0)).await;
    let cfg: ExploreNodeConfig =
        toml::from_str(&format!("enabled = true\nbase_config = {base_toml:?}\nlidar_height_m = 0.5\n")).unwrap();
    cfg.validate().unwrap();
    let mut x = ExploreDrive::open(&cfg, 300).await.unwrap();

    // Before any scan there is nothing to drive on: nothing is sent.
    x.control(starc_link::host_now_ns(), None).await.unwrap();
    let lidar = Isometry3::from_parts(Translation3::new(1.0, 2.0, 0.5), Default::default());
    x.on_scan(1_000_000_000, &lidar, room());

    // The first sweep: a turn in place, every wheel the same way round.
    let mut lidar_ns = 1_000_000_000u64;
    for _ in 0..30 {
        lidar_ns += 50_000_000;
        x.control(starc_link::host_now_ns(), Some(lidar_ns)).await.unwrap();
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    let sweep: Vec<f64> = (1..=3).map(|n| wheel_rpm(&mock, n)).collect();
    assert!(sweep.iter().all(|v| *v > 5.0) || sweep.iter().all(|v| *v < -5.0), "{sweep:?}");
    assert!(matches!(x.pilot().explorer().unwrap().state(), ExploreState::Sweeping { .. }));

    // Teleop: straight ahead at 0.3 m/s. Wheel 1 (at 90 deg, across the way) turns at the full
    // 6 rad/s (57 rpm), the other two half as fast the other way round.
    for _ in 0..20 {
        x.teleop(Twist::new(0.3, 0.0, 0.0), starc_link::host_now_ns()).await.unwrap();
        lidar_ns += 50_000_000;
        x.control(starc_link::host_now_ns(), Some(lidar_ns)).await.unwrap();
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    let ahead: Vec<f64> = (1..=3).map(|n| wheel_rpm(&mock, n)).collect();
    assert!((ahead[0].abs() - 57.3).abs() < 5.0, "{ahead:?}");
    assert!((ahead[1] + ahead[0] / 2.0).abs() < 5.0 && (ahead[2] + ahead[0] / 2.0).abs() < 5.0, "{ahead:?}");
    assert_eq!(x.pilot().explorer().unwrap().state(), ExploreState::Stopped);

    // Teleop falls silent: one stop after 300 ms, and the explorer does not resume (no
    // resume_after_s): the wheels come to rest.
    for _ in 0..30 {
        lidar_ns += 50_000_000;
        x.control(starc_link::host_now_ns(), Some(lidar_ns)).await.unwrap();
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    let rest: Vec<f64> = (1..=3).map(|n| wheel_rpm(&mock, n)).collect();
    assert!(rest.iter().all(|v| v.abs() < 2.0), "{rest:?}");
    assert_eq!(x.pilot().explorer().unwrap().state(), ExploreState::Stopped);

    let summary = x.finish().await;
    assert!(summary.control_steps >= 25 && summary.teleop_twists == 20, "{summary:?}");
    assert_eq!(summary.final_state.as_deref(), Some("Stopped"));
    let _ = mock.stop().await;
}
