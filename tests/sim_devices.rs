//! The simulator's serial IMU and CAN outputs decode with our own drivers (and python-can) into
//! the ground truth it writes beside them.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use starc_base::c620::frame::M3508_GEAR_RATIO;
use starc_base::c620::Feedback;
use starc_base::cia402::{Cia402Config, DriveState, VelocityStatus};
use starc_base::kinematics::{Kinematics, KinematicsConfig};
use starc_base::Twist;
use starc_can::CanFrame;
use starc_hil::sim::run::{run, SimOptions};
use starc_hil::sim::scenario::Scenario;
use starc_imu::timing::{LatencyModel, Timestamper};
use starc_imu::{ImuDecoder, ImuEvent, Protocol, STANDARD_GRAVITY_M_S2};
use starc_time::{Clock, Stamp};
use std::path::{Path, PathBuf};
use std::process::Command;

/// GPS time = Unix time - 315 964 800 s + 18 leap seconds.
const GPS_MINUS_UNIX_NS: i64 = (18 - 315_964_800) * 1_000_000_000;
/// The simulator's default 3-wheel omni base (hil/src/sim/wheels.rs).
const OMNI_RADIUS_M: f64 = 0.05;
const OMNI_ARM_M: f64 = 0.2;

fn simulate(text: &str, secs: f64, dir: &Path) {
    let scenario = Scenario::parse(text, "test").unwrap();
    let opts = SimOptions { out: dir.to_path_buf(), duration_s: Some(secs), seed: 11, realtime: false, camera: false };
    run(&scenario, text, &opts, &mut |_, _| {}).unwrap();
}

fn lab_text(motors: Option<&str>) -> String {
    let (_, text) = Scenario::load("lab").unwrap();
    match motors {
        Some(m) => text.replacen("[robot]\n", &format!("[robot]\nmotors = \"{m}\"\n"), 1),
        None => text,
    }
}

fn csv_rows(path: &Path) -> Vec<Vec<f64>> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .skip(1)
        .map(|l| l.split(',').map(|x| x.parse().unwrap()).collect())
        .collect()
}

/// `(sec.usec) can0 ID#DATA` lines as (ns, frame).
fn read_candump(path: &Path) -> Vec<(u64, CanFrame)> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .map(|l| {
            let (stamp, rest) = l.strip_prefix('(').unwrap().split_once(") ").unwrap();
            let (s, us) = stamp.split_once('.').unwrap();
            assert_eq!(us.len(), 6, "{l}");
            let ns = s.parse::<u64>().unwrap() * 1_000_000_000 + us.parse::<u64>().unwrap() * 1000;
            let (iface, frame) = rest.split_once(' ').unwrap();
            assert_eq!(iface, "can0");
            let (id, data) = frame.split_once('#').unwrap();
            let data: Vec<u8> =
                (0..data.len() / 2).map(|i| u8::from_str_radix(&data[2 * i..2 * i + 2], 16).unwrap()).collect();
            (ns, CanFrame::standard(u16::from_str_radix(id, 16).unwrap(), &data).unwrap())
        })
        .collect()
}

fn omni3() -> Kinematics {
    Kinematics::new(&KinematicsConfig::Omni3 {
        wheel_radius_m: OMNI_RADIUS_M,
        center_to_wheel_m: OMNI_ARM_M,
        wheel_angles_deg: None,
    })
    .unwrap()
}

/// How far the body twist can move when each wheel rate is off by up to `wheel_err`.
fn twist_bound(k: &Kinematics, wheel_err: f64) -> [f64; 3] {
    let mut bound = [0.0; 3];
    for i in 0..k.wheel_count() {
        let mut e = vec![0.0; k.wheel_count()];
        e[i] = wheel_err;
        let t = k.body_twist(&e).unwrap();
        for (b, v) in bound.iter_mut().zip([t.vx_m_s, t.vy_m_s, t.wz_rad_s]) {
            *b += v.abs();
        }
    }
    bound
}

/// Decodes the log's wheel rates with `wheel_rad_s` and checks them, and the body twist the
/// drivers/base forward model makes of them, against robot_wheels.csv within `quantum_rad_s`.
fn check_wheels(dir: &Path, quantum_rad_s: f64, wheel_rad_s: impl Fn(&CanFrame) -> (u8, f64)) -> usize {
    let rows = csv_rows(&dir.join("robot_wheels.csv"));
    let frames = read_candump(&dir.join("robot_can.log"));
    assert!(rows.len() > 100, "{} wheel rows", rows.len());
    assert_eq!(frames.len(), 3 * rows.len(), "one frame per wheel per sample");
    let k = omni3();
    // Rates are rounded to one count; the CSV prints 5 decimals.
    let wheel_tol = quantum_rad_s / 2.0 + 5e-6 + 1e-9;
    let bound = twist_bound(&k, quantum_rad_s / 2.0);
    let mut moving = 0;
    for (row, group) in rows.iter().zip(frames.chunks(3)) {
        let t_ns = (row[0] * 1e6).round() as u64 * 1000;
        let mut rates = [0.0; 3];
        for (i, (ns, frame)) in group.iter().enumerate() {
            assert_eq!(*ns, t_ns + i as u64 * 130_000, "frame times");
            let (id, w) = wheel_rad_s(frame);
            assert_eq!(usize::from(id), i + 1);
            assert!((w - row[1 + i]).abs() <= wheel_tol, "wheel {i} at {}: {w} vs {}", row[0], row[1 + i]);
            rates[i] = w;
        }
        let t: Twist = k.body_twist(&rates).unwrap();
        for (j, got) in [t.vx_m_s, t.vy_m_s, t.wz_rad_s].into_iter().enumerate() {
            let want = row[4 + j];
            assert!((got - want).abs() <= bound[j] + 5e-6 + 1e-9, "body {j} at {}: {got} vs {want}", row[0]);
        }
        moving += usize::from(row[4].abs() + row[5].abs() > 0.05);
    }
    assert!(moving > 50, "the base must move for the test to mean something ({moving} moving samples)");
    frames.len()
}

