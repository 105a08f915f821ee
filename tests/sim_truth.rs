//! The simulator end to end: what `starc sim` writes is deterministic, decodes as real Avia
//! traffic, and agrees with its own ground truth (poses, labels, people's boxes, IMU).

#![allow(clippy::unwrap_used, clippy::expect_used)]

use nalgebra::{Point3, Vector3};
use starc_eval::truth::{at as truth_at, read_people, read_tum};
use starc_hil::sim::lidar::LABEL_EMPTY;
use starc_hil::sim::run::{run, SimOptions, SimSummary};
use starc_hil::sim::scenario::Scenario;
use starc_hil::sim::truth::read_labels;
use starc_livox::capture;
use starc_livox::data::{DataPacket, Point};
use std::collections::HashMap;
use std::net::Ipv4Addr;
use std::path::Path;

fn simulate(name: &str, secs: f64, seed: u64, dir: &Path, camera: bool) -> SimSummary {
    let (scenario, text) = Scenario::load(name).unwrap();
    let opts = SimOptions { out: dir.to_path_buf(), duration_s: Some(secs), seed, realtime: false, camera };
    run(&scenario, &text, &opts, &mut |_, _| {}).unwrap()
}

#[test]
fn same_seed_same_bytes_other_seed_other_bytes() {
    let base = tempfile::tempdir().unwrap();
    let (a, b, c) = (base.path().join("a"), base.path().join("b"), base.path().join("c"));
    simulate("corridor", 2.5, 7, &a, true);
    simulate("corridor", 2.5, 7, &b, true);
    simulate("corridor", 2.5, 8, &c, true);
    for file in [
        "avia.pcap",
        "labels_robot.bin",
        "labels_fpv.bin",
        "gt_robot.tum",
        "gt_fpv.tum",
        "people.csv",
        "robot_imu_external.csv",
        "robot_wheels.csv",
        "robot_imu_external.mip",
        "robot_can.log",
        "camera/frames.csv",
        "extrinsics.json",
    ] {
        let (x, y) = (std::fs::read(a.join(file)).unwrap(), std::fs::read(b.join(file)).unwrap());
        assert!(x == y, "{file} differs between two runs with the same seed");
    }
    assert_ne!(std::fs::read(a.join("avia.pcap")).unwrap(), std::fs::read(c.join("avia.pcap")).unwrap());
}

