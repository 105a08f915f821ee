//! A host made of plain tokio UDP sockets and the livox codecs against a MockAvia on loopback:
//! broadcast, handshake (as the official SDK sends it, cmd_type 1), sampling, point and IMU
//! packets at the real rates, then heartbeat silence and the device dropping the host after 3 s.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use starc_hil::avia::{MockAvia, MockAviaConfig};
use starc_livox::control::{Body, CmdType, ControlFrame, DeviceType, Message, RawFrame, Request, Response};
use starc_livox::data::DataPacket;
use std::net::{Ipv4Addr, SocketAddr, SocketAddrV4};
use std::time::Duration;
use tokio::net::UdpSocket;
use tokio::time::{timeout, Instant};

const LO: Ipv4Addr = Ipv4Addr::LOCALHOST;

async fn socket() -> UdpSocket {
    UdpSocket::bind(SocketAddrV4::new(LO, 0)).await.unwrap()
}

fn port(s: &UdpSocket) -> u16 {
    s.local_addr().unwrap().port()
}

fn v4(a: SocketAddr) -> SocketAddrV4 {
    match a {
        SocketAddr::V4(a) => a,
        SocketAddr::V6(_) => panic!("ipv6 peer"),
    }
}

/// Receives control frames until one satisfies `want` (at most `within`).
async fn recv_frame(
    s: &UdpSocket,
    within: Duration,
    want: impl Fn(&ControlFrame) -> bool,
) -> (ControlFrame, SocketAddrV4) {
    let deadline = Instant::now() + within;
    let mut buf = [0u8; 2048];
    loop {
        let (n, from) =
            tokio::time::timeout_at(deadline, s.recv_from(&mut buf)).await.expect("no frame in time").unwrap();
        if let Ok(frame) = ControlFrame::decode(&buf[..n]) {
            if want(&frame) {
                return (frame, v4(from));
            }
        }
    }
}

