//! A real zenoh peer: the eclipse-zenoh Python package (tests/peers/requirements.txt, installed
//! into .venv by .ci/run) receives our robot's heartbeat bytes on `starc/robot/heartbeat`, and
//! sends rig heartbeats it builds from docs/link.md's table alone, which bring our robot Up.
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use std::process::{Command, Stdio};
use std::time::Duration;

use common::{open_listening, python, robot_cfg, root, wait_up, Reap};
use starc_link::{LinkMessage, Role};
use starc_pipeline::link::decode;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn python_zenoh_peer_reads_our_heartbeats_and_sends_its_own() {
    let Some(python) = python() else { return };
    let (robot, port) = open_listening(robot_cfg, Role::Robot).await;
    let child = Command::new(python)
        .arg(root().join("tests/peers/zenoh_peer.py"))
        .args([port.to_string(), "10".into()])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut child = Reap(child);
    // The Python peer's heartbeats (built from the documented layout) bring the robot's link Up.
    assert!(wait_up(&robot, Duration::from_secs(8)).await, "{:?}", robot.health());
    assert_eq!(robot.health().decode_errors, 0);

    let out = tokio::task::spawn_blocking(move || {
        let status = child.0.wait().unwrap();
        let mut stdout = String::new();
        let mut stderr = String::new();
        use std::io::Read;
        child.0.stdout.take().unwrap().read_to_string(&mut stdout).unwrap();
        child.0.stderr.take().unwrap().read_to_string(&mut stderr).unwrap();
        (status, stdout, stderr)
    })
    .await
    .unwrap();
    assert!(out.0.success(), "python peer: {}\n{}", out.1, out.2);
    let line = out.1.lines().next().unwrap();
    let key = line.split("\"key\": \"").nth(1).and_then(|s| s.split('"').next()).unwrap();
    let hex = line.split("\"hex\": \"").nth(1).and_then(|s| s.split('"').next()).unwrap();
    assert_eq!(key, "starc/robot/heartbeat");
    let bytes: Vec<u8> = (0..hex.len()).step_by(2).map(|i| u8::from_str_radix(&hex[i..i + 2], 16).unwrap()).collect();
    match decode(&bytes).unwrap() {
        LinkMessage::Heartbeat { role, .. } => assert_eq!(role, Role::Robot),
        other => panic!("{other:?}"),
    }
    robot.close().await.unwrap();
}
