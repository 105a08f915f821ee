//! A hostile zenoh peer (a plain zenoh session, as a stranger on the WiFi would run): without a
//! certificate it cannot connect to a mutual-TLS robot, read or put; with the rig's certificate
//! it cannot put the robot's messages nor serve its map to the rig; reaching a plain loopback
//! node, what it puts beyond its role, on the wrong key, in bursts or as map tiles out of bounds
//! is dropped and counted, and memory stays bounded.
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Duration;

use common::{fast, open_listening, robot_cfg, wait_for, wait_up};
use nalgebra::Vector3;
use starc_link::certs::make_certs;
use starc_link::{host_now_ns, LinkConfig, LinkMessage, LinkNode, LinkPerson, LinkState, Role, TlsConfig};
use starc_pipeline::align::{encode_tiles, TileMap, Vec3};
use starc_pipeline::ar::OrientedBox;
use starc_pipeline::detect::PersonPose;
use starc_pipeline::link::encode;
use starc_time::{Clock, Stamp};
use zenoh::qos::CongestionControl;

/// A zenoh peer that dials `endpoint` only (no scouting, no listening), retrying in the
/// background; with `root_ca`, it trusts our CA (the CA certificate is not secret) but holds no
/// certificate of its own.
async fn stranger(endpoint: &str, root_ca: Option<&Path>) -> zenoh::Session {
    session("peer", endpoint, root_ca, None).await
}

/// A zenoh session in `mode` ("peer" or "client": a hostile end picks either) dialling
/// `endpoint` only; with `leaf` (certificate, key) it shows that certificate (mutual TLS).
async fn session(mode: &str, endpoint: &str, root_ca: Option<&Path>, leaf: Option<(&Path, &Path)>) -> zenoh::Session {
    let mut c = zenoh::Config::default();
    let mut set = |k: &str, v: String| c.insert_json5(k, &v).unwrap();
    set("mode", format!("\"{mode}\""));
    set("connect/endpoints", format!("[\"{endpoint}\"]"));
    set("listen/endpoints", "[]".into());
    set("connect/timeout_ms", "-1".into());
    set("connect/exit_on_failure", "false".into());
    set("connect/retry", "{ period_init_ms: 100, period_max_ms: 100, period_increase_factor: 1 }".into());
    set("scouting/multicast/enabled", "false".into());
    set("scouting/gossip/enabled", "false".into());
    if let Some(ca) = root_ca {
        set("transport/link/tls/root_ca_certificate", format!("\"{}\"", ca.display()));
    }
    if let Some((cert, key)) = leaf {
        set("transport/link/tls/connect_certificate", format!("\"{}\"", cert.display()));
        set("transport/link/tls/connect_private_key", format!("\"{}\"", key.display()));
        set("transport/link/tls/enable_mtls", "true".into());
    }
    zenoh::open(c).await.unwrap()
}

async fn put(session: &zenoh::Session, key: &str, msg: &LinkMessage) {
    put_bytes(session, key, encode(msg).unwrap()).await;
}

async fn put_bytes(session: &zenoh::Session, key: &str, bytes: Vec<u8>) {
    // Blocking: none of the hostile messages may be lost on the way, so every one is counted.
    session.put(key, bytes).congestion_control(CongestionControl::Block).await.unwrap();
}

async fn peers(session: &zenoh::Session) -> usize {
    session.info().peers_zid().await.count()
}

fn heartbeat(role: Role, seq: u32) -> LinkMessage {
    LinkMessage::Heartbeat { role, seq, sent_host_ns: host_now_ns(), map_tiles: 0 }
}

/// Detections of one person with `points` points (12 bytes each on the wire).
fn detections(seq: u32, points: usize) -> LinkMessage {
    let now = host_now_ns();
    LinkMessage::Detections {
        seq,
        stamp: Stamp::new(now, Clock::Ptp),
        scan_last_packet_host_ns: now,
        sent_host_ns: now,
        people: vec![LinkPerson {
            score: 0.9,
            bbox: OrientedBox {
                centre_m: Vector3::new(2.0, 1.0, 0.9),
                size_m: Vector3::new(0.5, 0.4, 1.8),
                yaw_rad: 0.0,
            },
            pose: Some(PersonPose::Upright),
            points_world: (0..points).map(|i| [2.0, 1.0, (i % 1000) as f32 * 0.001]).collect(),
        }],
    }
}

