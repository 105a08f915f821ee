//! The device table's bounds, sans-IO: datagrams from many (spoofed) source addresses go
//! straight into [`Core`]; nothing touches a network.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use super::*;
use crate::control::{DeviceType, Response};
use crate::data::{encode_imu_packet, encode_point_packet, DataHeader, DataType, ImuSample, Return, StatusWord};
use crate::ports;
use starc_time::Clock;

const MS: u64 = 1_000_000;

fn host() -> HostEndpoint {
    HostEndpoint { ip: Ipv4Addr::LOCALHOST, cmd_port: 55501, data_port: 56001, imu_port: 56001 }
}

fn core(config: DriverConfig) -> (Core, mpsc::Receiver<LivoxEvent>) {
    let (tx, rx) = mpsc::channel(1024);
    (Core::new(config, host(), tx).unwrap(), rx)
}

/// The `k`th spoofed source: 10.0.0.0 + k.
fn spoofed(k: u32) -> Ipv4Addr {
    Ipv4Addr::from(0x0a00_0000 + k)
}

fn from(ip: Ipv4Addr, port: u16) -> SocketAddr {
    SocketAddr::V4(SocketAddrV4::new(ip, port))
}

fn broadcast(code: &str) -> Vec<u8> {
    let code = BroadcastCode::from_text(code).unwrap();
    ControlFrame::message(0, Message::Broadcast { code, device_type: DeviceType::Avia }).encode().unwrap()
}

fn header(data_type: DataType, ts_ns: u64) -> DataHeader {
    DataHeader {
        version: 5,
        slot: 1,
        lidar_id: 1,
        status: StatusWord::from_raw(0),
        data_type,
        timestamp: Stamp::new(ts_ns, Clock::Ptp),
    }
}

fn points(ts_ns: u64) -> Vec<u8> {
    let returns = vec![Return { x_m: 3.0, y_m: 1.0, z_m: 0.5, reflectivity: 10, tag: 0 }; 96];
    let mut out = Vec::new();
    encode_point_packet(&header(DataType::ExtendedCartesian, ts_ns), &returns, &mut out).unwrap();
    out
}

fn imu(ts_ns: u64, gyro_rad_s: [f32; 3], acc_g: [f32; 3]) -> Vec<u8> {
    let mut out = Vec::new();
    encode_imu_packet(&header(DataType::Imu, ts_ns), &ImuSample { gyro_rad_s, acc_g }, &mut out).unwrap();
    out
}

fn drain(rx: &mut mpsc::Receiver<LivoxEvent>) -> Vec<LivoxEvent> {
    let mut all = Vec::new();
    while let Ok(e) = rx.try_recv() {
        all.push(e);
    }
    all
}

fn host_time(ns: u64) -> Stamp {
    Stamp::new(ns, Clock::Host)
}

/// Answers every frame in `sends` for `ip` as a device would, successfully.
fn answer(core: &mut Core, now_ns: u64, ip: Ipv4Addr, sends: &Sends) -> Sends {
    let mut out = Vec::new();
    for (to, bytes) in sends {
        if *to != ip {
            continue;
        }
        let Ok(frame) = ControlFrame::decode(bytes) else { continue };
        let Body::Request(r) = frame.body else { continue };
        let response = match r {
            Request::QueryDeviceInfo => Response::QueryDeviceInfo { ret: 0, firmware: [1, 2, 3, 4] },
            Request::Heartbeat => Response::Heartbeat { ret: 0, work_state: 1, feature: 0, status: 0 },
            other => Response::Ret { id: other.id(), ret: 0 },
        };
        let ack = ControlFrame::response(frame.seq, response).encode().unwrap();
        out.extend(core.on_control(now_ns, from(ip, ports::DEVICE_CMD_PORT), &ack));
    }
    out
}

