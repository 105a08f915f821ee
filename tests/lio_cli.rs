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
    // The map reads back with our own reader.
    let map = starc_pipeline::cloud::read(&out.join("192.168.1.101_map.pcd")).unwrap();
    assert!(map.len() > 1000, "{} map points", map.len());

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
