//! `starc lio` end to end: a short simulated lab run through the command, its files, its clear
//! errors, and its trajectory scored by evo next to KISS-ICP (the peers of tests/peers/lio_eval.py).

#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn starc() -> Command {
    Command::new(env!("CARGO_BIN_EXE_starc"))
}

fn ok(out: Output) -> String {
    assert!(
        out.status.success(),
        "failed: {}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

fn python() -> PathBuf {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join(".venv/bin/python");
    assert!(p.exists(), "{} missing: .ci/run installs tests/peers/requirements.txt there", p.display());
    p
}

#[test]
fn starc_lio_writes_trajectories_maps_and_timing_that_evo_scores() {
    let dir = tempfile::tempdir().unwrap();
    let sim = dir.path().join("sim");
    ok(starc().args(["sim", "lab", "--duration", "8", "--no-camera", "--out"]).arg(&sim).output().unwrap());
    let out = dir.path().join("lio");
    let text =
        ok(starc().arg("lio").arg(sim.join("avia.pcap")).arg("--out").arg(&out).arg("--dump-scans").output().unwrap());
    println!("{text}");
    for ip in ["192.168.1.101", "192.168.2.102"] {
        for suffix in [".tum", "_scans.csv", "_map.pcd", "_map.ply", "_scans.bin"] {
            let f = out.join(format!("{ip}{suffix}"));
            assert!(f.metadata().is_ok_and(|m| m.len() > 100), "{} missing or empty", f.display());
        }
    }
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("lio.json")).unwrap()).unwrap();
    let devices = summary["devices"].as_array().unwrap();
    assert_eq!(devices.len(), 2);
    for d in devices {
        assert_eq!(d["status"], "running", "{d}");
        assert!(d["scans_out"].as_u64().unwrap() > 50, "{d}");
        assert!(d["time_per_scan_ms_median"].as_f64().unwrap() > 0.0, "{d}");
    }
    // With the base's wheel feedback (the simulator's robot_can.log and its base: three omni
    // wheels of 0.05 m on a 0.2 m arm, C620 ESCs 1-3), the robot's LIO uses it on nearly every scan.
    let base = dir.path().join("base.toml");
    let shipped = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("config/base.toml")).unwrap();
    std::fs::write(
        &base,
        shipped
            .replace("wheel_radius_m = 0.076", "wheel_radius_m = 0.05")
            .replace("center_to_wheel_m = 0.22", "center_to_wheel_m = 0.2"),
    )
    .unwrap();
    let wheeled = dir.path().join("lio_wheels");
    ok(starc()
        .arg("lio")
        .arg(sim.join("avia.pcap"))
        .args(["--device", "192.168.1.101", "--wheels"])
        .arg(sim.join("robot_can.log"))
        .arg("--base-config")
        .arg(&base)
        .arg("--out")
        .arg(&wheeled)
        .output()
        .unwrap());
    let table = std::fs::read_to_string(wheeled.join("192.168.1.101_scans.csv")).unwrap();
    let rows: Vec<&str> = table.lines().skip(1).collect();
    let applied = rows.iter().filter(|r| r.split(',').nth(14) == Some("applied")).count();
    assert!(rows.len() > 50 && applied * 10 >= rows.len() * 9, "{applied} of {} scans used the wheels", rows.len());
    // ... and measures its tilt from the accelerometer less the wheels on those scans, gating few.
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(wheeled.join("lio.json")).unwrap()).unwrap();
    let robot = &summary["devices"][0];
    let (levelled, gated) = (robot["level_updates"].as_u64().unwrap(), robot["level_gated"].as_u64().unwrap());
    assert!(levelled * 10 >= applied as u64 * 9 && gated * 20 <= applied as u64, "{levelled} levelled, {gated} gated");
    // Without --base-config the wheels cannot be read: a clear error.
    let refused = starc()
        .arg("lio")
        .arg(sim.join("avia.pcap"))
        .arg("--wheels")
        .arg(sim.join("robot_can.log"))
        .arg("--out")
        .arg(dir.path().join("x"))
        .output()
        .unwrap();
    assert!(!refused.status.success() && String::from_utf8_lossy(&refused.stderr).contains("base-config"));

    // The map reads back with our own reader.
    let map = starc_pipeline::cloud::read(&out.join("192.168.1.101_map.pcd")).unwrap();
    assert!(map.len() > 1000, "{} map points", map.len());

    // The same robot data as a recording (MCAP, ROS 2 PointCloud2 with per-point times and Imu)
    // gives the same trajectory.
    let rec_path = dir.path().join("robot.mcap");
    record_robot(&sim.join("avia.pcap"), &rec_path);
    let rec_out = dir.path().join("lio_mcap");
    println!("{}", ok(starc().arg("lio").arg(&rec_path).arg("--out").arg(&rec_out).output().unwrap()));
    let from_pcap = std::fs::read_to_string(out.join("192.168.1.101.tum")).unwrap();
    let from_mcap = std::fs::read_to_string(rec_out.join("robot.tum")).unwrap();
    let (a, b) = (tum_positions(&from_pcap), tum_positions(&from_mcap));
    assert!(a.len() > 50 && a.len().abs_diff(b.len()) <= 1, "{} vs {} poses", a.len(), b.len());
    let common: Vec<f64> =
        a.iter().filter_map(|(t, p)| b.iter().find(|(u, _)| u == t).map(|(_, q)| dist(p, q))).collect();
    assert!(common.len() + 1 >= a.len().min(b.len()), "poses at the same times");
    let worst = common.iter().copied().fold(0.0, f64::max);
    println!("recording vs capture: {} common poses, worst difference {:.6} m", common.len(), worst);
    assert!(worst < 1e-3, "the recording's trajectory differs from the capture's by {worst} m");

    let eval = Command::new(python())
        .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/peers/lio_eval.py"))
        .arg("--gt")
        .arg(sim.join("gt_robot.tum"))
        .arg("--ours")
        .arg(out.join("192.168.1.101.tum"))
        .arg("--scans")
        .arg(out.join("192.168.1.101_scans.bin"))
        .output()
        .unwrap();
    let line = ok(eval);
    println!("{line}");
    let r: serde_json::Value = serde_json::from_str(line.trim()).unwrap();
    let ours = r["ours"]["ape_rmse_m"].as_f64().unwrap();
    assert!(ours < 0.05, "evo APE RMSE {ours} m");
    assert!(r["ours"]["poses"].as_u64().unwrap() > 50);
    assert!(r["kiss_icp"]["scans"].as_u64().unwrap() > 50, "KISS-ICP ran: {r}");
}

