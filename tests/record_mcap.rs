//! MCAP recordings (starc_pipeline::record) end to end: every message type written, read back
//! by our reader and decoded by real ROS 2 tooling (PyPI `mcap` + `mcap-ros2-support`, and
//! `rosbags`, run from `.venv/bin/python` by tests/peers/mcap_check.py); a writer killed by
//! SIGKILL mid-recording, then read back as far as the file goes; damaged files read without
//! a panic.
//!
//! The peers are required: a missing peer fails these tests (install with
//! `.venv/bin/pip install -r tests/peers/requirements.txt`, as .ci/run does).

#![allow(clippy::unwrap_used, clippy::expect_used)]

use serde_json::{json, Value};
use starc_pipeline::cloud::{CloudPoint, PointCloud};
use starc_pipeline::record::msgs::{CanFrameMsg, Pose, Quaternion, Vector3};
use starc_pipeline::record::reader::{self, cloud_from_msg};
use starc_pipeline::record::{ChunkCompression, Decoded, PersonBox, ReadMode, Recorder, RecorderOptions, Topic};
use starc_time::{Clock, Stamp};
use std::path::{Path, PathBuf};
use std::process::Command;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The venv's python with the MCAP peers; a missing peer is a failure, not a skip.
fn peer_python() -> PathBuf {
    let python = root().join(".venv/bin/python");
    let ok = Command::new(&python)
        .args(["-c", "import mcap, mcap_ros2.decoder, rosbags.highlevel"])
        .output()
        .is_ok_and(|o| o.status.success());
    assert!(ok, "peers mcap / mcap-ros2-support / rosbags missing from .venv: .venv/bin/pip install -r tests/peers/requirements.txt");
    python
}

fn run_peer(args: &[&str]) -> Value {
    let out = Command::new(peer_python())
        .arg(root().join("tests/peers/mcap_check.py"))
        .args(args)
        .output()
        .expect("starting the peer");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "peer failed: {}\n{stdout}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_str(stdout.lines().last().unwrap_or_default()).unwrap_or_else(|e| panic!("{stdout:?}: {e}"))
}

const T0_NS: u64 = 1_763_719_200_000_000_000; // 2025-11-21 10:00 UTC on the PTP clock
const PNG_4X2: &str = "89504e470d0a1a0a0000000d4948445200000004000000020802000000f0caea340000001349444154789c63d0603801470c1a2927e0080066c20911af6e4d840000000049454e44ae426082";

fn ptp(ns: u64) -> Stamp {
    Stamp::new(ns, Clock::Ptp)
}

fn png() -> Vec<u8> {
    (0..PNG_4X2.len()).step_by(2).map(|i| u8::from_str_radix(&PNG_4X2[i..i + 2], 16).unwrap()).collect()
}

fn scan(k: u64, n: usize) -> PointCloud {
    let points = (0..n)
        .map(|i| CloudPoint {
            x_m: 1.0 + i as f32 * 0.01,
            y_m: -2.0 + k as f32 * 0.5,
            z_m: 0.25 * (i % 7) as f32,
            intensity: (i % 256) as f32,
            offset_ns: i as u32 * 4_000,
            line: (i % 6) as u8,
            tag: 0x10,
        })
        .collect();
    PointCloud::new(Some(ptp(T0_NS + k * 100_000_000)), points)
}

fn point_json(p: &CloudPoint) -> Value {
    json!([p.x_m, p.y_m, p.z_m, p.intensity, p.offset_ns, p.line, p.tag])
}

fn pose(x: f64, yaw_rad: f64) -> Pose {
    let (s, c) = (yaw_rad / 2.0).sin_cos();
    Pose { position: Vector3::new(x, 0.5 * x, 0.1), orientation: Quaternion { x: 0.0, y: 0.0, z: s, w: c } }
}

fn v(p: &Vector3) -> Value {
    json!([p.x, p.y, p.z])
}

fn q(q: &Quaternion) -> Value {
    json!([q.x, q.y, q.z, q.w])
}

