//! The live Foxglove view (view/src/foxglove.rs) against a real client: PyPI `websockets`
//! speaking `foxglove.websocket.v1` (tests/peers/foxglove_client.py), which decodes what it
//! receives with `mcap_ros2`'s decoder built from the schema the server advertised and with
//! `rosbags`' ROS 2 Humble types. Also: a client without the subprotocol is refused, and a
//! client that stops reading loses messages instead of holding up `publish`.
//!
//! The peer is required: a missing one fails these tests (`.venv/bin/pip install -r
//! tests/peers/requirements.txt`, as .ci/run does).

#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;
use common::{peer_python, root};
use serde_json::Value;
use starc_pipeline::cloud::{CloudPoint, PointCloud};
use starc_pipeline::record::msgs::{Header, Marker, MarkerArray, Pose, Time, Vector3};
use starc_pipeline::record::writer::cloud_to_msg;
use starc_pipeline::record::{msgs::RosMessage, Topic};
use starc_view::{ChannelSpec, FoxgloveServer};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

const T0_NS: u64 = 1_763_719_200_000_000_000;

/// The workspace root, where .venv and tests/peers live.
/// Starts the peer; it is killed if the test ends first.
struct Peer(Option<std::process::Child>);

impl Peer {
    fn start(args: &[&str]) -> Self {
        let child = Command::new(peer_python())
            .arg(root().join("tests/peers/foxglove_client.py"))
            .args(args)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("starting the peer");
        Self(Some(child))
    }

    fn finished(&mut self) -> bool {
        self.0.as_mut().map(|c| c.try_wait().unwrap().is_some()).unwrap_or(true)
    }

    fn output(mut self) -> Output {
        self.0.take().unwrap().wait_with_output().unwrap()
    }
}