#[test]
fn pcap_is_avia_traffic_and_points_match_the_truth() {
    let dir = tempfile::tempdir().unwrap();
    let summary = simulate("lab", 4.0, 3, dir.path(), false);
    let robot_tum = read_tum(&dir.path().join("gt_robot.tum")).unwrap();
    let fpv_tum = read_tum(&dir.path().join("gt_fpv.tum")).unwrap();
    assert_eq!(robot_tum.len(), 801, "200 Hz over 4 s");
    assert!(fpv_tum.len() > 590 && fpv_tum.len() < 610, "the rig powers on at 1 s: {}", fpv_tum.len());
    let labels: HashMap<(bool, u64), Vec<u16>> = ["robot", "fpv"]
        .iter()
        .flat_map(|name| {
            let bytes = std::fs::read(dir.path().join(format!("labels_{name}.bin"))).unwrap();
            read_labels(&bytes).unwrap().into_iter().map(move |(t, l)| ((*name == "robot", t), l))
        })
        .collect();

    let world = {
        let (scenario, _) = Scenario::load("lab").unwrap();
        starc_hil::sim::world::World::new(&scenario)
    };
    let mut per_ip: HashMap<Ipv4Addr, (u64, u64, u64)> = HashMap::new();
    let mut residuals = Vec::new();
    let mut points = Vec::new();
    let mut checked_labels = 0usize;
    for d in capture::open(&dir.path().join("avia.pcap")).unwrap() {
        let d = d.unwrap();
        let src = d.src.unwrap();
        let e = per_ip.entry(*src.ip()).or_default();
        if src.port() == 65000 || d.dst.unwrap().port() == 65000 {
            e.2 += 1;
            continue;
        }
        let packet = DataPacket::parse(&d.payload).unwrap();
        if packet.imu().is_some() {
            e.1 += 1;
            continue;
        }
        e.0 += 1;
        let is_robot = *src.ip() == Ipv4Addr::new(192, 168, 1, 101);
        points.clear();
        packet.decode_points(&mut points);
        let t0 = packet.header.timestamp.ns;
        let l = labels.get(&(is_robot, t0)).expect("every point packet has its labels");
        assert_eq!(l.len(), 96);
        // Every other packet: check each return against the scene, cast from the true pose.
        if !e.0.is_multiple_of(2) {
            continue;
        }
        let tum = if is_robot { &robot_tum } else { &fpv_tum };
        let non_empty: Vec<&Point> = points.iter().collect();
        let labelled: Vec<u16> = l.iter().copied().filter(|&x| x != LABEL_EMPTY).collect();
        assert_eq!(non_empty.len(), labelled.len(), "labels and returns line up");
        let bodies = world.bodies_at((t0 - 1_767_225_600_000_000_000) as f64 * 1e-9);
        for p in non_empty {
            let pose = truth_at(tum, t0 + u64::from(p.offset_ns));
            let local = Vector3::new(f64::from(p.x_m), f64::from(p.y_m), f64::from(p.z_m));
            let range = local.norm();
            let dir_w = pose.rotation * (local / range);
            let origin = pose.translation.vector;
            if let Some(hit) = world.cast(&origin, &dir_w, 400.0, &bodies) {
                residuals.push(range - hit.t);
            }
            checked_labels += 1;
        }
    }
    let robot = per_ip[&Ipv4Addr::new(192, 168, 1, 101)];
    let fpv = per_ip[&Ipv4Addr::new(192, 168, 2, 102)];
    // 240,000 points/s in packets of 96, and 200 Hz IMU, from their power-on.
    assert!((robot.0 as f64 - 4.0 * 2500.0).abs() < 10.0, "{robot:?}");
    assert!((fpv.0 as f64 - 3.0 * 2500.0).abs() < 10.0, "{fpv:?}");
    assert!((robot.1 as f64 - 800.0).abs() < 3.0 && (fpv.1 as f64 - 600.0).abs() < 3.0);
    assert!(robot.2 >= 8 && fpv.2 >= 8, "broadcast, acks and heartbeat acks: {robot:?} {fpv:?}");
    assert_eq!(summary.devices.len(), 2);
    // Ranges agree with the scene seen from the true pose: 2 cm noise, pose sampled at 200 Hz.
    residuals.sort_by(f64::total_cmp);
    let n = residuals.len();
    let median_abs = {
        let mut a: Vec<f64> = residuals.iter().map(|r| r.abs()).collect();
        a.sort_by(f64::total_cmp);
        a[n / 2]
    };
    let within = residuals.iter().filter(|r| r.abs() < 0.1).count() as f64 / n as f64;
    eprintln!("{n} returns checked: median |range residual| {median_abs:.4} m, {:.2} % within 10 cm", 100.0 * within);
    assert!(checked_labels > 100_000);
    assert!(median_abs < 0.02, "median residual {median_abs}");
    assert!(within > 0.97, "only {within} within 10 cm");
}

#[test]
fn imu_measures_the_true_motion() {
    let dir = tempfile::tempdir().unwrap();
    simulate("lab", 8.0, 5, dir.path(), false);
    let tum = read_tum(&dir.path().join("gt_robot.tum")).unwrap();
    let mut gyro_err = Vec::new();
    let mut static_acc = Vec::new();
    for d in capture::open(&dir.path().join("avia.pcap")).unwrap() {
        let d = d.unwrap();
        if d.src.unwrap() != "192.168.1.101:60003".parse().unwrap() {
            continue;
        }
        let packet = DataPacket::parse(&d.payload).unwrap();
        let imu = packet.imu().unwrap();
        let t = packet.header.timestamp.ns;
        // The truth's rate: finite difference of the 200 Hz poses around t (yaw about the
        // LiDAR's z, which the IMU's axes share).
        let (a, b) = (truth_at(&tum, t - 5_000_000), truth_at(&tum, t + 5_000_000));
        let w = (a.rotation.inverse() * b.rotation).scaled_axis() / 0.01;
        gyro_err.push(f64::from(imu.gyro_rad_s[2]) - w.z);
        if t < 1_767_225_600_000_000_000 + 1_900_000_000 {
            let acc = imu.acc_m_s2();
            static_acc.push(Vector3::new(f64::from(acc[0]), f64::from(acc[1]), f64::from(acc[2])).norm());
        }
    }
    let mean_err = gyro_err.iter().sum::<f64>() / gyro_err.len() as f64;
    let rms = (gyro_err.iter().map(|e| (e - mean_err).powi(2)).sum::<f64>() / gyro_err.len() as f64).sqrt();
    let g = static_acc.iter().sum::<f64>() / static_acc.len() as f64;
    eprintln!("gyro z vs truth: bias {mean_err:.4} rad/s, rms {rms:.4} rad/s; static |acc| {g:.3} m/s^2");
    assert!(gyro_err.len() > 1500);
    assert!(rms < 0.02, "{rms}");
    assert!(mean_err.abs() < 0.015, "gyro bias {mean_err}");
    assert!((g - 9.80665).abs() < 0.2, "{g}");
}

