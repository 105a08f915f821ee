//! `starc sim lab --duration 12`: the see-through mission live. Mock Avias play the simulated
//! run back over their real protocol; the robot node and the rig node (each with its own live
//! driver) talk over zenoh on tcp/127.0.0.1; report.json (mode "live") holds the link's latency
//! and the rig is aligned; both nodes' MCAP recordings decode with mcap-ros2-support and rosbags;
//! `starc rerun` of the recordings reruns the pipeline, the same bytes every time.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn f64_at(v: &Value, key: &str) -> f64 {
    v.pointer(key).and_then(Value::as_f64).unwrap_or_else(|| panic!("report.json lacks {key}: {v}"))
}

fn topics(recording: &Path) -> Value {
    let python = root().join(".venv/bin/python");
    let out = Command::new(&python)
        .arg(root().join("tests/peers/mcap_check.py"))
        .arg("topics")
        .arg(recording)
        .output()
        .expect("the MCAP peers run from .venv (.venv/bin/pip install -r tests/peers/requirements.txt)");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_slice(&out.stdout).unwrap()
}

#[test]
fn the_live_mission_links_the_nodes_and_aligns_the_rig() {
    let dir = tempfile::tempdir().unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_starc"))
        // The first alignment at once (no confirmation over the next searches): the lab's people
        // are in the rig's view in its first 10 s, and this test is about what the link carries
        // to the overlay. The confirmation is the default, tested offline and in mission::rig.
        .args(["sim", "lab", "--duration", "12", "--confirm-first-s", "0", "--out"])
        .arg(dir.path())
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{stdout}\n{}", String::from_utf8_lossy(&out.stderr));
    println!("{stdout}");
    let mission = dir.path().join("mission");
    let report: Value = serde_json::from_str(&std::fs::read_to_string(mission.join("report.json")).unwrap()).unwrap();
    assert_eq!(report.pointer("/mode").and_then(Value::as_str), Some("live"));
    // The link carried the detections: a transport time was measured, well under a scan.
    let comm = f64_at(&report, "/latency_ms/comm_p50");
    assert!(comm > 0.0 && comm < 50.0, "L_comm p50 {comm} ms");
    for key in ["/latency_ms/slam_p50", "/latency_ms/viz_p50", "/latency_ms/total_p50", "/latency_ms/total_p99"] {
        assert!(f64_at(&report, key) > 0.0, "{key}");
    }
    let total = f64_at(&report, "/latency_ms/total_p50");
    let parts =
        ["slam_p50", "comm_p50", "viz_p50"].iter().map(|k| f64_at(&report, &format!("/latency_ms/{k}"))).sum::<f64>();
    assert!(total <= parts * 1.5 + 1.0, "total {total} ms against its parts {parts} ms");
    // The rig found itself in the robot's map from what came over the link.
    let first = report.pointer("/alignment/first_accepted_after_s").and_then(Value::as_f64);
    assert!(first.is_some_and(|t| t < 6.0), "the rig is aligned within 6 s: {report}");
    assert!(f64_at(&report, "/alignment/first_error_m") < 0.1);
    assert!(f64_at(&report, "/rig_pose_error/translation_m/p50") < 0.05);
    assert!(f64_at(&report, "/detection/windows") > 50.0);
    assert!(f64_at(&report, "/inlier_ratio/frames_scored") > 5.0);
    let nodes: Value = serde_json::from_str(&std::fs::read_to_string(mission.join("nodes.json")).unwrap()).unwrap();
    assert!(f64_at(&nodes, "/robot/tiles_sent") > 10.0, "{nodes}");
    assert_eq!(f64_at(&nodes, "/robot/detections_sent"), f64_at(&nodes, "/fpv/detections_received"), "{nodes}");
    // The base's feedback reached the robot's LIO: the run's CAN log, replayed as its bus.
    assert!(f64_at(&nodes, "/robot/wheel_twists") > 100.0, "{nodes}");

    // Both recordings decode with real ROS 2 tooling.
    let robot = topics(&mission.join("robot.mcap"));
    let fpv = topics(&mission.join("fpv.mcap"));
    for (rec, topic) in [
        (&robot, "/robot/points"),
        (&robot, "/robot/imu"),
        (&robot, "/robot/odom"),
        (&robot, "/detections/markers"),
        (&robot, "/robot/wheel_odom"),
        (&robot, "/robot/can/rx"),
        (&fpv, "/fpv/points"),
        (&fpv, "/fpv/imu"),
        (&fpv, "/fpv/odom"),
        (&fpv, "/fpv/ar_image/compressed"),
    ] {
        let n = rec.pointer(&format!("/mcap/{}", topic.replace('/', "~1"))).and_then(Value::as_u64).unwrap_or(0);
        let m = rec.pointer(&format!("/rosbags/{}", topic.replace('/', "~1"))).and_then(Value::as_u64).unwrap_or(0);
        assert!(n > 0 && n == m, "{topic}: mcap {n}, rosbags {m}");
    }

    // The recordings rerun offline: the robot's side sees the same scans, so it finds the same
    // people in the same windows; the rig aligns again. With no wall clock in it, a rerun writes
    // the same bytes every time.
    let rerun = |name: &str| {
        let out_dir = dir.path().join(name);
        let out = Command::new(env!("CARGO_BIN_EXE_starc"))
            .arg("rerun")
            .arg(mission.join("robot.mcap"))
            .arg(mission.join("fpv.mcap"))
            .arg("--out")
            .arg(&out_dir)
            .arg("--truth")
            .arg(dir.path())
            .arg("--no-wall-timing")
            // As the live run above: its first alignment at once.
            .args(["--confirm-first-s", "0"])
            .output()
            .unwrap();
        let stdout = String::from_utf8_lossy(&out.stdout);
        assert!(out.status.success(), "{stdout}\n{}", String::from_utf8_lossy(&out.stderr));
        println!("{stdout}");
        out_dir
    };
    let (first_run, second_run) = (rerun("rerun_a"), rerun("rerun_b"));
    let again: Value = serde_json::from_str(&std::fs::read_to_string(first_run.join("report.json")).unwrap()).unwrap();
    for key in ["/detection/windows", "/detection/true_positives", "/detection/false_positives"] {
        assert_eq!(again.pointer(key), report.pointer(key), "{key}: rerun {again} live {report}");
    }
    assert!(f64_at(&again, "/alignment/first_error_m") < 0.1);
    let (a, b) = (files_under(&first_run), files_under(&second_run));
    assert!(a.len() > 10, "{a:?}");
    assert_eq!(a.keys().collect::<Vec<_>>(), b.keys().collect::<Vec<_>>());
    for (name, bytes) in &a {
        assert!(b.get(name) == Some(bytes), "{name} differs between two reruns");
    }
}

/// Every file under `dir` by its path relative to `dir`, with its bytes.
fn files_under(dir: &Path) -> std::collections::BTreeMap<String, Vec<u8>> {
    let mut out = std::collections::BTreeMap::new();
    let mut todo = vec![dir.to_path_buf()];
    while let Some(d) = todo.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                todo.push(p);
            } else {
                let name = p.strip_prefix(dir).unwrap().to_string_lossy().into_owned();
                out.insert(name, std::fs::read(&p).unwrap());
            }
        }
    }
    out
}