impl Drop for Peer {
    fn drop(&mut self) {
        if let Some(mut c) = self.0.take() {
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}

fn json_out(out: &Output) -> Value {
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "peer failed: {}\n{stdout}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_str(stdout.lines().last().unwrap_or_default()).unwrap_or_else(|e| panic!("{stdout:?}: {e}"))
}

fn cloud(k: u64, n: usize) -> Vec<u8> {
    let points = (0..n)
        .map(|i| CloudPoint {
            x_m: 1.0 + k as f32,
            y_m: -2.0 + i as f32 * 0.25,
            z_m: 0.5,
            intensity: 7.0,
            offset_ns: i as u32 * 1000,
            line: (i % 6) as u8,
            tag: 0,
        })
        .collect();
    let cloud = PointCloud::new(None, points);
    let header = Header { stamp: Time::from_ns(T0_NS + k).unwrap(), frame_id: "lidar".into() };
    cloud_to_msg(&cloud, header).to_cdr()
}

fn markers(k: u64) -> MarkerArray {
    let header = Header { stamp: Time::from_ns(T0_NS + k).unwrap(), frame_id: "map".into() };
    MarkerArray {
        markers: vec![
            Marker { header: header.clone(), action: Marker::DELETE_ALL, ..Marker::default() },
            Marker {
                header,
                ns: "people".into(),
                id: 3,
                kind: Marker::CUBE,
                action: Marker::ADD,
                pose: Pose { position: Vector3::new(4.5, 1.0, 0.9), ..Pose::default() },
                scale: Vector3::new(0.5, 0.4, 1.8),
                text: "person 3".into(),
                ..Marker::default()
            },
        ],
    }
}

async fn server() -> (FoxgloveServer, tokio::sync::watch::Sender<bool>) {
    let (stop, shutdown) = tokio::sync::watch::channel(false);
    let channels = [Topic::Points, Topic::DetectionMarkers, Topic::ArImage].map(ChannelSpec::recorded);
    let (server, _task) = FoxgloveServer::start("127.0.0.1:0".parse().unwrap(), &channels, shutdown).await.unwrap();
    (server, stop)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_foxglove_client_subscribes_and_decodes_our_ros2_messages() {
    let (server, _stop) = server().await;
    let url = format!("ws://{}", server.local_addr());
    let mut peer = Peer::start(&["receive", &url, "2", "/robot/points", "/detections/markers"]);
    // Publish until the peer has what it wants (it subscribes at its own pace).
    let deadline = Instant::now() + Duration::from_secs(20);
    let mut k = 0u64;
    while !peer.finished() {
        assert!(Instant::now() < deadline, "the peer did not finish");
        server.publish(Topic::Points.name(), T0_NS + k, &cloud(k, 50)).unwrap();
        server.publish_msg(Topic::DetectionMarkers.name(), T0_NS + k, &markers(k)).unwrap();
        k += 1;
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    let v = json_out(&peer.output());

    assert_eq!(v["subprotocol"], "foxglove.websocket.v1");
    assert_eq!(v["server_info"]["op"], "serverInfo");
    assert_eq!(v["server_info"]["name"], "starc");
    let channels = v["channels"].as_array().unwrap();
    assert_eq!(channels.len(), 3);
    for c in channels {
        assert_eq!(c["encoding"], "cdr");
        assert_eq!(c["schemaEncoding"], "ros2msg");
    }
    assert_eq!(channels[0]["topic"], "/robot/points");
    assert_eq!(channels[0]["schemaName"], "sensor_msgs/msg/PointCloud2");
    // The malformed request got an error status; the subscribe got none.
    let statuses = v["statuses"].as_array().unwrap();
    assert_eq!(statuses.len(), 1, "{statuses:?}");
    assert_eq!(statuses[0]["level"], 2);

    let points = v["received"]["/robot/points"].as_array().unwrap();
    assert_eq!(points.len(), 2);
    let mut last_k = None;
    for m in points {
        assert_eq!(m["op"], 1);
        assert_eq!(m["humble_agrees"], true, "{m}");
        let k = m["log_ns"].as_u64().unwrap() - T0_NS;
        assert!(last_k.is_none_or(|l| k > l), "messages in order");
        last_k = Some(k);
        let msg = &m["msg"];
        assert_eq!(msg["frame_id"], "lidar");
        assert_eq!(msg["width"], 50);
        assert_eq!(msg["point_step"], 24);
        assert_eq!(msg["fields"], serde_json::json!(["x", "y", "z", "intensity", "t", "line", "tag"]));
        assert_eq!(msg["first_xyz"], serde_json::json!([1.0 + k as f64, -2.0, 0.5]));
        assert_eq!(msg["stamp"][1].as_u64().unwrap() % 1_000_000_000, (T0_NS + k) % 1_000_000_000);
    }
    let marks = v["received"]["/detections/markers"].as_array().unwrap();
    assert_eq!(marks.len(), 2);
    for m in marks {
        assert_eq!(m["humble_agrees"], true, "{m}");
        let list = m["msg"]["markers"].as_array().unwrap();
        assert_eq!(list.len(), 2);
        assert_eq!(list[0]["action"], 3);
        assert_eq!(list[1]["ns"], "people");
        assert_eq!(list[1]["id"], 3);
        assert_eq!(list[1]["type"], 1);
        assert_eq!(list[1]["x"], 4.5);
        assert_eq!(list[1]["text"], "person 3");
    }
    // The client has gone; its slot goes with it.
    let deadline = Instant::now() + Duration::from_secs(5);
    while server.clients() > 0 {
        assert!(Instant::now() < deadline, "the client's slot was not removed");
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_client_without_the_subprotocol_is_refused() {
    let (server, _stop) = server().await;
    let url = format!("ws://{}", server.local_addr());
    let out = tokio::task::spawn_blocking(move || Peer::start(&["noproto", &url]).output()).await.unwrap();
    assert_eq!(json_out(&out)["status"], 400);
    // Unknown topics and unknown types are errors, not silent no-ops.
    assert!(server.publish("/nope", 0, &[]).is_err());
    let (_s, shutdown) = tokio::sync::watch::channel(false);
    let bad = [ChannelSpec::new("/x", "sensor_msgs/msg/Nope")];
    assert!(FoxgloveServer::start("127.0.0.1:0".parse().unwrap(), &bad, shutdown).await.is_err());
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_client_that_stops_reading_loses_messages_and_blocks_nothing() {
    let (server, _stop) = server().await;
    let url = format!("ws://{}", server.local_addr());
    let mut peer = Peer::start(&["stall", &url, "6", "/robot/points"]);
    // 1 MB clouds: the socket buffers and the client's queue fill within a few dozen.
    let big = cloud(0, 44_000);
    let deadline = Instant::now() + Duration::from_secs(5);
    let mut slowest = Duration::ZERO;
    let mut queued = 0;
    while server.dropped() == 0 {
        assert!(Instant::now() < deadline, "nothing was dropped (queued {queued})");
        assert!(!peer.finished(), "the stalling peer ended early");
        let t0 = Instant::now();
        queued += server.publish(Topic::Points.name(), T0_NS, &big).unwrap().queued;
        slowest = slowest.max(t0.elapsed());
        tokio::time::sleep(Duration::from_millis(2)).await;
    }
    assert!(queued > 0, "the stalling client was never subscribed");
    // Generous bound: a publish is a copy per client and a queue push, never a network wait.
    assert!(slowest < Duration::from_millis(500), "a publish took {slowest:?}");
}