/// Writes one of everything the recorder offers; returns what a decoder must find, as
/// `[topic, log_ns, fields]` in the layout of mcap_check.py's `summarize`.
fn write_everything(path: &Path, compression: ChunkCompression) -> Vec<Value> {
    let options = RecorderOptions { compression, chunk_span_ns: 250_000_000, ..RecorderOptions::default() };
    let mut rec = Recorder::create(path, options).unwrap();
    let mut expected = Vec::new();

    let extrinsics = [("base_link", "avia", pose(0.2, 0.0)), ("base_link", "imu_link", pose(0.1, 0.5))];
    rec.tf_static(ptp(T0_NS), &extrinsics).unwrap();
    let tf_json = |ns: u64, list: &[(&str, &str, Pose)]| json!({"transforms": list.iter().map(|(p, c, x)| json!([p, c, ns, v(&x.position), q(&x.orientation)])).collect::<Vec<_>>()});
    expected.push(json!([Topic::TfStatic.name(), T0_NS, tf_json(T0_NS, &extrinsics)]));

    for k in 0..5 {
        let cloud = scan(k, 2_000);
        rec.point_cloud(&cloud).unwrap();
        let ns = cloud.start.unwrap().ns;
        let fields = json!([
            ["x", 0, 7, 1],
            ["y", 4, 7, 1],
            ["z", 8, 7, 1],
            ["intensity", 12, 7, 1],
            ["t", 16, 6, 1],
            ["line", 20, 2, 1],
            ["tag", 21, 2, 1]
        ]);
        expected.push(json!([Topic::Points.name(), ns, {
            "frame": "avia", "stamp_ns": ns, "width": 2_000, "height": 1, "point_step": 24, "fields": fields,
            "first": point_json(&cloud.points[0]), "last": point_json(&cloud.points[1_999]),
        }]));
    }
    for i in 0..100u64 {
        let ns = T0_NS + i * 5_000_000;
        let gyro = [0.01 * i as f64, -0.02, 0.003];
        let acc = [0.1, 0.2 + i as f64 * 1e-3, 9.81];
        rec.imu(ptp(ns), gyro, acc).unwrap();
        expected.push(json!([Topic::Imu.name(), ns, {
            "frame": "imu_link", "stamp_ns": ns, "gyro": gyro, "acc": acc, "orientation_covariance0": -1.0,
        }]));
    }
    for i in 0..10u64 {
        let ns = T0_NS + i * 50_000_000;
        let p = pose(0.05 * i as f64, 0.1 * i as f64);
        rec.odometry(ptp(ns), p, [0.3, 0.0, 0.0], [0.0, 0.0, 0.1]).unwrap();
        expected.push(json!([Topic::Odom.name(), ns, {
            "frame": "odom", "child": "base_link", "stamp_ns": ns, "position": v(&p.position),
            "orientation": q(&p.orientation), "linear": [0.3, 0.0, 0.0], "angular": [0.0, 0.0, 0.1],
        }]));
        let list = [("map", "odom", pose(1.0, 0.0)), ("odom", "base_link", p)];
        rec.tf(ptp(ns), &list).unwrap();
        expected.push(json!([Topic::Tf.name(), ns, tf_json(ns, &list)]));
    }
    for i in 0..10u64 {
        let ns = T0_NS + 7_000_000 + i * 40_000_000;
        let p = pose(0.04 * i as f64, 0.05 * i as f64);
        rec.wheel_odometry(ptp(ns), p, [0.25, -0.05, 0.0], [0.0, 0.0, 0.2]).unwrap();
        expected.push(json!([Topic::WheelOdom.name(), ns, {
            "frame": "wheel_odom", "child": "base_link", "stamp_ns": ns, "position": v(&p.position),
            "orientation": q(&p.orientation), "linear": [0.25, -0.05, 0.0], "angular": [0.0, 0.0, 0.2],
        }]));
    }
    for i in 0..12u64 {
        let ns = T0_NS + 3_000_000 + i * 10_000_000;
        let frame = CanFrameMsg {
            id: 0x201 + (i % 3) as u32,
            dlc: 8,
            data: [i as u8, 0x10, 0, 0x57, 0, 0, 0x1E, 0],
            ..CanFrameMsg::default()
        };
        rec.can_frame(ptp(ns), &frame).unwrap();
        expected.push(json!([Topic::CanRx.name(), ns, {
            "stamp_ns": ns, "id": frame.id, "is_rtr": false, "is_extended": false, "is_error": false,
            "dlc": 8, "data": frame.data,
        }]));
    }
    for i in 0..3u64 {
        let ns = T0_NS + 20_000_000 + i * 100_000_000;
        let p = pose(2.0 + i as f64, -0.3);
        rec.fpv_odometry(ptp(ns), p).unwrap();
        expected.push(json!([Topic::FpvOdom.name(), ns, {
            "frame": "map", "child": "fpv_camera", "stamp_ns": ns, "position": v(&p.position),
            "orientation": q(&p.orientation), "linear": [0.0, 0.0, 0.0], "angular": [0.0, 0.0, 0.0],
        }]));
    }
    for i in 0..3u64 {
        let ns = T0_NS + 30_000_000 + i * 100_000_000;
        let people: Vec<PersonBox> = (0..i)
            .map(|j| PersonBox {
                id: j as i32 + 7,
                center_m: [3.0 + j as f64, -1.0, 0.9],
                size_m: [0.6, 0.5, 1.8],
                yaw_rad: 0.4 * j as f64,
                score: 0.9,
                pose: starc_pipeline::detect::PersonPose::Upright,
            })
            .collect();
        rec.detections(ptp(ns), &people).unwrap();
        let mut markers = vec![json!(["", 0, 0, 3, "map", [0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0], [0.0, 0.0, 0.0], ""])];
        for p in &people {
            let (s, c) = (p.yaw_rad / 2.0).sin_cos();
            markers.push(json!(["people", p.id, 1, 0, "map", p.center_m, [0.0, 0.0, s, c], p.size_m, ""]));
            let top = [p.center_m[0], p.center_m[1], p.center_m[2] + 0.9 + 0.2];
            let text = format!("person {} upright (0.90)", p.id);
            markers.push(json!(["people_labels", p.id, 9, 0, "map", top, [0.0, 0.0, s, c], [0.0, 0.0, 0.25], text]));
        }
        expected.push(json!([Topic::DetectionMarkers.name(), ns, {"markers": markers}]));
    }
    for i in 0..2u64 {
        let ns = T0_NS + 40_000_000 + i * 200_000_000;
        rec.ar_image_png(ptp(ns), &png()).unwrap();
        expected.push(json!([Topic::ArImage.name(), ns, {
            "frame": "fpv_camera", "stamp_ns": ns, "format": "png", "png_signature": true,
            "png_width": 4, "png_height": 2, "bytes": png().len(),
        }]));
    }
    let stats = rec.finish().unwrap();
    assert_eq!(stats.messages, expected.len() as u64);
    assert_eq!(stats.committed_messages, stats.messages);
    expected
}