/// Points labelled as a person lie in that person's true box; people are in the visible mask
/// only where no wall hides them.
#[test]
fn person_labels_fall_in_the_true_boxes() {
    let text = r#"
name = "two people"
duration_s = 2.0
[[floors]]
min = [-2, -5]
max = [12, 5]
ceiling_m = 3.0
[[people]]
name = "walker"
at = [6, -2]
path = [[6, 2]]
speed_m_s = 1.0
[[people]]
name = "victim"
pose = "lying"
at = [4, 1.5]
yaw_deg = 30
[robot]
static_s = 5.0
waypoints = [[0, 0, 0]]
[responder]
waypoints = [[0, 0]]
yaw_deg = 0
"#;
    let scenario = Scenario::parse(text, "inline").unwrap();
    let dir = tempfile::tempdir().unwrap();
    let opts = SimOptions { out: dir.path().to_path_buf(), duration_s: None, seed: 2, realtime: false, camera: true };
    run(&scenario, text, &opts, &mut |_, _| {}).unwrap();
    let tum = read_tum(&dir.path().join("gt_robot.tum")).unwrap();
    // people.csv: each person's box at 10 Hz.
    let boxes = read_people(&dir.path().join("people.csv")).unwrap();
    let labels: HashMap<u64, Vec<u16>> =
        read_labels(&std::fs::read(dir.path().join("labels_robot.bin")).unwrap()).unwrap().into_iter().collect();
    let (mut inside, mut person_points) = (0usize, [0usize; 3]);
    let mut points = Vec::new();
    for d in capture::open(&dir.path().join("avia.pcap")).unwrap() {
        let d = d.unwrap();
        if d.src.unwrap() != "192.168.1.101:60001".parse().unwrap() {
            continue;
        }
        let packet = DataPacket::parse(&d.payload).unwrap();
        points.clear();
        packet.decode_points(&mut points);
        let t0 = packet.header.timestamp.ns;
        let l: Vec<u16> = labels[&t0].iter().copied().filter(|&x| x != LABEL_EMPTY).collect();
        for (p, &label) in points.iter().zip(&l) {
            if label == 0 {
                continue;
            }
            person_points[usize::from(label)] += 1;
            let t = t0 + u64::from(p.offset_ns);
            let w =
                truth_at(&tum, t).transform_point(&Point3::new(f64::from(p.x_m), f64::from(p.y_m), f64::from(p.z_m)));
            // The box of this person at the nearest 100 ms.
            let b = boxes.iter().filter(|b| b.label == label).min_by_key(|b| b.t_ns.abs_diff(t)).unwrap();
            let (s, c) = b.yaw_rad.sin_cos();
            let (dx, dy) = (w.x - b.centre_m.x, w.y - b.centre_m.y);
            let local = [c * dx + s * dy, -s * dx + c * dy, w.z - b.centre_m.z];
            // 5 cm of range noise, and a walker moves up to 5 cm between box samples.
            let margin = 0.12;
            if (0..3).all(|i| local[i].abs() <= b.size_m[i] / 2.0 + margin) {
                inside += 1;
            }
        }
    }
    let total = person_points[1] + person_points[2];
    eprintln!("person returns: walker {}, victim {}; {inside} inside their boxes", person_points[1], person_points[2]);
    assert!(person_points[1] > 500 && person_points[2] > 100, "{person_points:?}");
    assert!(inside as f64 / total as f64 > 0.97, "{inside} of {total}");
    // A mask pair per camera frame at 10 Hz, from 0 s to 2 s inclusive.
    let frames = std::fs::read_dir(dir.path().join("camera/see_through")).unwrap().count();
    assert_eq!(frames, 21);
}
