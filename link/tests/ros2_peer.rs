//! The ROS 2 bridge against a ROS 2 system's side of the wire: the eclipse-zenoh Python package
//! plays the rmw_zenoh router (tests/peers/ros2_peer.py), sees the node's and each publisher's
//! liveliness token, takes every sample on its exact rmw_zenoh key with rmw_zenoh's attachment,
//! decodes each payload with rosbags, and publishes /cmd_vel back, which the bridge receives.
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use std::io::{BufRead, BufReader, Read};
use std::process::{Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use common::{free_port, python, root, Reap};
use starc_link::ros2::{Qos, Ros2Bridge, Ros2Config, TopicId};
use starc_pipeline::cloud::{CloudPoint, PointCloud};
use starc_pipeline::detect::PersonPose;
use starc_pipeline::record::msgs::{RosMessage, Twist};
use starc_pipeline::record::{Frames, MessageBuilder, PersonBox};
use starc_time::{Clock, Stamp};

const T0: u64 = 1_700_000_000_000_000_000;

fn cloud(n: usize) -> PointCloud {
    let points = (0..n)
        .map(|i| CloudPoint {
            x_m: i as f32 * 0.1,
            y_m: 1.0,
            z_m: 0.5,
            intensity: 7.0,
            offset_ns: i as u32,
            line: 1,
            tag: 0,
        })
        .collect();
    PointCloud::new(Some(Stamp::new(T0, Clock::Ptp)), points)
}

/// Puts `rounds` of every robot message the bridge carries, 50 ms apart.
fn publish_all(bridge: &mut Ros2Bridge, ids: &[(TopicId, Vec<u8>)], rounds: usize) {
    for _ in 0..rounds {
        for (id, payload) in ids {
            bridge.put(*id, payload.clone(), 1).unwrap();
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

fn payloads(bridge: &mut Ros2Bridge) -> Vec<(TopicId, Vec<u8>)> {
    use starc_pipeline::record::msgs::{CompressedImage, Imu, MarkerArray, Odometry, PointCloud2, TfMessage};
    use starc_pipeline::record::vision::Detection3DArray;
    let b = MessageBuilder::new(Clock::Ptp, Frames::default());
    let t = Stamp::new(T0, Clock::Ptp);
    let pose = starc_pipeline::record::msgs::Pose {
        position: starc_pipeline::record::msgs::Vector3::new(1.5, 0.0, 0.0),
        ..Default::default()
    };
    let people = [PersonBox {
        id: 4,
        center_m: [2.0, 1.0, 0.9],
        size_m: [0.5, 0.4, 1.8],
        yaw_rad: 0.3,
        score: 0.9,
        pose: PersonPose::Lying,
    }];
    let mut adv = |topic: &str, ty: &str| bridge.advertise(topic, ty, Qos::DEFAULT).unwrap();
    vec![
        (adv("robot/points", PointCloud2::TYPE_NAME), b.cloud(&cloud(100)).unwrap().1.to_cdr()),
        (adv("robot/imu", Imu::TYPE_NAME), b.imu(t, [0.0, 0.0, 0.1], [0.0, 0.0, 9.81]).unwrap().to_cdr()),
        (
            adv("robot/odom", Odometry::TYPE_NAME),
            b.odometry(t, "odom", "base_link", pose, [[0.0; 3]; 2]).unwrap().to_cdr(),
        ),
        (adv("tf", TfMessage::TYPE_NAME), b.tf(t, &[("odom", "base_link", pose)]).unwrap().to_cdr()),
        (adv("detections/markers", MarkerArray::TYPE_NAME), b.markers(t, &people).unwrap().to_cdr()),
        (adv("detections/people", Detection3DArray::TYPE_NAME), b.people(t, &people).unwrap().to_cdr()),
        (
            adv("fpv/ar_image/compressed", CompressedImage::TYPE_NAME),
            b.png_image(t, &[137, 80, 78, 71]).unwrap().to_cdr(),
        ),
    ]
}

#[test]
fn a_python_ros2_router_sees_every_topic_and_sends_cmd_vel() {
    let Some(python) = python() else { return };
    let port = free_port();
    let cfg = Ros2Config { enabled: true, connect: vec![format!("tcp/127.0.0.1:{port}")], ..Ros2Config::default() };
    let cmd_vel_key = starc_link::ros2::names::topic_key(
        0,
        "/cmd_vel",
        Twist::TYPE_NAME,
        &starc_link::ros2::type_hash::rihs01(Twist::TYPE_NAME).unwrap(),
    );
    let child = Command::new(python)
        .arg(root().join("tests/peers/ros2_peer.py"))
        .args([port.to_string(), "6".into(), "plain".into(), String::new(), cmd_vel_key.clone()])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut child = Reap(child);
    let mut stdout = BufReader::new(child.0.stdout.take().unwrap());
    let mut line = String::new();
    stdout.read_line(&mut line).unwrap();
    assert_eq!(line.trim(), "ready");

    let mut bridge = Ros2Bridge::open(&cfg, "starc_robot").unwrap();
    let twists = Arc::new(Mutex::new(Vec::new()));
    let got = twists.clone();
    bridge
        .subscribe("cmd_vel", Twist::TYPE_NAME, Qos::DEFAULT, move |payload| {
            if let Ok(t) = Twist::from_cdr(&payload) {
                got.lock().unwrap().push(t);
            }
        })
        .unwrap();
    let ids = payloads(&mut bridge);
    std::thread::sleep(Duration::from_millis(500));
    publish_all(&mut bridge, &ids, 20);
    let zid = bridge.zid();
    std::thread::sleep(Duration::from_millis(1500));
    let received = twists.lock().unwrap().clone();
    bridge.close().unwrap();

    let mut out = String::new();
    stdout.read_to_string(&mut out).unwrap();
    let mut err = String::new();
    child.0.stderr.take().unwrap().read_to_string(&mut err).unwrap();
    assert!(child.0.wait().unwrap().success(), "{out}\n{err}");
    let report: serde_json::Value = serde_json::from_str(out.lines().last().unwrap()).unwrap();
    assert_eq!(report["errors"], serde_json::json!([]), "{report}");

    // Liveliness: the node, and each publisher with its topic, type, hash and QoS.
    let of_kind = |kind: &str| -> Vec<&str> {
        let all = report["tokens"].as_array().unwrap().iter();
        all.filter(|t| t[0].as_str().unwrap().contains(kind)).map(|t| t[1].as_str().unwrap()).collect()
    };
    let tokens = of_kind("PUT");
    // Closing withdraws every token: a ROS 2 graph forgets the node.
    let mut withdrawn = of_kind("DELETE");
    withdrawn.sort_unstable();
    let mut declared = tokens.clone();
    declared.sort_unstable();
    assert_eq!(withdrawn, declared);
    assert!(tokens.contains(&format!("@ros2_lv/0/{zid}/0/0/NN/%/%/starc_robot").as_str()), "{tokens:?}");
    let points_hash = starc_link::ros2::type_hash::rihs01("sensor_msgs/msg/PointCloud2").unwrap();
    assert!(points_hash.starts_with("RIHS01_9198cabf"));
    let points_token = format!(
        "@ros2_lv/0/{zid}/0/2/MP/%/%/starc_robot/%robot%points/sensor_msgs::msg::dds_::PointCloud2_/{points_hash}/::,10:,:,:,,"
    );
    assert!(tokens.contains(&points_token.as_str()), "{points_token} not in {tokens:?}");
    assert_eq!(tokens.iter().filter(|t| t.contains("/MP/")).count(), 7, "{tokens:?}");
    assert_eq!(tokens.iter().filter(|t| t.contains("/MS/%/%/starc_robot/%cmd_vel/")).count(), 1, "{tokens:?}");

    // Every message, on its exact key, with the attachment, decoded by rosbags.
    let samples = report["samples"].as_object().unwrap();
    let key = |topic: &str, ty: &str| {
        starc_link::ros2::names::topic_key(0, topic, ty, &starc_link::ros2::type_hash::rihs01(ty).unwrap())
    };
    let expect = [
        ("/robot/points", "sensor_msgs/msg/PointCloud2"),
        ("/robot/imu", "sensor_msgs/msg/Imu"),
        ("/robot/odom", "nav_msgs/msg/Odometry"),
        ("/tf", "tf2_msgs/msg/TFMessage"),
        ("/detections/markers", "visualization_msgs/msg/MarkerArray"),
        ("/detections/people", "vision_msgs/msg/Detection3DArray"),
        ("/fpv/ar_image/compressed", "sensor_msgs/msg/CompressedImage"),
    ];
    for (topic, ty) in expect {
        let k = key(topic, ty);
        let s = samples.get(&k).unwrap_or_else(|| panic!("nothing on {k}: {:?}", samples.keys()));
        assert_eq!(s["attachment_len"], 33, "{k}");
        // Every sample from the first one seen: the sequence numbers run on without a gap.
        let seqs: Vec<i64> = s["seqs"].as_array().unwrap().iter().map(|v| v.as_i64().unwrap()).collect();
        assert!(!seqs.is_empty(), "{k}");
        assert_eq!(seqs.last().unwrap() - seqs[0] + 1, seqs.len() as i64, "{k}: {seqs:?}");
        assert_eq!(*seqs.last().unwrap(), 20, "{k}: the last of 20 rounds");
    }
    let first = |topic, ty| samples[&key(topic, ty)]["first"].clone();
    assert_eq!(first("/robot/points", "sensor_msgs/msg/PointCloud2")["width"], 100);
    assert_eq!(first("/robot/imu", "sensor_msgs/msg/Imu")["acc_z"], 9.81);
    assert_eq!(first("/robot/odom", "nav_msgs/msg/Odometry")["child_frame_id"], "base_link");
    assert_eq!(first("/robot/odom", "nav_msgs/msg/Odometry")["stamp_ns"], T0);
    assert_eq!(first("/tf", "tf2_msgs/msg/TFMessage")["transforms"], serde_json::json!([["odom", "base_link"]]));
    assert_eq!(first("/detections/markers", "visualization_msgs/msg/MarkerArray")["markers"], 3);
    assert_eq!(
        first("/detections/people", "vision_msgs/msg/Detection3DArray")["detections"],
        serde_json::json!([["4", "person", "lying", 1.8]])
    );
    assert_eq!(first("/fpv/ar_image/compressed", "sensor_msgs/msg/CompressedImage")["format"], "png");

    // /cmd_vel from the peer, every one it sent, decoded.
    let sent = report["cmd_vel_sent"].as_u64().unwrap();
    assert_eq!(sent, 20, "{report}");
    assert_eq!(received.len() as u64, sent, "{received:?}");
    assert!((received[19].linear.x - 2.0).abs() < 1e-12 && (received[0].angular.z - 0.1).abs() < 1e-12);
}
