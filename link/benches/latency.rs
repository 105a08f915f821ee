//! Link figures over tcp/127.0.0.1 (one host, so send and receive stamps share a clock):
//! detections of 2,000 points at 20 Hz, robot -> rig latency p50/p99/max; then how long a rig
//! joining late takes to fetch a 1.6 MB map (100 tiles). Prints figures; asserts nothing.
//!
//! Run: `cargo bench -p starc-link --bench latency` (or `--profile dev` to skip a release build).
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::time::{Duration, Instant};

use nalgebra::Vector3;
use starc_link::{host_now_ns, LinkConfig, LinkMessage, LinkNode, LinkPerson, LinkState, Role};
use starc_pipeline::align::{encode_tiles, Vec3};
use starc_pipeline::ar::OrientedBox;
use starc_pipeline::detect::PersonPose;
use starc_pipeline::link::encode;

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port()
}

fn cfgs(port: u16) -> (LinkConfig, LinkConfig) {
    let robot = LinkConfig { listen: vec![format!("tcp/127.0.0.1:{port}")], ..LinkConfig::default() };
    let rig = LinkConfig { connect: vec![format!("tcp/127.0.0.1:{port}")], ..LinkConfig::default() };
    (robot, rig)
}

fn detections(seq: u32) -> LinkMessage {
    let now = host_now_ns();
    LinkMessage::Detections {
        seq,
        stamp: starc_time::Stamp::new(now, starc_time::Clock::Ptp),
        scan_last_packet_host_ns: now,
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

fn pct(v: &mut [i64], q: f64) -> f64 {
    v.sort_unstable();
    v[((v.len() - 1) as f64 * q).round() as usize] as f64 / 1e6
}

async fn wait_up(node: &LinkNode) {
    let start = Instant::now();
    while node.health().state != LinkState::Up && start.elapsed() < Duration::from_secs(10) {
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
    assert_eq!(node.health().state, LinkState::Up);
}

#[tokio::main(flavor = "multi_thread", worker_threads = 2)]
async fn main() {
    let port = free_port();
    let (robot_cfg, rig_cfg) = cfgs(port);
    let robot = LinkNode::open(&robot_cfg, Role::Robot).await.unwrap();
    let mut rig = LinkNode::open(&rig_cfg, Role::Rig).await.unwrap();
    wait_up(&rig).await;
    wait_up(&robot).await;

    let n = 400u32;
    let bytes = encode(&detections(0)).unwrap().len();
    let sender = tokio::spawn(async move {
        let mut tick = tokio::time::interval(Duration::from_millis(50));
        for seq in 0..n {
            tick.tick().await;
            robot.publish(&detections(seq)).await.unwrap();
        }
        robot
    });
    let mut lat = Vec::new();
    let deadline = tokio::time::Instant::now() + Duration::from_secs(60);
    while lat.len() < n as usize {
        match tokio::time::timeout_at(deadline, rig.recv()).await {
            Ok(Some(r)) => {
                if let (LinkMessage::Detections { .. }, Some(l)) = (&r.msg, r.raw_latency_ns) {
                    lat.push(l);
                }
            }
            _ => break,
        }
    }
    let robot = sender.await.unwrap();
    let got = lat.len();
    println!(
        "detections ({bytes} B, 2000 points) at 20 Hz over tcp/127.0.0.1: {got}/{n} received, latency p50 {:.3} ms, p99 {:.3} ms, max {:.3} ms",
        pct(&mut lat, 0.5),
        pct(&mut lat, 0.99),
        pct(&mut lat, 1.0)
    );
    let h = rig.health();
    if let Some(c) = h.clock {
        println!(
            "clock offset estimate (same host, truth 0): {:.3} ms +- {:.3} ms, rtt {:.3} ms over {} probes",
            c.offset_ns as f64 / 1e6,
            c.uncertainty_ns as f64 / 1e6,
            c.rtt_ns as f64 / 1e6,
            c.samples
        );
    }
    if let Some(l) = h.heartbeat_latency {
        println!(
            "heartbeat latency p50 {:.3} ms, p99 {:.3} ms ({} samples)",
            l.p50_ns as f64 / 1e6,
            l.p99_ns as f64 / 1e6,
            l.count
        );
    }
    rig.close().await.unwrap();

    // A 40 m x 40 m floor at 0.1 m: 160,000 points in 100 tiles of 4 m.
    let mut pts = Vec::new();
    for i in 0..400 {
        for j in 0..400 {
            pts.push(Vec3::new(0.1 * f64::from(i) + 0.05, 0.1 * f64::from(j) + 0.05, 0.0));
        }
    }
    let nrm = vec![Some(Vec3::new(0.0, 0.0, 1.0)); pts.len()];
    let tiles = encode_tiles(&pts, &nrm, 4.0, 0.01, 1).unwrap();
    let total: usize = tiles.iter().map(|(_, b)| b.len()).sum();
    for (_, b) in &tiles {
        robot.publish(&LinkMessage::MapTile { bytes: b.clone() }).await.unwrap();
    }
    let start = Instant::now();
    let mut rig = LinkNode::open(&rig_cfg, Role::Rig).await.unwrap();
    let mut fetched = 0;
    let deadline = tokio::time::Instant::now() + Duration::from_secs(30);
    while fetched < tiles.len() {
        match tokio::time::timeout_at(deadline, rig.recv()).await {
            Ok(Some(r)) if r.fetched => fetched += 1,
            Ok(Some(_)) => {}
            _ => break,
        }
    }
    println!(
        "late rig: open to {fetched}/{} tiles ({:.1} MB) in {:.0} ms",
        tiles.len(),
        total as f64 / 1e6,
        start.elapsed().as_secs_f64() * 1e3
    );
    rig.close().await.unwrap();
    robot.close().await.unwrap();
}