async fn command(cmd: &UdpSocket, to: SocketAddrV4, seq: u16, request: Request) -> Response {
    let bytes = ControlFrame::request(seq, request).encode().unwrap();
    cmd.send_to(&bytes, to).await.unwrap();
    let (frame, _) = recv_frame(cmd, Duration::from_secs(1), |f| f.cmd_type == CmdType::Ack && f.seq == seq).await;
    match frame.body {
        Body::Response(r) => r,
        other => panic!("not a response: {other:?}"),
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn host_discovers_handshakes_streams_and_is_dropped_without_heartbeats() {
    let bcast = socket().await;
    let (cmd, data, imu) = (socket().await, socket().await, socket().await);
    let config = MockAviaConfig {
        ip: LO,
        cmd_port: 0,
        data_port: 0,
        imu_port: 0,
        broadcast_to: SocketAddrV4::new(LO, port(&bcast)),
        broadcast_code: Some("LOOPBACKAVIA0001".into()),
        ..MockAviaConfig::default()
    };
    let mock = MockAvia::spawn(config).await.unwrap();

    // Broadcast: code, Avia, from the command port.
    let (frame, device) = recv_frame(&bcast, Duration::from_secs(2), |f| f.cmd_type == CmdType::Msg).await;
    let Body::Message(Message::Broadcast { code, device_type }) = frame.body else { panic!("{frame:?}") };
    assert_eq!((code.text().as_str(), device_type), ("LOOPBACKAVIA0001", DeviceType::Avia));
    assert_eq!(device, mock.cmd_addr());

    // Handshake as the official SDK sends it (cmd_type 1).
    let hs = Request::Handshake { host_ip: LO, data_port: port(&data), cmd_port: port(&cmd), imu_port: port(&imu) };
    let payload =
        [&LO.octets()[..], &port(&data).to_le_bytes(), &port(&cmd).to_le_bytes(), &port(&imu).to_le_bytes()].concat();
    let bytes = RawFrame { cmd_type: CmdType::Ack, seq: 1, cmd_set: 0, cmd_id: 1, payload: &payload }.encode().unwrap();
    assert_eq!(ControlFrame::decode(&bytes).map(|f| f.body).ok(), Some(Body::Request(hs)));
    cmd.send_to(&bytes, device).await.unwrap();
    let (ack, _) = recv_frame(&cmd, Duration::from_secs(1), |f| f.cmd_type == CmdType::Ack && f.seq == 1).await;
    assert_eq!(ack.body, Body::Response(Response::Ret { id: starc_livox::control::CommandId::Handshake, ret: 0 }));
    assert_eq!(command(&cmd, device, 2, Request::Sampling { start: true }).await.ret(), 0);

    // Stream ~0.5 s with heartbeats every 800 ms (one at the start).
    let mut seq = 3u16;
    assert_eq!(command(&cmd, device, seq, Request::Heartbeat).await.ret(), 0);
    let mut last_heartbeat = Instant::now();
    let (mut dbuf, mut ibuf) = ([0u8; 2048], [0u8; 2048]);
    let mut point_stamps = Vec::new();
    let mut imu_stamps = Vec::new();
    let (first, _) = timeout(Duration::from_secs(1), data.recv_from(&mut dbuf)).await.unwrap().unwrap();
    let window = Duration::from_millis(500);
    let started = Instant::now();
    point_stamps.push(DataPacket::parse(&dbuf[..first]).unwrap().header.timestamp.ns);
    while started.elapsed() < window {
        tokio::select! {
            r = data.recv_from(&mut dbuf) => {
                let (n, from) = r.unwrap();
                assert_eq!(v4(from), mock.data_addr());
                point_stamps.push(DataPacket::parse(&dbuf[..n]).unwrap().header.timestamp.ns);
            }
            r = imu.recv_from(&mut ibuf) => {
                let (n, from) = r.unwrap();
                assert_eq!(v4(from), mock.imu_addr());
                let p = DataPacket::parse(&ibuf[..n]).unwrap();
                assert!(p.imu().is_some());
                imu_stamps.push(p.header.timestamp.ns);
            }
            _ = tokio::time::sleep_until(started + window) => {}
        }
    }
    // 0.5 s is 1250 point packets and 100 IMU packets; wall-clock windows on a busy machine wobble.
    let (np, ni) = (point_stamps.len(), imu_stamps.len());
    assert!((1000..=1500).contains(&np), "{np} point packets in 0.5 s");
    assert!((75..=125).contains(&ni), "{ni} imu packets in 0.5 s");
    // Device stamps are exact: 400,032 ns apart, none lost on loopback (allow a rare drop).
    let steps: Vec<u64> = point_stamps.windows(2).map(|w| w[1] - w[0]).collect();
    let exact = steps.iter().filter(|&&d| d == 96 * 4167).count();
    assert!(exact + 3 >= steps.len(), "{} of {} steps exact", exact, steps.len());
    assert!(imu_stamps.windows(2).all(|w| w[1] - w[0] == 5_000_000 || w[1] - w[0] == 10_000_000));

    // Keep heartbeating for a while, then stop: the device drops us 3 s after the last one.
    while last_heartbeat.elapsed() < Duration::from_millis(800) {
        let _ = timeout(Duration::from_millis(50), data.recv_from(&mut dbuf)).await;
    }
    seq += 1;
    let bytes = ControlFrame::request(seq, Request::Heartbeat).encode().unwrap();
    cmd.send_to(&bytes, device).await.unwrap();
    last_heartbeat = Instant::now();
    let mut last_data = Instant::now();
    let quiet = Duration::from_millis(400);
    while let Ok(r) = timeout(quiet, data.recv_from(&mut dbuf)).await {
        r.unwrap();
        last_data = Instant::now();
        assert!(last_heartbeat.elapsed() < Duration::from_secs(5), "still streaming 5 s after the last heartbeat");
    }
    let stopped_after = last_data - last_heartbeat;
    assert!(
        stopped_after > Duration::from_millis(2800) && stopped_after < Duration::from_millis(3400),
        "streaming stopped {stopped_after:?} after the last heartbeat"
    );
    // Broadcasting again.
    let (frame, _) = recv_frame(&bcast, Duration::from_millis(1500), |f| f.cmd_type == CmdType::Msg).await;
    assert!(matches!(frame.body, Body::Message(Message::Broadcast { .. })));

    let stats = mock.stop().await.unwrap();
    assert_eq!(stats.device.host_losses, 1);
    assert_eq!(stats.device.connections, 1);
    assert!(stats.commands_answered() >= 4, "{stats:?}");
    assert!(stats.device.point_packets as usize >= np);
    assert_eq!(stats.device.crc_errors, 0);
}

#[tokio::test]
async fn mocks_side_by_side_on_127_0_0_x_use_the_real_ports_and_differ() {
    let bcast = socket().await;
    let to = SocketAddrV4::new(LO, port(&bcast));
    let a = MockAvia::spawn(MockAviaConfig { broadcast_to: to, ..MockAviaConfig::on(Ipv4Addr::new(127, 0, 0, 2)) })
        .await
        .unwrap();
    let b = MockAvia::spawn(MockAviaConfig { broadcast_to: to, ..MockAviaConfig::on(Ipv4Addr::new(127, 0, 0, 3)) })
        .await
        .unwrap();
    assert_eq!(a.cmd_addr(), "127.0.0.2:65000".parse().unwrap());
    assert_eq!(a.data_addr(), "127.0.0.2:60001".parse().unwrap());
    assert_eq!(a.imu_addr(), "127.0.0.2:60003".parse().unwrap());
    assert_eq!(b.cmd_addr(), "127.0.0.3:65000".parse().unwrap());
    let mut seen = std::collections::BTreeMap::new();
    while seen.len() < 2 {
        let (frame, from) = recv_frame(&bcast, Duration::from_secs(2), |f| f.cmd_type == CmdType::Msg).await;
        if let Body::Message(Message::Broadcast { code, .. }) = frame.body {
            seen.insert(from, code.text());
        }
    }
    assert_eq!(seen.get(&a.cmd_addr()).map(String::as_str), Some("STARCMOCK000002"));
    assert_eq!(seen.get(&b.cmd_addr()).map(String::as_str), Some("STARCMOCK000003"));
    // A second mock on a taken address is a typed bind error.
    let clash = MockAvia::spawn(MockAviaConfig::on(Ipv4Addr::new(127, 0, 0, 2))).await;
    assert!(matches!(clash, Err(starc_hil::HilError::Bind { .. })), "{clash:?}");
    a.stop().await.unwrap();
    b.stop().await.unwrap();
}
