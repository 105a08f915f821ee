//! The shipped node configs' link: mutual TLS end to end (config/robot.toml and config/fpv.toml
//! moved onto loopback, with the files `starc link certs` writes), and plain TCP beyond loopback
//! refused with the key and the file named.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use starc_link::certs::make_certs;
use starc_link::{host_now_ns, LinkMessage, LinkNode, LinkState, Role};
use starc_node::config::{FpvNodeConfig, RobotNodeConfig};
use starc_time::{Clock, Stamp};

fn shipped(name: &str) -> String {
    std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("../config").join(name)).unwrap()
}

/// `name` from config/, with `from` replaced by `to`, written into `dir`.
fn rewrite(dir: &Path, name: &str, from: &str, to: &str) -> PathBuf {
    let text = shipped(name);
    assert!(text.contains(from), "{name} has no {from:?}");
    let path = dir.join(name);
    std::fs::write(&path, text.replace(from, to)).unwrap();
    path
}

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port()
}

async fn wait_up(node: &LinkNode, limit: Duration) -> bool {
    let start = Instant::now();
    while start.elapsed() < limit {
        if node.health().state == LinkState::Up {
            return true;
        }
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    false
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_shipped_configs_link_over_mutual_tls() {
    let dir = tempfile::tempdir().unwrap();
    // Where the shipped configs look: certs/ beside them. The robot's certificate names the
    // address the rig dials (here loopback instead of 192.168.50.2).
    make_certs(&dir.path().join("certs"), &["127.0.0.1".into()], false).unwrap();
    let port = free_port();
    let ep = format!("127.0.0.1:{port}");
    let robot_path = rewrite(dir.path(), "robot.toml", "192.168.50.2:7447", &ep);
    let fpv_path = rewrite(dir.path(), "fpv.toml", "192.168.50.2:7447", &ep);
    let robot_cfg = RobotNodeConfig::from_file(&robot_path).unwrap();
    let fpv_cfg = FpvNodeConfig::from_file(&fpv_path).unwrap();
    assert_eq!(robot_cfg.link.listen, vec![format!("tls/{ep}")]);
    assert_eq!(fpv_cfg.link.connect, vec![format!("tls/{ep}")]);
    assert_eq!(fpv_cfg.link.tls.as_ref().unwrap().key.as_deref(), Some(dir.path().join("certs/rig.key").as_path()));

    let robot = LinkNode::open(&robot_cfg.link, Role::Robot).await.unwrap();
    let mut rig = LinkNode::open(&fpv_cfg.link, Role::Rig).await.unwrap();
    assert!(wait_up(&rig, Duration::from_secs(10)).await, "{:?}", rig.health());
    assert!(wait_up(&robot, Duration::from_secs(2)).await, "{:?}", robot.health());
    // Detections are droppable and may be sent before the rig's subscription reached the robot:
    // a round that brings nothing is sent again, five rounds at most.
    let now = host_now_ns();
    let msg = LinkMessage::Detections {
        seq: 7,
        stamp: Stamp::new(now, Clock::Ptp),
        scan_last_packet_host_ns: now,
        sent_host_ns: now,
        people: vec![],
    };
    let mut got = None;
    for _round in 0..5 {
        robot.publish(&msg).await.unwrap();
        if let Ok(Some(r)) = tokio::time::timeout(Duration::from_secs(1), rig.recv()).await {
            got = Some(r.msg);
            break;
        }
    }
    assert_eq!(got, Some(msg));
    let refused = rig.health().refused;
    assert_eq!((refused.kind, refused.key, refused.tiles), (0, 0, 0));
    rig.close().await.unwrap();
    robot.close().await.unwrap();
}

#[test]
fn plain_tcp_beyond_loopback_is_refused_naming_the_key_and_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let robot = rewrite(dir.path(), "robot.toml", "tls/192.168.50.2:7447", "tcp/192.168.50.2:7447");
    let e = RobotNodeConfig::from_file(&robot).unwrap_err().to_string();
    for part in [robot.display().to_string().as_str(), "[link]", "listen", "tcp/192.168.50.2:7447", "insecure = true"] {
        assert!(e.contains(part), "{part:?} not in: {e}");
    }
    let fpv = rewrite(dir.path(), "fpv.toml", "tls/192.168.50.2:7447", "tcp/192.168.50.2:7447");
    let e = FpvNodeConfig::from_file(&fpv).unwrap_err().to_string();
    for part in [fpv.display().to_string().as_str(), "connect", "insecure = true"] {
        assert!(e.contains(part), "{part:?} not in: {e}");
    }
    // Said out loud, it is allowed.
    let text = std::fs::read_to_string(&robot).unwrap().replace("[link]\n", "[link]\ninsecure = true\n");
    std::fs::write(&robot, text).unwrap();
    assert!(RobotNodeConfig::from_file(&robot).unwrap().link.insecure);
    // A TLS listener beyond loopback without mutual TLS lets anyone in: refused as well.
    let robot = rewrite(dir.path(), "robot.toml", "mutual = true", "mutual = false");
    let e = RobotNodeConfig::from_file(&robot).unwrap_err().to_string();
    assert!(e.contains("tls.mutual") && e.contains("robot.toml"), "{e}");
    // Loopback plain TCP stays allowed (`starc sim`, tests, config/loopback).
    let robot = rewrite(dir.path(), "robot.toml", "tls/192.168.50.2:7447", "tcp/127.0.0.1:7447");
    RobotNodeConfig::from_file(&robot).unwrap();
}