/// One 4 m map tile at `version`: the one with key (x, 0, 0).
fn tile(x: i32, version: u32) -> Vec<u8> {
    let pts: Vec<Vec3> =
        (0..40).map(|i| Vec3::new(4.0 * f64::from(x) + 0.1 * f64::from(i) + 0.05, 1.0, 0.02)).collect();
    let nrm = vec![None; pts.len()];
    let tiles = encode_tiles(&pts, &nrm, 4.0, 0.01, version).unwrap();
    assert_eq!(tiles.len(), 1);
    tiles.into_iter().next().unwrap().1
}

/// Puts `role` heartbeats from `peer` until `node` is Up (the peer is connected and knows the
/// node's subscription).
async fn bring_up(peer: &zenoh::Session, role: Role, node: &LinkNode) {
    let key = format!("starc/{}/heartbeat", role.name());
    for seq in 0..250 {
        put(peer, &key, &heartbeat(role, seq)).await;
        if node.health().state == LinkState::Up {
            return;
        }
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    panic!("the peer never brought the node up: {:?}", node.health());
}

/// This process's resident memory, bytes.
fn rss_bytes() -> u64 {
    let status = std::fs::read_to_string("/proc/self/status").unwrap();
    let line = status.lines().find(|l| l.starts_with("VmRSS:")).unwrap();
    line.split_whitespace().nth(1).unwrap().parse::<u64>().unwrap() * 1024
}

fn tls(dir: &Path, leaf: &str) -> TlsConfig {
    TlsConfig {
        root_ca: dir.join("ca.pem"),
        cert: Some(dir.join(format!("{leaf}.pem"))),
        key: Some(dir.join(format!("{leaf}.key"))),
        mutual: true,
        verify_name: true,
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_peer_without_a_certificate_cannot_connect_read_or_put() {
    let dir = tempfile::tempdir().unwrap();
    let certs = dir.path().join("certs");
    let files = make_certs(&certs, &["127.0.0.1".into()], false).unwrap();
    let (robot, port) = open_listening(
        |p| LinkConfig { tls: Some(tls(&certs, "robot")), ..fast(vec![format!("tls/127.0.0.1:{p}")], vec![]) },
        Role::Robot,
    )
    .await;

    // Two strangers: TLS trusting our CA but with no certificate, and plain TCP to the TLS port.
    // Each listens to everything and puts rig heartbeats (which would bring the robot Up) and
    // detections.
    let heard = Arc::new(AtomicU64::new(0));
    let mut strangers = Vec::new();
    for (endpoint, ca) in
        [(format!("tls/127.0.0.1:{port}"), Some(files.ca_cert.as_path())), (format!("tcp/127.0.0.1:{port}"), None)]
    {
        let s = stranger(&endpoint, ca).await;
        let h = heard.clone();
        // Remote only: a session hears its own puts otherwise.
        let sub = s
            .declare_subscriber("starc/**")
            .allowed_origin(zenoh::sample::Locality::Remote)
            .callback(move |_| {
                h.fetch_add(1, Ordering::Relaxed);
            })
            .await
            .unwrap();
        strangers.push((s, sub));
    }
    for seq in 0..60 {
        for (s, _) in &strangers {
            put(s, "starc/rig/heartbeat", &heartbeat(Role::Rig, seq)).await;
            put(s, "starc/robot/detections", &detections(seq, 10)).await;
        }
        tokio::time::sleep(Duration::from_millis(25)).await;
    }
    for (s, _) in &strangers {
        assert_eq!(peers(s).await, 0, "a stranger without a certificate got a session");
    }
    let h = robot.health();
    assert_eq!((h.state, h.heartbeats, h.received, h.decode_errors), (LinkState::Lost, 0, 0, 0), "{h:?}");

    // The rig holding its certificate connects to the same robot, and the two talk while the
    // strangers still hear nothing.
    let rig = LinkNode::open(
        &LinkConfig { tls: Some(tls(&certs, "rig")), ..fast(vec![], vec![format!("tls/127.0.0.1:{port}")]) },
        Role::Rig,
    )
    .await
    .unwrap();
    assert!(wait_up(&rig, Duration::from_secs(5)).await, "{:?}", rig.health());
    assert!(wait_up(&robot, Duration::from_secs(2)).await, "{:?}", robot.health());
    robot.publish(&detections(1, 10)).await.unwrap();
    tokio::time::sleep(Duration::from_millis(300)).await;
    assert_eq!(heard.load(Ordering::Relaxed), 0, "a stranger read the link");
    for (s, sub) in strangers {
        sub.undeclare().await.unwrap();
        s.close().await.unwrap();
    }
    rig.close().await.unwrap();
    robot.close().await.unwrap();
}

/// An insider: a zenoh session holding the rig's valid certificate (a stolen rig, a rig host
/// taken over) joins a mutual-TLS robot while the real rig is linked, as a peer and then as a
/// client (a peer brokers for its clients: without zenoh's access control by certificate name a
/// client's `starc/robot/detections` reached the rig through the robot, 20 of 20). It puts robot
/// detections and map tiles on the robot's keys and serves a forged map tile on the robot's map
/// queryable key: none of it reaches the rig, and the robot's inbox takes nothing; its rig-keyed
/// detections (allowed by name, refused by kind) show that it was connected and heard.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_peer_holding_the_rig_certificate_cannot_put_robot_messages_or_serve_the_map() {
    let dir = tempfile::tempdir().unwrap();
    let certs = dir.path().join("certs");
    let files = make_certs(&certs, &["127.0.0.1".into()], false).unwrap();
    let (mut robot, port) = open_listening(
        |p| LinkConfig { tls: Some(tls(&certs, "robot")), ..fast(vec![format!("tls/127.0.0.1:{p}")], vec![]) },
        Role::Robot,
    )
    .await;
    // The robot's one real tile, fetched by the rig when the link comes up (the map query and its
    // replies pass the built-in policy).
    robot.publish(&LinkMessage::MapTile { bytes: tile(0, 1) }).await.unwrap();
    let endpoint = format!("tls/127.0.0.1:{port}");
    let mut rig = LinkNode::open(
        &LinkConfig { tls: Some(tls(&certs, "rig")), ..fast(vec![], vec![endpoint.clone()]) },
        Role::Rig,
    )
    .await
    .unwrap();
    assert!(wait_up(&rig, Duration::from_secs(5)).await, "{:?}", rig.health());
    assert!(wait_up(&robot, Duration::from_secs(2)).await, "{:?}", robot.health());

    let forged_map = encode(&LinkMessage::MapTile { bytes: tile(5, 7) }).unwrap();
    let mut witnessed = 0;
    for mode in ["peer", "client"] {
        let insider = session(mode, &endpoint, Some(&files.ca_cert), Some((&files.rig_cert, &files.rig_key))).await;
        // Connected and heard: its rig-keyed detections reach the robot (refused there by kind).
        let mut heard = false;
        for seq in 0..100 {
            put(&insider, "starc/rig/detections", &detections(seq, 10)).await;
            witnessed += 1;
            if wait_for(Duration::from_millis(50), || robot.health().refused.kind == witnessed).await {
                heard = true;
                break;
            }
        }
        assert!(heard, "{mode}: the insider never reached the robot: {:?}", robot.health());
        let forged = forged_map.clone();
        let queryable = insider
            .declare_queryable("starc/robot/map/**")
            .callback(move |query| {
                use zenoh::Wait;
                let _ = query.reply("starc/robot/map/5/0/0", forged.clone()).wait();
            })
            .await
            .unwrap();
        for seq in 0..20 {
            put(&insider, "starc/robot/detections", &detections(900 + seq, 10)).await;
        }
        for x in 10..15 {
            put(&insider, "starc/robot/map_tile", &LinkMessage::MapTile { bytes: tile(x, 1) }).await;
        }
        // A map fetch now would reach the forged queryable if the robot had taken its declaration.
        let fetched = rig.health().map_tiles_fetched;
        rig.request_map();
        assert!(
            wait_for(Duration::from_secs(3), || rig.health().map_tiles_fetched > fetched).await,
            "{mode}: {:?}",
            rig.health()
        );
        tokio::time::sleep(Duration::from_millis(300)).await;
        queryable.undeclare().await.unwrap();
        insider.close().await.unwrap();
    }
    let mut tiles = Vec::new();
    while let Some(r) = rig.try_recv() {
        match r.msg {
            LinkMessage::Detections { seq, .. } => panic!("the rig took forged detections {seq}"),
            LinkMessage::MapTile { bytes } => tiles.push(starc_pipeline::link::map_tile_id(&bytes).unwrap()),
            _ => {}
        }
    }
    // Only the robot's own tile, once on link up and once per fetch asked for.
    assert!(!tiles.is_empty() && tiles.iter().all(|t| *t == ((0, 0, 0), 1)), "{tiles:?}");
    let h = rig.health();
    assert_eq!((h.refused, h.decode_errors, h.map_tiles), (Default::default(), 0, 1), "{h:?}");
    let h = robot.health();
    assert_eq!((h.refused.kind, h.refused.key, h.received, h.decode_errors), (witnessed, 0, 0, 0), "{h:?}");
    assert!(robot.try_recv().is_none());
    rig.close().await.unwrap();
    robot.close().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn kinds_a_rig_never_sends_and_wrong_keys_are_dropped_and_counted() {
    let (mut robot, port) = open_listening(robot_cfg, Role::Robot).await;
    let peer = stranger(&format!("tcp/127.0.0.1:{port}"), None).await;
    bring_up(&peer, Role::Rig, &robot).await;
    let pose =
        LinkMessage::RobotPose { stamp: Stamp::new(1, Clock::Ptp), world_t_lidar: nalgebra::Isometry3::identity() };
    // Six messages of kinds a rig never sends, on the keys their kinds would use.
    for seq in 0..4 {
        put(&peer, "starc/rig/detections", &detections(seq, 100)).await;
    }
    put(&peer, "starc/rig/pose", &pose).await;
    put(&peer, "starc/rig/map_tile", &LinkMessage::MapTile { bytes: tile(0, 1) }).await;
    // A heartbeat naming the robot, from the rig's side.
    put(&peer, "starc/rig/heartbeat", &heartbeat(Role::Robot, 1)).await;
    // A clock probe passed off as a heartbeat; a heartbeat on the probe key.
    put(&peer, "starc/rig/heartbeat", &LinkMessage::ClockProbe { seq: 1, t1_ns: 2 }).await;
    put(&peer, "starc/rig/clock_probe", &heartbeat(Role::Rig, 1)).await;
    let counted = wait_for(Duration::from_secs(5), || {
        let r = robot.health().refused;
        (r.kind, r.key) == (7, 2)
    })
    .await;
    let h = robot.health();
    assert!(counted, "{:?}", h.refused);
    assert_eq!((h.received, h.queue_bytes, h.decode_errors), (0, 0, 0), "{h:?}");
    assert!(robot.try_recv().is_none());
    peer.close().await.unwrap();
    robot.close().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_burst_of_large_messages_leaves_the_robot_bounded() {
    let (robot, port) = open_listening(robot_cfg, Role::Robot).await;
    let peer = stranger(&format!("tcp/127.0.0.1:{port}"), None).await;
    bring_up(&peer, Role::Rig, &robot).await;
    // 200 detections of 1 MiB each on the rig's key: the robot used to queue them for a caller
    // that never reads (1024 slots of up to 16 MiB).
    let frame = encode(&detections(0, 87_000)).unwrap();
    assert!(frame.len() > 1_000_000, "{}", frame.len());
    let before = rss_bytes();
    for _ in 0..200 {
        put_bytes(&peer, "starc/rig/detections", frame.clone()).await;
    }
    let all = wait_for(Duration::from_secs(20), || robot.health().refused.kind == 200).await;
    let grown = rss_bytes().saturating_sub(before);
    let h = robot.health();
    assert!(all, "{:?}", h);
    assert_eq!((h.received, h.queue_bytes), (0, 0));
    // 200 MiB went through; what stays is zenoh's and the allocator's working set.
    assert!(grown < 64 << 20, "resident memory grew by {} MiB", grown >> 20);
    peer.close().await.unwrap();
    robot.close().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_rig_that_does_not_read_holds_at_most_queue_bytes_and_the_newest_messages() {
    let (mut rig, port) = open_listening(
        |p| LinkConfig { queue_bytes: 1 << 20, ..fast(vec![format!("tcp/127.0.0.1:{p}")], vec![]) },
        Role::Rig,
    )
    .await;
    let peer = stranger(&format!("tcp/127.0.0.1:{port}"), None).await;
    bring_up(&peer, Role::Robot, &rig).await;
    // 100 detections of about 96 kB: ten fit in 1 MiB.
    for seq in 0..100 {
        put(&peer, "starc/robot/detections", &detections(seq, 8000)).await;
    }
    assert!(wait_for(Duration::from_secs(10), || rig.health().received == 100).await, "{:?}", rig.health());
    let h = rig.health();
    assert!(h.queue_bytes <= 1 << 20, "{h:?}");
    assert_eq!(h.queue_drops, 90, "{h:?}");
    let mut seqs = Vec::new();
    while let Some(r) = rig.try_recv() {
        if let LinkMessage::Detections { seq, .. } = r.msg {
            seqs.push(seq);
        }
    }
    assert_eq!(seqs, (90..100).collect::<Vec<_>>());
    assert_eq!(rig.health().queue_bytes, 0);
    peer.close().await.unwrap();
    rig.close().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn map_tiles_far_ahead_or_beyond_the_bounds_are_refused_and_later_updates_still_land() {
    let (mut rig, port) = open_listening(
        |p| LinkConfig {
            max_tiles: 3,
            max_tile_version_lead: 1000,
            ..fast(vec![format!("tcp/127.0.0.1:{p}")], vec![])
        },
        Role::Rig,
    )
    .await;
    let peer = stranger(&format!("tcp/127.0.0.1:{port}"), None).await;
    bring_up(&peer, Role::Robot, &rig).await;
    let key = "starc/robot/map_tile";
    let send = |x: i32, version: u32| LinkMessage::MapTile { bytes: tile(x, version) };
    // u32::MAX would hold tile 0 for ever (the rig keeps the highest version of each tile).
    put(&peer, key, &send(0, u32::MAX)).await;
    put(&peer, key, &send(0, 1)).await;
    put(&peer, key, &send(0, 2)).await;
    // 1003 is more than 1000 ahead of the newest taken (2); 1002 is not.
    put(&peer, key, &send(1, 1003)).await;
    put(&peer, key, &send(1, 1002)).await;
    put(&peer, key, &send(2, 1)).await;
    // A fourth distinct tile, beyond max_tiles = 3.
    put(&peer, key, &send(3, 1)).await;
    assert!(wait_for(Duration::from_secs(5), || rig.health().refused.tiles == 3).await, "{:?}", rig.health().refused);
    let mut map = TileMap::default();
    let mut taken = Vec::new();
    let deadline = tokio::time::Instant::now() + Duration::from_secs(2);
    while taken.len() < 4 {
        let Ok(Some(r)) = tokio::time::timeout_at(deadline, rig.recv()).await else { break };
        if let LinkMessage::MapTile { bytes } = r.msg {
            let version = starc_pipeline::link::map_tile_id(&bytes).unwrap().1;
            taken.push((map.apply(&bytes).unwrap(), version));
        }
    }
    // Each update of tile 0 lands: the forged version never reached the map.
    assert_eq!(taken, vec![(true, 1), (true, 2), (true, 1002), (true, 1)]);
    assert_eq!(map.tile_count(), 3);
    assert_eq!(rig.health().map_tiles, 3);
    peer.close().await.unwrap();
    rig.close().await.unwrap();
}