#[test]
fn our_reader_gets_back_what_was_written() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("all.mcap");
    let expected = write_everything(&path, ChunkCompression::Lz4);
    let bytes = reader::read_file(&path).unwrap();

    let mut n = 0;
    let mut clouds = 0;
    for m in reader::messages(&bytes, ReadMode::Strict).unwrap() {
        let m = m.unwrap();
        assert_eq!(m.log_ns, m.publish_ns);
        match m.decode().unwrap() {
            Decoded::PointCloud2(c) => {
                let k = clouds;
                let back = cloud_from_msg(&c, Clock::Ptp).unwrap();
                assert_eq!(back, scan(k, 2_000), "scan {k}");
                clouds += 1;
            }
            Decoded::Imu(imu) => assert_eq!(imu.header.frame_id, "imu_link"),
            Decoded::CompressedImage(img) => assert_eq!(img.data, png()),
            _ => {}
        }
        n += 1;
    }
    assert_eq!(n, expected.len());
    assert_eq!(clouds, 5);

    // the file streamed gives the same messages as the bytes in memory
    let streamed: Vec<_> = reader::open(&path, ReadMode::Strict).unwrap().map(Result::unwrap).collect();
    let in_memory: Vec<_> = reader::messages(&bytes, ReadMode::Strict).unwrap().map(Result::unwrap).collect();
    assert_eq!(streamed, in_memory);

    let s = reader::summarize(&bytes).unwrap();
    assert_eq!(reader::summarize_file(&path).unwrap(), s);
    assert!(s.finished);
    assert_eq!(s.stopped_by, None);
    assert_eq!(s.messages, expected.len() as u64);
    assert_eq!(s.topics.len(), Topic::ALL.len());
    for t in Topic::ALL {
        let want = expected.iter().filter(|e| e[0] == t.name()).count() as u64;
        assert_eq!(s.topics[t.name()].messages, want, "{}", t.name());
        assert_eq!(s.topics[t.name()].type_name, t.type_name());
    }
    assert_eq!(s.start_ns, Some(T0_NS));
    assert_eq!(s.end_ns, Some(T0_NS + 495_000_000));
}