#[test]
fn ten_thousand_spoofed_broadcasters_hold_at_most_max_devices_and_are_forgotten() {
    // A config that names no device takes any device heard: the bounds are all that stand
    // between a spoofer and the host's memory.
    let config = DriverConfig::default();
    let cap = config.max_devices;
    let (mut core, mut rx) = core(config);
    let mut handshakes = 0usize;
    for k in 0..10_000u32 {
        let now = u64::from(k) * 100_000; // 10 000 broadcasts in one second
        let sends = core.on_broadcast(now, from(spoofed(k), 55000), &broadcast(&format!("SPOOF{k:010}")));
        handshakes += sends.len();
        assert!(core.devices.len() <= cap);
        if k % 500 == 0 {
            handshakes += core.poll(now).len();
        }
    }
    let s = core.stats();
    println!("after 10 000 spoofed broadcasters: {s:?}");
    assert_eq!((s.devices, s.sessions), (cap, cap));
    assert_eq!(s.refused_full, 10_000 - cap as u64);
    // Each session handshakes at most once a second: 32 sessions over 1 s, not 10 000.
    assert!(handshakes <= 2 * cap, "{handshakes} handshakes");
    let discovered = drain(&mut rx).iter().filter(|e| matches!(e, LivoxEvent::Discovered { .. })).count();
    assert_eq!(discovered, cap);
    // Silence: all forgotten after forget_after_ms (10 s), none before.
    let _ = core.poll(9_000 * MS);
    assert_eq!(core.stats().devices, cap);
    let _ = core.poll(11_000 * MS);
    let s = core.stats();
    assert_eq!((s.devices, s.sessions, s.forgotten), (0, 0, cap as u64));
    // The table has room again: a real device found after the flood is taken.
    let _ = core.on_broadcast(11_001 * MS, from(Ipv4Addr::new(192, 168, 1, 101), 55000), &broadcast("3JEDK380016K261"));
    assert_eq!(core.stats().sessions, 1);
}

#[test]
fn ten_thousand_spoofed_data_senders_are_dropped_and_counted_by_default() {
    let robot_avia = Ipv4Addr::new(192, 168, 1, 101);
    let config = DriverConfig { connect: vec![robot_avia], ..DriverConfig::default() };
    let (mut core, mut rx) = core(config);
    let packet = points(5_000_000_000);
    for k in 0..10_000u32 {
        core.on_data(u64::from(k) * 1000, from(spoofed(k), 56001), &packet, host_time(0));
    }
    let s = core.stats();
    assert_eq!((s.devices, s.sessions, s.unsolicited_data), (1, 1, 10_000));
    // Nothing decoded for a stranger: no scans, no events, no assemblers.
    assert!(drain(&mut rx).is_empty());
    assert_eq!(
        core.devices.values().filter_map(|d| d.assembler.as_ref()).map(|a| a.pending_points()).sum::<usize>(),
        0
    );
    // The configured device's data is taken.
    core.on_data(20 * MS, from(robot_avia, 56001), &packet, host_time(0));
    assert_eq!(core.devices.get(&robot_avia).and_then(|d| d.assembler.as_ref()).map(|a| a.pending_points()), Some(96));
    println!("spoofed data senders: {s:?}");
}

#[test]
fn with_unsolicited_data_opted_in_the_senders_are_still_capped_and_forgotten() {
    let config = DriverConfig { accept_unsolicited_data: true, max_devices: 8, ..DriverConfig::default() };
    let (mut core, _rx) = core(config);
    let packet = points(5_000_000_000);
    for k in 0..10_000u32 {
        core.on_data(u64::from(k) * 1000, from(spoofed(k), 56001), &packet, host_time(0));
        assert!(core.devices.len() <= 8);
    }
    let s = core.stats();
    assert_eq!((s.devices, s.sessions, s.refused_full), (8, 0, 10_000 - 8));
    let _ = core.poll(20_000 * MS);
    assert_eq!((core.stats().devices, core.stats().forgotten), (0, 8));
}