fn python_with_can() -> Option<PathBuf> {
    let python = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(".venv/bin/python");
    let ok =
        python.exists() && Command::new(&python).args(["-c", "import can"]).output().is_ok_and(|o| o.status.success());
    if ok {
        return Some(python);
    }
    assert!(std::env::var_os("CI").is_none(), "python-can missing from .venv: run .ci/run's install step");
    println!("skipped: .venv has no python-can");
    None
}

#[test]
fn mip_stream_decodes_into_the_imu_csv() {
    let dir = tempfile::tempdir().unwrap();
    simulate(&lab_text(None), 3.0, dir.path());
    let rows = csv_rows(&dir.path().join("robot_imu_external.csv"));
    let bytes = std::fs::read(dir.path().join("robot_imu_external.mip")).unwrap();
    // 500 Hz from t = 0 to 3 s inclusive.
    assert_eq!(rows.len(), 1501);
    let mut decoder = ImuDecoder::new(Protocol::Mip, Timestamper::new(LatencyModel::new(0, 0)));
    let mut events = Vec::new();
    for chunk in bytes.chunks(333) {
        decoder.push(chunk, Stamp::new(0, Clock::Host), &mut events);
    }
    let stats = decoder.stats();
    assert_eq!(stats.skipped_bytes, 0);
    assert_eq!(stats.bad_checksums, 0);
    assert_eq!(stats.bytes, bytes.len() as u64);
    let samples: Vec<_> = events
        .into_iter()
        .map(|e| match e {
            ImuEvent::Sample(s) => s,
            other => panic!("not a sample: {other:?}"),
        })
        .collect();
    assert_eq!(samples.len(), rows.len());
    for (s, row) in samples.iter().zip(&rows) {
        // GPS time of the packet is the CSV's PTP time, converted.
        let unix_ns = s.device_ns.unwrap() as i64 - GPS_MINUS_UNIX_NS;
        assert!((unix_ns as f64 * 1e-9 - row[0]).abs() < 2e-6, "time {unix_ns} vs {}", row[0]);
        // f32 on the wire (6e-8 relative) against 7 (gyro) and 6 (accel) printed decimals.
        for i in 0..3 {
            let (g, want) = (s.gyro_rad_s[i], row[1 + i]);
            assert!((g - want).abs() <= 5e-8 + 1.2e-7 * want.abs() + 1e-9, "gyro {i}: {g} vs {want}");
            let (a, want) = (s.accel_m_s2[i], row[4 + i]);
            assert!((a - want).abs() <= 5e-7 + 1.2e-7 * want.abs() + 1e-9, "accel {i}: {a} vs {want}");
        }
    }
    // Gravity is in there: the accel norm of the first (still) sample.
    let a0 = samples[0].accel_m_s2;
    let norm = (a0[0] * a0[0] + a0[1] * a0[1] + a0[2] * a0[2]).sqrt();
    assert!((norm - STANDARD_GRAVITY_M_S2).abs() < 0.2, "{norm}");
}

#[test]
fn c620_log_decodes_into_the_wheel_csv_and_python_can_reads_it() {
    let dir = tempfile::tempdir().unwrap();
    simulate(&lab_text(None), 5.0, dir.path());
    // One rotor rpm, through the gearbox.
    let quantum = std::f64::consts::TAU / 60.0 / M3508_GEAR_RATIO;
    let frames = check_wheels(dir.path(), quantum, |f| {
        let fb = Feedback::parse(f).unwrap();
        assert_eq!(fb.temperature_c, 30);
        (fb.esc, fb.output_rad_s(M3508_GEAR_RATIO))
    });
    let Some(python) = python_with_can() else { return };
    let script = "import can, sys\n\
        msgs = list(can.CanutilsLogReader(sys.argv[1]))\n\
        ids = sorted({m.arbitration_id for m in msgs})\n\
        ok = all(m.dlc == 8 and not m.is_extended_id and m.channel == 'can0' for m in msgs)\n\
        mono = all(a.timestamp <= b.timestamp for a, b in zip(msgs, msgs[1:]))\n\
        print(len(msgs), ' '.join(hex(i) for i in ids), ok, mono)\n";
    let log = dir.path().join("robot_can.log");
    let out = Command::new(python).args(["-c", script]).arg(&log).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert_eq!(stdout.trim(), format!("{frames} 0x201 0x202 0x203 True True"));
}

#[test]
fn cia402_log_decodes_into_the_wheel_csv() {
    let dir = tempfile::tempdir().unwrap();
    simulate(&lab_text(Some("cia402")), 5.0, dir.path());
    let units = Cia402Config::default().units_per_rad_s;
    check_wheels(dir.path(), 1.0 / units, |f| {
        let (node, s) = VelocityStatus::parse(f).unwrap();
        assert_eq!(DriveState::from_statusword(s.statusword), Some(DriveState::OperationEnabled));
        (node, f64::from(s.actual_velocity) / units)
    });
}
