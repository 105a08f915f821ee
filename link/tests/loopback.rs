//! Robot and rig nodes in one process over tcp/127.0.0.1: every kind arrives, a late rig gets the
//! whole map, and a lost robot is seen Stale then Lost, then Up again with the map fetched anew.
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use std::time::Duration;

use common::{collect, free_port, open_listening, rig_cfg, robot_cfg, wait_for, wait_up};
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use starc_link::{host_now_ns, LinkMessage, LinkNode, LinkPerson, LinkState, Received, Role};
use starc_pipeline::align::{encode_tiles, TileMap, Vec3};
use starc_pipeline::ar::OrientedBox;
use starc_pipeline::detect::PersonPose;
use starc_time::{Clock, Stamp};

/// Map tiles of a 12 m x 4 m floor at `version`: three 4 m tiles.
fn tiles(version: u32) -> Vec<Vec<u8>> {
    let mut pts = Vec::new();
    for i in 0..120 {
        for j in 0..40 {
            pts.push(Vec3::new(0.1 * f64::from(i) + 0.05, 0.1 * f64::from(j) + 0.05, 0.02));
        }
    }
    let nrm = vec![Some(Vec3::new(0.0, 0.0, 1.0)); pts.len()];
    encode_tiles(&pts, &nrm, 4.0, 0.01, version).unwrap().into_iter().map(|(_, b)| b).collect()
}

/// A detection of a scan whose last packet reached the robot 25 ms before sending; the scan is
/// stamped on its LiDAR's free-running clock, 5 s after that LiDAR powered up.
fn detections(seq: u32) -> LinkMessage {
    let now = host_now_ns();
    LinkMessage::Detections {
        seq,
        stamp: Stamp::new(5_000_000_000, Clock::Device),
        scan_last_packet_host_ns: now - 25_000_000,
        sent_host_ns: now,
        people: vec![LinkPerson {
            score: 0.9,
            bbox: OrientedBox {
                centre_m: Vector3::new(2.0, 1.0, 0.9),
                size_m: Vector3::new(0.5, 0.4, 1.8),
                yaw_rad: 0.3,
            },
            pose: Some(PersonPose::Upright),
            points_world: (0..2000).map(|i| [2.0 + (i % 10) as f32 * 0.02, 1.0, (i / 10) as f32 * 0.009]).collect(),
        }],
    }
}