#[test]
fn a_passive_driver_takes_data_from_anyone_but_only_max_devices_of_them() {
    // No discovery, no connect (`starc livox monitor --passive` fed by `starc replay`): the
    // only way such a driver gets data.
    let config = DriverConfig { broadcast_listen: None, max_devices: 4, ..DriverConfig::default() };
    let (mut core, mut rx) = core(config);
    for k in 0..1000u32 {
        core.on_data(0, from(spoofed(k), 56001), &points(5_000_000_000), host_time(0));
    }
    let s = core.stats();
    assert_eq!((s.devices, s.sessions, s.unsolicited_data, s.refused_full), (4, 0, 0, 996));
    assert!(drain(&mut rx).is_empty(), "scans still in progress");
}

#[test]
fn a_config_naming_its_devices_ignores_other_broadcasts_unless_opted_in() {
    let ours = "3JEDK380016K261";
    let config = DriverConfig { accept_codes: vec![ours.into()], ..DriverConfig::default() };
    let (mut core, _rx) = core(config.clone());
    for k in 0..1000u32 {
        assert!(core.on_broadcast(0, from(spoofed(k), 55000), &broadcast(&format!("SPOOF{k:010}"))).is_empty());
    }
    assert_eq!((core.stats().devices, core.stats().unknown_broadcasts), (0, 1000));
    let sends = core.on_broadcast(0, from(Ipv4Addr::new(192, 168, 1, 101), 55000), &broadcast(ours));
    assert_eq!(sends.len(), 1, "the handshake goes out at once");
    assert_eq!(core.stats().sessions, 1);
    // Control frames from strangers are ignored before decoding.
    let ack =
        ControlFrame::response(1, Response::Ret { id: crate::control::CommandId::Handshake, ret: 0 }).encode().unwrap();
    assert!(core.on_control(0, from(spoofed(1), 65000), &ack).is_empty());
    assert_eq!(core.stats().unsolicited_control, 1);

    // A config that names an address only also takes only that device.
    let connect = DriverConfig { connect: vec![Ipv4Addr::new(192, 168, 1, 102)], ..DriverConfig::default() };
    let (mut core, _rx) = self::core(connect.clone());
    let _ = core.on_broadcast(0, from(spoofed(7), 55000), &broadcast("SPOOF"));
    assert_eq!((core.stats().devices, core.stats().unknown_broadcasts), (1, 1));

    // So does a config that names an address to accept broadcasts from (a node's lidar_ip).
    let ours_ip = Ipv4Addr::new(192, 168, 1, 101);
    let by_ip = DriverConfig { accept_ips: vec![ours_ip], ..DriverConfig::default() };
    let (mut core, _rx) = self::core(by_ip);
    let _ = core.on_broadcast(0, from(spoofed(7), 55000), &broadcast(ours));
    assert_eq!((core.stats().devices, core.stats().unknown_broadcasts), (0, 1));
    assert_eq!(core.on_broadcast(0, from(ours_ip, 55000), &broadcast("ANY0000000001")).len(), 1);
    assert_eq!(core.stats().sessions, 1);

    // The opt-in takes any device, bounded.
    let any = DriverConfig { accept_any_device: true, max_devices: 4, ..config };
    let (mut core, _rx) = self::core(any);
    for k in 0..100u32 {
        let _ = core.on_broadcast(0, from(spoofed(k), 55000), &broadcast(&format!("SPOOF{k:010}")));
    }
    assert_eq!((core.stats().sessions, core.stats().refused_full), (4, 96));
}

