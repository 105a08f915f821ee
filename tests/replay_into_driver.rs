//! A real capture drives the live driver path: `starc replay` sends the Tele-15 capture's
//! datagrams to the driver's data port with their original timing, and the driver's scans and
//! IMU samples hold exactly what the capture holds.

use starc_livox::live::{DriverConfig, LivoxDriver, LivoxEvent};
use starc_livox::scan::{ScanConfig, TagFilter};
use starc_time::Clock;
use std::net::Ipv4Addr;
use std::path::PathBuf;
use std::process::Command;
use std::time::Duration;

fn tele15() -> Option<PathBuf> {
    let p = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/data/livox/tele15_small.pcap");
    p.exists().then_some(p)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn replayed_tele15_capture_arrives_whole() {
    let Some(capture) = tele15() else {
        eprintln!("skipped: ../shared/data/livox/tele15_small.pcap is absent");
        return;
    };
    let config = DriverConfig {
        host_ip: Ipv4Addr::LOCALHOST,
        broadcast_listen: None,
        cmd_port: 0,
        data_port: 0,
        imu_port: 0,
        scan: ScanConfig { tags: TagFilter::All, blind_m: 0.0, ..ScanConfig::default() },
        ..DriverConfig::default()
    };
    let (driver, mut events) = LivoxDriver::start(config).await.unwrap_or_else(|e| panic!("{e}"));
    let to = format!("udp://127.0.0.1:{}", driver.host.data_port);
    let replay = tokio::task::spawn_blocking(move || {
        Command::new(env!("CARGO_BIN_EXE_starc")).arg("replay").arg(&capture).args(["--to", &to]).output()
    });
    let mut points = 0u64;
    let mut returns = 0u64;
    let mut empty = 0u64;
    let mut packets = 0u64;
    let mut imu = 0u64;
    let mut lost = 0u64;
    let collect_until = tokio::time::Instant::now() + Duration::from_secs(10);
    let output = replay.await.unwrap_or_else(|e| panic!("{e}")).unwrap_or_else(|e| panic!("starc replay: {e}"));
    assert!(output.status.success(), "replay failed: {}", String::from_utf8_lossy(&output.stderr));
    // The last scan is flushed by stop(); drain what the replay produced first.
    tokio::time::sleep(Duration::from_millis(200)).await;
    driver.stop().await.unwrap_or_else(|e| panic!("{e}"));
    while let Ok(Some(e)) = tokio::time::timeout_at(collect_until, events.recv()).await {
        match e {
            LivoxEvent::Scan { scan, .. } => {
                assert_eq!(scan.start.clock, Clock::Ptp);
                points += scan.points.len() as u64;
                returns += scan.returns;
                empty += scan.empty;
                packets += u64::from(scan.packets);
                lost += scan.lost_packets;
            }
            LivoxEvent::Imu(r) => {
                assert_eq!(r.device_time.clock, Clock::Ptp);
                imu += 1;
            }
            LivoxEvent::BadDatagram { from, error } => panic!("{from}: {error}"),
            _ => {}
        }
    }
    assert_eq!(packets, 926);
    assert_eq!(returns, 926 * 96);
    assert_eq!(points, returns - empty);
    assert_eq!(points, 88_844);
    assert_eq!(imu, 74);
    assert_eq!(lost, 0);
}