fn count(got: &[Received], f: impl Fn(&Received) -> bool) -> usize {
    got.iter().filter(|r| f(r)).count()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_kind_arrives_and_decodes() {
    let (robot, port) = open_listening(robot_cfg, Role::Robot).await;
    let mut rig = LinkNode::open(&rig_cfg(port), Role::Rig).await.unwrap();
    assert!(wait_up(&rig, Duration::from_secs(5)).await, "rig never saw the robot: {:?}", rig.health());
    assert!(wait_up(&robot, Duration::from_secs(5)).await, "robot never saw the rig: {:?}", robot.health());

    let pose =
        Isometry3::from_parts(Translation3::new(1.0, 2.0, 0.3), UnitQuaternion::from_euler_angles(0.0, 0.0, 0.7));
    let sent_detections = detections(1);
    let tile = tiles(1).remove(0);
    let all_three = |g: &[Received]| {
        count(g, |r| matches!(r.msg, LinkMessage::RobotPose { .. })) > 0
            && count(g, |r| matches!(r.msg, LinkMessage::Detections { .. })) > 0
            && count(g, |r| matches!(&r.msg, LinkMessage::MapTile { bytes } if *bytes == tile)) > 0
    };
    // Poses and detections are droppable, and "up" comes from heartbeats, which can arrive before
    // the rig's subscriptions reach the robot: a round that misses one is sent again, five at most.
    let mut got = Vec::new();
    for _round in 0..5 {
        let pose_msg = LinkMessage::RobotPose { stamp: Stamp::new(123, Clock::Ptp), world_t_lidar: pose };
        robot.publish(&pose_msg).await.unwrap();
        robot.publish(&sent_detections).await.unwrap();
        robot.publish(&LinkMessage::MapTile { bytes: tile.clone() }).await.unwrap();
        let seen = got.clone();
        got.extend(collect(&mut rig, Duration::from_secs(1), |g| all_three(&[seen.as_slice(), g].concat())).await);
        if all_three(&got) {
            break;
        }
    }
    let pose_back = got.iter().find_map(|r| match r.msg {
        LinkMessage::RobotPose { stamp, world_t_lidar } => Some((stamp, world_t_lidar)),
        _ => None,
    });
    let (stamp, back) = pose_back.expect("no pose");
    assert_eq!(stamp, Stamp::new(123, Clock::Ptp));
    assert!((back.translation.vector - pose.translation.vector).norm() < 1e-12);
    let det = got.iter().find(|r| matches!(r.msg, LinkMessage::Detections { .. })).expect("no detections");
    assert_eq!(det.msg, sent_detections);
    assert!(det.raw_latency_ns.is_some_and(|l| (0..1_000_000_000).contains(&l)), "{:?}", det.raw_latency_ns);
    assert!(got.iter().any(|r| matches!(&r.msg, LinkMessage::MapTile { bytes } if *bytes == tile)));

    // Clock probes ran both ways: on one host the offset is near zero, within its own bound.
    assert!(wait_for(Duration::from_secs(3), || rig.health().clock.is_some() && robot.health().clock.is_some()).await);
    for node in [&rig, &robot] {
        let c = node.health().clock.unwrap();
        assert!(c.offset_ns.unsigned_abs() <= c.uncertainty_ns + 1_000, "{c:?}");
        assert!(c.rtt_ns < 100_000_000, "{c:?}");
    }
    // Heartbeat latencies count once the offset is known (the next heartbeat, 20 ms on).
    assert!(wait_for(Duration::from_secs(1), || rig.health().heartbeat_latency.is_some_and(|l| l.count > 0)).await);
    let report = rig.health();
    assert_eq!(report.decode_errors, 0);
    assert!(report.detections_latency.is_some() || det.latency_ns.is_none());
    robot.close().await.unwrap();
    rig.close().await.unwrap();
}

/// The age of a detection is measured on the robot's host clock (last packet to arrival), never
/// from the scan's LiDAR stamp, whose clock (PTP or the LiDAR's own) no host clock matches.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn detections_age_is_measured_on_host_clocks() {
    let (robot, port) = open_listening(robot_cfg, Role::Robot).await;
    let mut rig = LinkNode::open(&rig_cfg(port), Role::Rig).await.unwrap();
    assert!(wait_up(&rig, Duration::from_secs(5)).await, "{:?}", rig.health());
    assert!(wait_for(Duration::from_secs(3), || rig.health().clock.is_some()).await, "no clock offset");
    // Detections are droppable: send one every 50 ms until one has been aged, 5 s at most.
    let mut aged = false;
    for seq in 0..100 {
        robot.publish(&detections(seq)).await.unwrap();
        tokio::time::sleep(Duration::from_millis(50)).await;
        while rig.try_recv().is_some() {}
        aged = rig.health().detections_age.is_some_and(|a| a.count > 0);
        if aged {
            break;
        }
    }
    assert!(aged, "no detection aged: {:?}", rig.health());
    let age = rig.health().detections_age.unwrap();
    // 25 ms before sending, plus loopback transport and the offset's error.
    assert!((20_000_000..1_000_000_000).contains(&age.p50_ns), "{age:?}");
    robot.close().await.unwrap();
    rig.close().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_late_rig_gets_the_whole_map() {
    let (robot, port) = open_listening(robot_cfg, Role::Robot).await;
    let sent = tiles(1);
    assert_eq!(sent.len(), 3);
    for t in &sent {
        robot.publish(&LinkMessage::MapTile { bytes: t.clone() }).await.unwrap();
    }
    // A newer version of the first tile replaces the old one in what the robot serves.
    let v2 = tiles(2).remove(0);
    robot.publish(&LinkMessage::MapTile { bytes: v2.clone() }).await.unwrap();
    assert_eq!(robot.health().map_tiles, 3);

    let mut rig = LinkNode::open(&rig_cfg(port), Role::Rig).await.unwrap();
    let got = collect(&mut rig, Duration::from_secs(5), |g| count(g, |r| r.fetched) >= 3).await;
    let mut map = TileMap::default();
    for r in &got {
        if let LinkMessage::MapTile { bytes } = &r.msg {
            assert!(r.fetched, "a tile published before the rig joined came as a publication");
            map.apply(bytes).unwrap();
        }
    }
    assert_eq!(map.tile_count(), 3);
    assert!(got.iter().any(|r| matches!(&r.msg, LinkMessage::MapTile { bytes } if *bytes == v2)));
    let report = rig.health();
    assert!(report.map_fetches >= 1 && report.map_tiles_fetched >= 3, "{report:?}");
    assert_eq!(report.map_tiles, 3);
    rig.close().await.unwrap();
    robot.close().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn wifi_loss_goes_stale_then_lost_and_resumes_with_the_map() {
    let (robot, port) = open_listening(robot_cfg, Role::Robot).await;
    let mut rig = LinkNode::open(&rig_cfg(port), Role::Rig).await.unwrap();
    assert!(wait_up(&rig, Duration::from_secs(5)).await);
    let before = tiles(1);
    for t in &before[..2] {
        robot.publish(&LinkMessage::MapTile { bytes: t.clone() }).await.unwrap();
    }
    let got =
        collect(&mut rig, Duration::from_secs(5), |g| count(g, |r| matches!(r.msg, LinkMessage::MapTile { .. })) >= 2)
            .await;
    assert!(count(&got, |r| matches!(r.msg, LinkMessage::MapTile { .. })) >= 2);

    // The robot goes away (its session closes: the WiFi drops for the rig).
    robot.close().await.unwrap();
    let mut seen = Vec::new();
    let lost = wait_for(Duration::from_secs(5), || {
        let s = rig.health().state;
        if seen.last() != Some(&s) {
            seen.push(s);
        }
        s == LinkState::Lost
    })
    .await;
    assert!(lost, "states seen: {seen:?}");
    assert_eq!(seen, vec![LinkState::Up, LinkState::Stale, LinkState::Lost]);
    while rig.try_recv().is_some() {}

    // It comes back on the same port with one more tile; the rig resumes and fetches the map.
    let robot = LinkNode::open(&robot_cfg(port), Role::Robot).await.unwrap();
    for t in &before {
        robot.publish(&LinkMessage::MapTile { bytes: t.clone() }).await.unwrap();
    }
    assert!(wait_up(&rig, Duration::from_secs(10)).await, "no resumption: {:?}", rig.health());
    let got = collect(&mut rig, Duration::from_secs(5), |g| count(g, |r| r.fetched) >= 3).await;
    assert!(count(&got, |r| r.fetched) >= 3, "fetched {} tiles", count(&got, |r| r.fetched));
    let report = rig.health();
    assert_eq!((report.stalls, report.drops, report.resumptions), (1, 1, 1), "{report:?}");
    assert!(report.map_fetches >= 2, "{report:?}");
    assert_eq!(report.map_tiles, 3);
    rig.close().await.unwrap();
    robot.close().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn dropping_a_node_without_close_ends_its_session() {
    let (robot, port) = open_listening(robot_cfg, Role::Robot).await;
    let rig = LinkNode::open(&rig_cfg(port), Role::Rig).await.unwrap();
    assert!(wait_up(&rig, Duration::from_secs(5)).await);
    drop(robot);
    // Its heartbeat task is gone and its listener closed: the rig loses it, and the port is free.
    assert!(wait_for(Duration::from_secs(5), || rig.health().state == LinkState::Lost).await, "{:?}", rig.health());
    assert!(wait_for(Duration::from_secs(5), || std::net::TcpListener::bind(("127.0.0.1", port)).is_ok()).await);
    rig.close().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_rig_started_first_waits_for_the_robot() {
    let port = free_port();
    let started = std::time::Instant::now();
    let rig = LinkNode::open(&rig_cfg(port), Role::Rig).await.unwrap();
    // Opening does not wait for the robot: the connector retries in the background.
    assert!(started.elapsed() < Duration::from_secs(2), "open took {:?}", started.elapsed());
    tokio::time::sleep(Duration::from_millis(300)).await;
    assert_eq!(rig.health().state, LinkState::Lost);
    let robot = LinkNode::open(&robot_cfg(port), Role::Robot).await.unwrap();
    assert!(wait_up(&rig, Duration::from_secs(5)).await, "{:?}", rig.health());
    assert_eq!(rig.health().resumptions, 0);
    robot.close().await.unwrap();
    rig.close().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn damaged_messages_on_the_wire_are_counted_not_delivered() {
    let (mut rig, port) =
        open_listening(|port| common::fast(vec![format!("tcp/127.0.0.1:{port}")], vec![]), Role::Rig).await;
    // A plain zenoh peer (no link node) puts garbage and a damaged frame on the robot's keys.
    let mut z = zenoh::Config::default();
    z.insert_json5("listen/endpoints", "[]").unwrap();
    z.insert_json5("connect/endpoints", &format!("[\"tcp/127.0.0.1:{port}\"]")).unwrap();
    z.insert_json5("scouting/multicast/enabled", "false").unwrap();
    z.insert_json5("scouting/gossip/enabled", "false").unwrap();
    let raw = zenoh::open(z).await.unwrap();
    let mut frame = starc_pipeline::link::encode(&detections(1)).unwrap();
    frame[100] ^= 0x40;
    let sent = wait_for(Duration::from_secs(5), || {
        // Keep sending until the rig has seen both (its subscription may take a moment to reach us).
        let _ = zenoh::Wait::wait(raw.put("starc/robot/detections", b"not a link frame".to_vec()));
        let _ = zenoh::Wait::wait(raw.put("starc/robot/pose", frame.clone()));
        rig.health().decode_errors >= 2
    })
    .await;
    assert!(sent, "{:?}", rig.health());
    assert!(rig.try_recv().is_none(), "a damaged message was delivered");
    assert_eq!(rig.health().received, 0);
    raw.close().await.unwrap();
    rig.close().await.unwrap();
}