#[test]
fn starc_lio_explains_what_is_wrong() {
    let dir = tempfile::tempdir().unwrap();
    let missing = starc().args(["lio", "/nonexistent.pcap", "--out"]).arg(dir.path()).output().unwrap();
    assert!(!missing.status.success());
    assert!(String::from_utf8_lossy(&missing.stderr).contains("/nonexistent.pcap"));

    let bad = dir.path().join("bad.toml");
    std::fs::write(&bad, "[map]\nvoxel = 0.5\n").unwrap();
    let out = starc().args(["lio", "x.pcap", "--out"]).arg(dir.path()).arg("--config").arg(&bad).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("voxel"), "{err}");

    let ext = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/lio_external_imu.toml");
    let out = starc().args(["lio", "x.pcap", "--out"]).arg(dir.path()).arg("--config").arg(&ext).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("--imu"), "{err}");
    let out = starc()
        .args(["lio", "x.pcap", "--out"])
        .arg(dir.path())
        .arg("--config")
        .arg(&ext)
        .args(["--imu", "imu.mip"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("--device"), "{err}");
}

fn tum_positions(text: &str) -> Vec<(String, [f64; 3])> {
    text.lines()
        .map(|l| {
            let f: Vec<&str> = l.split_whitespace().collect();
            (f[0].to_string(), [f[1].parse().unwrap(), f[2].parse().unwrap(), f[3].parse().unwrap()])
        })
        .collect()
}

fn dist(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// Writes the robot's scans and IMU from a sim pcap into an MCAP, each scan after the IMU
/// samples up to its end (the order a live recorder sees them in).
fn record_robot(pcap: &Path, path: &Path) {
    use starc_pipeline::cloud::{CloudPoint, PointCloud};
    use starc_pipeline::record::{Recorder, RecorderOptions};
    use starc_time::{Clock, Stamp};
    let d = starc_bridge::decode_avia(pcap, std::net::Ipv4Addr::new(192, 168, 1, 101)).unwrap();
    let mut rec = Recorder::create(path, RecorderOptions::default()).unwrap();
    let mut imu = d.imu.iter().peekable();
    for scan in &d.scans {
        while let Some(s) = imu.next_if(|s| s.t_ns <= scan.end_ns) {
            rec.imu(Stamp::new(s.t_ns, Clock::Ptp), s.gyro_rad_s.into(), s.acc_m_s2.into()).unwrap();
        }
        let points = scan
            .points
            .iter()
            .map(|p| CloudPoint {
                x_m: p.x_m,
                y_m: p.y_m,
                z_m: p.z_m,
                offset_ns: (p.t_ns - scan.start_ns) as u32,
                ..CloudPoint::default()
            })
            .collect();
        rec.point_cloud(&PointCloud::new(Some(Stamp::new(scan.start_ns, Clock::Ptp)), points)).unwrap();
    }
    for s in imu {
        rec.imu(Stamp::new(s.t_ns, Clock::Ptp), s.gyro_rad_s.into(), s.acc_m_s2.into()).unwrap();
    }
    rec.finish().unwrap();
}