#[test]
fn real_peers_decode_every_message() {
    for compression in [ChunkCompression::None, ChunkCompression::Lz4] {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("all.mcap");
        let expected = write_everything(&path, compression);
        let expected_path = dir.path().join("expected.json");
        std::fs::write(&expected_path, serde_json::to_string(&expected).unwrap()).unwrap();
        let r = run_peer(&["full", path.to_str().unwrap(), expected_path.to_str().unwrap()]);
        println!("{compression:?}: {r}");
        assert_eq!(r["ok"], true, "{r}");
        let n = expected.len() as u64;
        for decoder in ["mcap_ros2", "rosbags_anyreader", "rosbags_humble"] {
            assert_eq!(r["counts"][decoder], n, "{decoder}: {r}");
        }
        assert_eq!(r["summary_messages"], n);
        assert_eq!(r["topics"].as_object().unwrap().len(), Topic::ALL.len());
        // rosbags parses our QoS metadata: the extrinsics are latched for `ros2 bag play`
        assert_eq!(r["durability"]["/tf_static"], json!(["transient_local"]), "{r}");
        assert_eq!(r["durability"]["/robot/imu"], json!(["volatile"]), "{r}");
    }
}

const CHILD_ENV: &str = "STARC_RECORD_KILLED_CHILD";

/// Not a test of its own: the process `a_writer_killed_mid_recording_keeps_closed_chunks`
/// starts and lets die. Writes 200 Hz IMU and 10 Hz scans with 100 ms chunks, prints what
/// was committed, then kills itself with SIGKILL (no destructor, no flush, no core dump).
#[test]
#[ignore = "child process of a_writer_killed_mid_recording_keeps_closed_chunks"]
fn killed_child() {
    let Some(path) = std::env::var_os(CHILD_ENV) else {
        return;
    };
    let options = RecorderOptions { chunk_span_ns: 100_000_000, ..RecorderOptions::default() };
    let mut rec = Recorder::create(Path::new(&path), options).unwrap();
    for i in 0..1_037u64 {
        let ns = T0_NS + i * 5_000_000;
        rec.imu(ptp(ns), [0.0, 0.0, 0.1], [0.0, 0.0, 9.81]).unwrap();
        if i % 20 == 0 {
            rec.point_cloud(&PointCloud::new(Some(ptp(ns)), scan(i / 20, 500).points)).unwrap();
        }
    }
    let s = rec.stats();
    println!("committed={} written={} chunks={}", s.committed_messages, s.messages, s.chunks);
    use std::io::Write;
    let _ = std::io::stdout().flush();
    // SAFETY: kill(2) on our own pid; nothing after it runs.
    unsafe { libc::kill(libc::getpid(), libc::SIGKILL) };
    unreachable!("SIGKILL returned");
}

