//! The live driver against Avia mock devices on loopback, in one process: several devices found
//! by their (unicast) broadcast, a device reached without discovery, a power cycle survived, and
//! faults seen for what they are. Each test uses its own 127.0.0.x addresses and free host ports.

use starc_hil::avia::{MockAvia, MockAviaConfig};
use starc_livox::live::{DriverConfig, LivoxDriver, LivoxEvent, ReturnModeSetting, SessionConfig};
use starc_time::Clock;
use std::collections::{BTreeMap, BTreeSet};
use std::net::{Ipv4Addr, SocketAddrV4, UdpSocket};
use std::time::Duration;
use tokio::sync::mpsc::Receiver;

fn free_port() -> u16 {
    UdpSocket::bind("127.0.0.1:0").and_then(|s| s.local_addr()).map(|a| a.port()).unwrap_or(0)
}

fn driver_config(broadcast: Option<SocketAddrV4>) -> DriverConfig {
    DriverConfig {
        host_ip: Ipv4Addr::LOCALHOST,
        broadcast_listen: broadcast,
        cmd_port: 0,
        data_port: 0,
        imu_port: 0,
        ..DriverConfig::default()
    }
}

/// Collects events for `seconds`, or until `stop` says enough.
async fn collect(
    events: &mut Receiver<LivoxEvent>,
    seconds: f64,
    mut stop: impl FnMut(&LivoxEvent) -> bool,
) -> Vec<LivoxEvent> {
    let deadline = tokio::time::Instant::now() + Duration::from_secs_f64(seconds);
    let mut all = Vec::new();
    while let Ok(Some(e)) = tokio::time::timeout_at(deadline, events.recv()).await {
        let done = stop(&e);
        all.push(e);
        if done {
            break;
        }
    }
    all
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn three_devices_found_by_broadcast_stream_points_and_imu() {
    let broadcast = SocketAddrV4::new(Ipv4Addr::LOCALHOST, free_port());
    let (driver, mut events) =
        LivoxDriver::start(driver_config(Some(broadcast))).await.unwrap_or_else(|e| panic!("{e}"));
    let ips: Vec<Ipv4Addr> = (21..24).map(|d| Ipv4Addr::new(127, 0, 0, d)).collect();
    let mut mocks = Vec::new();
    for (k, ip) in ips.iter().enumerate() {
        let mut c = MockAviaConfig::on(*ip);
        c.broadcast_to = broadcast;
        c.seed = k as u64;
        mocks.push(MockAvia::spawn(c).await.unwrap_or_else(|e| panic!("mock on {ip}: {e}")));
    }
    let all = collect(&mut events, 2.5, |_| false).await;

    let discovered: BTreeSet<(Ipv4Addr, String)> = all
        .iter()
        .filter_map(|e| match e {
            LivoxEvent::Discovered { ip, code, .. } => Some((*ip, code.text())),
            _ => None,
        })
        .collect();
    let expected: BTreeSet<(Ipv4Addr, String)> =
        ips.iter().map(|ip| (*ip, format!("STARCMOCK{:06}", ip.octets()[3]))).collect();
    assert_eq!(discovered, expected);

    let mut points: BTreeMap<Ipv4Addr, u64> = BTreeMap::new();
    let mut imu: BTreeMap<Ipv4Addr, u64> = BTreeMap::new();
    for e in &all {
        match e {
            LivoxEvent::Scan { ip, scan } => {
                *points.entry(*ip).or_default() += scan.points.len() as u64;
                assert_eq!(scan.start.clock, Clock::Ptp);
                assert!(scan.points.iter().all(|p| u64::from(p.offset_ns) < scan.period_ns));
                assert!(scan.points.iter().all(|p| p.x_m != 0.0 || p.y_m != 0.0 || p.z_m != 0.0));
                assert!(scan.last_host_receive.is_some_and(|h| h.clock == Clock::Host));
            }
            LivoxEvent::Imu(r) => {
                *imu.entry(r.ip).or_default() += 1;
                let g: f32 = r.sample.acc_m_s2().iter().map(|a| a * a).sum::<f32>().sqrt();
                assert!((9.0..10.6).contains(&g), "a resting Avia feels 1 g, got {g} m/s^2");
            }
            LivoxEvent::BadDatagram { from, error } => panic!("bad datagram from {from}: {error}"),
            _ => {}
        }
    }
    for ip in &ips {
        // About 1.5-2 s of streaming after discovery and setup.
        let p = points.get(ip).copied().unwrap_or(0);
        let i = imu.get(ip).copied().unwrap_or(0);
        assert!(p > 150_000, "{ip}: only {p} points");
        assert!(i > 150, "{ip}: only {i} IMU samples");
    }
    driver.stop().await.unwrap_or_else(|e| panic!("{e}"));
    for m in mocks {
        let stats = m.stop().await.unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(stats.device.crc_errors, 0);
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn connects_without_discovery_sets_dual_return_and_survives_a_power_cycle() {
    let ip = Ipv4Addr::new(127, 0, 0, 31);
    let mut config = driver_config(None);
    config.connect = vec![ip];
    config.session = SessionConfig { return_mode: Some(ReturnModeSetting::Dual), ..SessionConfig::default() };
    config.emit_packets = true;
    let (driver, mut events) = LivoxDriver::start(config).await.unwrap_or_else(|e| panic!("{e}"));
    let mut mock_config = MockAviaConfig::on(ip);
    // Broadcasts go nowhere anyone listens: the driver must not need them.
    mock_config.broadcast_to = SocketAddrV4::new(Ipv4Addr::LOCALHOST, free_port());
    let mock = MockAvia::spawn(mock_config.clone()).await.unwrap_or_else(|e| panic!("{e}"));

    let first =
        collect(&mut events, 3.0, |e| matches!(e, LivoxEvent::Points(p) if p.header.data_type as u8 == 4)).await;
    assert!(first.iter().any(|e| matches!(e, LivoxEvent::Connected { ip: i, .. } if *i == ip)));
    let dual = first.iter().rev().find_map(|e| match e {
        LivoxEvent::Points(p) => Some(p.clone()),
        _ => None,
    });
    let dual = dual.unwrap_or_else(|| panic!("no dual-return packet arrived"));
    // 48 firings of 2 returns; the two returns of a firing share its time.
    assert_eq!(dual.counts.returns, 96);
    assert!(dual.points.iter().all(|p| p.offset_ns % 4167 == 0 && p.offset_ns < 48 * 4167));

    mock.stop().await.unwrap_or_else(|e| panic!("{e}"));
    let lost = collect(&mut events, 5.0, |e| matches!(e, LivoxEvent::Lost { .. })).await;
    assert!(lost.iter().any(|e| matches!(e, LivoxEvent::Lost { ip: i } if *i == ip)), "no loss after 5 s of silence");

    let mock = MockAvia::spawn(mock_config).await.unwrap_or_else(|e| panic!("{e}"));
    let again =
        collect(&mut events, 4.0, |e| matches!(e, LivoxEvent::Scan { scan, .. } if !scan.points.is_empty())).await;
    assert!(again.iter().any(|e| matches!(e, LivoxEvent::Connected { .. })), "no reconnection");
    assert!(again.iter().any(|e| matches!(e, LivoxEvent::Scan { .. })), "no data after reconnection");
    driver.stop().await.unwrap_or_else(|e| panic!("{e}"));
    mock.stop().await.unwrap_or_else(|e| panic!("{e}"));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn dropped_and_corrupted_packets_are_counted_not_trusted() {
    let ip = Ipv4Addr::new(127, 0, 0, 41);
    let mut config = driver_config(None);
    config.connect = vec![ip];
    let (driver, mut events) = LivoxDriver::start(config).await.unwrap_or_else(|e| panic!("{e}"));
    let mut mock_config = MockAviaConfig::on(ip);
    mock_config.broadcast_to = SocketAddrV4::new(Ipv4Addr::LOCALHOST, free_port());
    mock_config.faults.drop = 0.05;
    mock_config.faults.corrupt = 0.02;
    mock_config.seed = 9;
    let mock = MockAvia::spawn(mock_config).await.unwrap_or_else(|e| panic!("{e}"));
    let all = collect(&mut events, 2.5, |_| false).await;
    let lost: u64 = all
        .iter()
        .map(|e| match e {
            LivoxEvent::Scan { scan, .. } => scan.lost_packets,
            _ => 0,
        })
        .sum();
    let packets: u64 = all
        .iter()
        .map(|e| match e {
            LivoxEvent::Scan { scan, .. } => u64::from(scan.packets),
            _ => 0,
        })
        .sum();
    let bad = all.iter().filter(|e| matches!(e, LivoxEvent::BadDatagram { .. })).count();
    assert!(packets > 2000, "{packets} packets");
    let rate = lost as f64 / (lost + packets) as f64;
    // 5 % dropped; corrupted packets that still parse are kept, the rest are counted as bad.
    assert!((0.03..0.10).contains(&rate), "loss rate {rate} ({lost} of {})", lost + packets);
    assert!(bad > 0, "no corrupted packet was refused");
    driver.stop().await.unwrap_or_else(|e| panic!("{e}"));
    mock.stop().await.unwrap_or_else(|e| panic!("{e}"));
}