#[test]
fn devices_that_answer_are_kept_and_connect_devices_are_never_forgotten() {
    let pinned = Ipv4Addr::new(192, 168, 1, 102);
    let real = Ipv4Addr::new(192, 168, 1, 101);
    let config = DriverConfig { connect: vec![pinned], accept_any_device: true, ..DriverConfig::default() };
    let (mut core, _rx) = core(config);
    let mut sends = core.on_broadcast(0, from(real, 55000), &broadcast("3JEDK380016K261"));
    // The real device answers everything for a minute, and sends data; the pinned one is silent.
    for t in 0..600u64 {
        let now = t * 100 * MS;
        for _ in 0..5 {
            sends = answer(&mut core, now, real, &sends);
        }
        core.on_data(now, from(real, 56001), &points(5_000_000_000 + now), host_time(now));
        sends.extend(core.poll(now));
    }
    let s = core.stats();
    assert_eq!((s.devices, s.sessions, s.forgotten), (2, 2, 0));
    // The real one falls silent: forgotten after 10 s; the pinned one stays.
    let _ = core.poll(71_000 * MS);
    assert_eq!((core.stats().devices, core.stats().forgotten), (1, 1));
    assert!(core.devices.contains_key(&pinned));
}

#[test]
fn a_repeated_time_stamp_cannot_grow_a_devices_scan_past_the_cap() {
    let avia = Ipv4Addr::new(192, 168, 1, 101);
    let config = DriverConfig { connect: vec![avia], ..DriverConfig::default() };
    let cap = config.scan.max_points();
    let (mut core, mut rx) = core(config);
    let packet = points(5_000_000_000);
    for k in 0..5_000u64 {
        core.on_data(k * MS, from(avia, 56001), &packet, host_time(k));
    }
    let held = core.devices.get(&avia).and_then(|d| d.assembler.as_ref()).map(|a| a.pending_points());
    assert_eq!(held, Some(cap));
    let s = core.stats();
    assert_eq!((s.cut_points, s.cut_scans), (5_000 * 96 - cap as u64, 1));
    assert!(drain(&mut rx).is_empty(), "the scan never ends, so nothing is emitted");
}

#[test]
fn nan_and_infinite_imu_packets_are_dropped_and_counted() {
    let avia = Ipv4Addr::new(192, 168, 1, 101);
    let (mut core, mut rx) = core(DriverConfig { connect: vec![avia], ..DriverConfig::default() });
    let good = ([0.01, 0.02, 0.03], [0.0, 0.0, 1.0]);
    let bad = [
        ([f32::NAN, 0.0, 0.0], good.1),
        (good.0, [0.0, f32::INFINITY, 1.0]),
        (good.0, [0.0, 0.0, f32::NEG_INFINITY]),
        ([0.0, 0.0, f32::NAN], [f32::NAN; 3]),
    ];
    for (k, (g, a)) in bad.iter().enumerate() {
        core.on_data(k as u64 * 5 * MS, from(avia, 56001), &imu(k as u64 * 5_000_000, *g, *a), host_time(0));
    }
    core.on_data(30 * MS, from(avia, 56001), &imu(30_000_000, good.0, good.1), host_time(0));
    let readings: Vec<ImuReading> = drain(&mut rx)
        .into_iter()
        .filter_map(|e| match e {
            LivoxEvent::Imu(r) => Some(r),
            _ => None,
        })
        .collect();
    assert_eq!(readings.len(), 1);
    assert!(readings[0].sample.is_finite());
    assert_eq!(core.stats().non_finite_imu, 4);
}

#[test]
fn bad_bounds_are_refused_naming_the_key() {
    let cases = [
        (DriverConfig { max_devices: 0, ..DriverConfig::default() }, "max_devices"),
        (DriverConfig { forget_after_ms: 0, ..DriverConfig::default() }, "forget_after_ms"),
        (
            DriverConfig {
                connect: vec![Ipv4Addr::new(192, 168, 1, 101), Ipv4Addr::new(192, 168, 1, 102)],
                max_devices: 1,
                ..DriverConfig::default()
            },
            "max_devices",
        ),
    ];
    for (config, key) in cases {
        let (tx, _rx) = mpsc::channel(16);
        let err = Core::new(config, host(), tx).err().map(|e| e.to_string()).unwrap_or_default();
        assert!(err.contains(key), "{err}");
    }
}