#[test]
fn a_writer_killed_mid_recording_keeps_closed_chunks() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("killed.mcap");
    let out = Command::new(std::env::current_exe().unwrap())
        .args(["killed_child", "--exact", "--ignored", "--nocapture", "--test-threads=1"])
        .env(CHILD_ENV, &path)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    use std::os::unix::process::ExitStatusExt;
    assert_eq!(out.status.signal(), Some(libc::SIGKILL), "the child should have been killed: {stdout}");
    // the harness prints "test killed_child ... " on the same line
    let line = stdout.lines().find_map(|l| l.find("committed=").map(|i| &l[i..])).unwrap_or_else(|| panic!("{stdout}"));
    let field =
        |name: &str| -> u64 { line.split_whitespace().find_map(|kv| kv.strip_prefix(name)).unwrap().parse().unwrap() };
    let (committed, written, chunks) = (field("committed="), field("written="), field("chunks="));
    println!("child: {line}");
    assert!(committed > 0 && committed < written, "{line}");
    assert!(chunks >= 50, "{line}");

    let bytes = reader::read_file(&path).unwrap();
    // Strict reading says the file is damaged...
    let strict: Vec<_> = reader::messages(&bytes, ReadMode::Strict).unwrap().collect();
    assert!(strict.last().unwrap().is_err(), "a strict read must report the missing end");
    // ...recovery keeps exactly what was committed, every message decodable.
    let mut it = reader::messages(&bytes, ReadMode::Recover).unwrap();
    let mut n = 0u64;
    for m in it.by_ref() {
        m.unwrap().decode().unwrap();
        n += 1;
    }
    assert_eq!(n, committed, "stopped by {:?}", it.stopped_by());
    let s = reader::summarize(&bytes).unwrap();
    assert!(!s.finished);
    assert_eq!(s.messages, committed);
    assert_eq!(reader::summarize_file(&path).unwrap(), s);
    let streamed = reader::open(&path, ReadMode::Recover).unwrap().count() as u64;
    assert_eq!(streamed, committed);

    // The reference reader agrees.
    let r = run_peer(&["recover", path.to_str().unwrap()]);
    println!("mcap (python) recover: {r}");
    assert_eq!(r["messages"], committed, "{r}");
}

#[test]
fn damaged_recordings_give_errors_not_panics() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("all.mcap");
    let total = write_everything(&path, ChunkCompression::Lz4).len() as u64;
    let bytes = reader::read_file(&path).unwrap();

    // Every cut: a summary that never claims more than the file holds.
    let mut last = 0;
    for cut in (0..bytes.len()).step_by(53) {
        match reader::summarize(&bytes[..cut]) {
            Ok(s) => {
                assert!(s.messages <= total);
                assert!(s.messages >= last, "a longer prefix lost messages at {cut}");
                last = s.messages;
            }
            Err(_) => assert!(cut < 16, "only a missing header may refuse to open ({cut})"),
        }
    }
    // Flipped bytes: errors or (CRC-checked) messages, never a panic; decode what comes out.
    let mut seed = 0x2545_f491_4f6c_dd1d_u64;
    for _ in 0..300 {
        let mut b = bytes.clone();
        for _ in 0..3 {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            let i = (seed % b.len() as u64) as usize;
            b[i] ^= (seed >> 32) as u8 | 1;
        }
        for mode in [ReadMode::Strict, ReadMode::Recover] {
            if let Ok(it) = reader::messages(&b, mode) {
                for m in it.take(1_000).flatten() {
                    let _ = m.decode();
                }
            }
        }
    }
}

#[test]
fn starc_inspect_summarizes_a_recording() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("all.mcap");
    let expected = write_everything(&path, ChunkCompression::Lz4);
    let out = Command::new(env!("CARGO_BIN_EXE_starc")).arg("inspect").arg(&path).output().unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{text}{}", String::from_utf8_lossy(&out.stderr));
    println!("{text}");
    assert!(text.contains("(MCAP, finished)"), "{text}");
    assert!(text.contains(&format!("{} on {} topics", expected.len(), Topic::ALL.len())), "{text}");
    let imu = text.lines().find(|l| l.starts_with("/robot/imu")).unwrap();
    assert!(imu.contains("sensor_msgs/msg/Imu") && imu.contains(" 100 ") && imu.ends_with("200.0"), "{imu}");

    let out = Command::new(env!("CARGO_BIN_EXE_starc")).args(["inspect", "--json"]).arg(&path).output().unwrap();
    let v: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["messages"], expected.len());
    assert_eq!(v["topics"]["/robot/points"]["messages"], 5);
    assert_eq!(v["finished"], true);

    // Cut in the middle: summarized up to the damage, exit status 1.
    let bytes = std::fs::read(&path).unwrap();
    let cut = dir.path().join("cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_starc")).arg("inspect").arg(&cut).output().unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(!out.status.success(), "{text}");
    assert!(text.contains("not finished"), "{text}");
}

#[test]
fn drop_finishes_and_bad_calls_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("dropped.mcap");
    {
        let mut rec = Recorder::create(&path, RecorderOptions::default()).unwrap();
        rec.imu(ptp(T0_NS), [0.0; 3], [0.0, 0.0, 9.81]).unwrap();
        // refused, and nothing written: another clock, a time ROS 2 cannot hold, a cloud without a start
        assert!(rec.imu(Stamp::new(T0_NS, Clock::Host), [0.0; 3], [0.0; 3]).is_err());
        assert!(rec.imu(ptp(u64::MAX), [0.0; 3], [0.0; 3]).is_err());
        assert!(rec.point_cloud(&PointCloud::new(None, vec![CloudPoint::xyz(1.0, 0.0, 0.0)])).is_err());
        assert_eq!(rec.stats().messages, 1);
    } // dropped without finish()
    let bytes = std::fs::read(&path).unwrap();
    let s = reader::summarize(&bytes).unwrap();
    assert!(s.finished && s.stopped_by.is_none() && s.messages == 1, "{s:?}");

    let mut rec = Recorder::create(&dir.path().join("f.mcap"), RecorderOptions::default()).unwrap();
    rec.finish().unwrap();
    assert!(rec.imu(ptp(T0_NS), [0.0; 3], [0.0; 3]).is_err(), "a write after finish() must fail");
    assert!(rec.finish().is_ok(), "finish() twice is harmless");
}

#[test]
fn the_same_input_records_the_same_bytes() {
    let dir = tempfile::tempdir().unwrap();
    let (a, b) = (dir.path().join("a.mcap"), dir.path().join("b.mcap"));
    write_everything(&a, ChunkCompression::Lz4);
    write_everything(&b, ChunkCompression::Lz4);
    let (a, b) = (std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap());
    assert_eq!(a.len(), b.len());
    // The data section (every chunk, index and the data-end record) is byte-identical. The
    // summary repeats schemas and channels in the mcap crate's HashMap order, so there only the
    // set of records is the same (and with it the footer's summary CRC differs).
    let split = |f: &[u8]| {
        let n = f.len();
        let summary_start = u64::from_le_bytes(f[n - 28..n - 20].try_into().unwrap()) as usize;
        let mut records = Vec::new();
        let mut pos = summary_start;
        while pos < n - 37 {
            let len = u64::from_le_bytes(f[pos + 1..pos + 9].try_into().unwrap()) as usize;
            records.push(f[pos..pos + 9 + len].to_vec());
            pos += 9 + len;
        }
        records.sort();
        (f[..summary_start].to_vec(), records)
    };
    let ((data_a, summary_a), (data_b, summary_b)) = (split(&a), split(&b));
    assert!(data_a == data_b, "the data sections differ");
    assert!(summary_a == summary_b, "the summaries hold different records");
}
