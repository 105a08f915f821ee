//! The alignment peers (tests/peers/align_peers.py: PyPI `small-gicp` and `open3d-cpu`
//! point-to-plane ICP) run on a synthetic room from an easy start, and agree with our aligner
//! and with the known transform. This is what the grid bench (`cargo bench -p starc-pipeline
//! --bench align_grid`) relies on; here it runs in a few seconds.
//!
//! The peers run from `.venv/bin/python` (installed by .ci/run from tests/peers/requirements.txt);
//! a missing package fails the test (the bench cannot compare without it).

#![allow(clippy::unwrap_used, clippy::expect_used)]

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion};
use starc_pipeline::align::{pose_error, pose_from_rows, pose_rows, AlignConfig, Aligner, Vec3};
use std::io::Write;
use std::path::PathBuf;
use std::process::Command;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Four walls, floor, ceiling, two boxes and a pillar: constrained in every direction.
fn room() -> Vec<Vec3> {
    let mut pts = Vec::new();
    let step = 0.05;
    for i in 0..=200 {
        for j in 0..=56 {
            let (a, z) = (-5.0 + f64::from(i) * step, f64::from(j) * step);
            pts.push(Vec3::new(a, -4.0, z));
            pts.push(Vec3::new(a, 4.0, z));
            pts.push(Vec3::new(-5.0, a * 0.8, z));
            pts.push(Vec3::new(5.0, a * 0.8, z));
        }
    }
    for i in 0..=100 {
        for j in 0..=80 {
            let (x, y) = (-5.0 + f64::from(i) * 0.1, -4.0 + f64::from(j) * 0.1);
            pts.push(Vec3::new(x, y, 0.0));
            pts.push(Vec3::new(x, y, 2.8));
        }
    }
    for i in 0..=20 {
        for j in 0..=20 {
            let (a, b) = (f64::from(i) * step, f64::from(j) * step);
            pts.push(Vec3::new(1.0 + a, 1.0 + b, 1.0));
            pts.push(Vec3::new(1.0, 1.0 + a, b));
            pts.push(Vec3::new(1.0 + a, 1.0, b));
            pts.push(Vec3::new(-3.0 + a, -2.0, b * 1.5));
            pts.push(Vec3::new(-3.0, -2.0 + a, b * 1.5));
            pts.push(Vec3::new(3.0 + a * 0.3, -1.0, b * 2.8));
            pts.push(Vec3::new(3.0, -1.0 + a * 0.3, b * 2.8));
        }
    }
    pts
}

fn write_f64(path: &std::path::Path, pts: &[Vec3]) {
    let bytes: Vec<u8> = pts.iter().flat_map(|p| [p.x, p.y, p.z]).flat_map(f64::to_le_bytes).collect();
    std::fs::write(path, bytes).unwrap();
}

#[test]
fn small_gicp_and_open3d_agree_with_us_on_an_easy_start() {
    let python = root().join(".venv/bin/python");
    let probe = Command::new(&python).args(["-c", "import small_gicp, open3d"]).output();
    assert!(
        probe.as_ref().is_ok_and(|o| o.status.success()),
        "small-gicp / open3d-cpu missing from .venv (pip install -r tests/peers/requirements.txt; Open3D needs libusb-1.0-0): {probe:?}"
    );

    let target = room();
    let truth = Isometry3::from_parts(
        Translation3::new(0.25, -0.15, 0.05),
        UnitQuaternion::from_euler_angles(0.01, -0.01, 0.12),
    );
    let inv = truth.inverse();
    let source: Vec<Vec3> = target.iter().map(|p| (inv * Point3::from(*p)).coords).collect();
    // The easy start: the truth off by 10 cm and 2 deg.
    let start =
        Isometry3::from_parts(Translation3::new(0.1, 0.0, 0.0), UnitQuaternion::from_euler_angles(0.0, 0.0, 0.035))
            * truth;

    let ours = Aligner::new(&target, AlignConfig::default()).unwrap().align(&source, &start);
    let (ours_m, ours_deg) = pose_error(&ours.pose, &truth);
    assert!(ours.accepted && ours_m < 0.01 && ours_deg < 0.1, "ours: {ours_m} m {ours_deg} deg");

    let dir = tempfile::tempdir().unwrap();
    write_f64(&dir.path().join("source.f64"), &source);
    write_f64(&dir.path().join("target.f64"), &target);
    let mut seeds = std::fs::File::create(dir.path().join("seeds.txt")).unwrap();
    let row: Vec<String> = pose_rows(&start).iter().flatten().map(|v| format!("{v:.17e}")).collect();
    writeln!(seeds, "{}", row.join(" ")).unwrap();
    drop(seeds);
    let out = Command::new(&python)
        .arg(root().join("tests/peers/align_peers.py"))
        .arg(dir.path())
        .env("OMP_NUM_THREADS", "1")
        .output()
        .unwrap();
    assert!(out.status.success(), "align_peers.py: {}", String::from_utf8_lossy(&out.stderr));
    let mut seen = Vec::new();
    for line in String::from_utf8_lossy(&out.stdout).lines() {
        let v: serde_json::Value = serde_json::from_str(line).unwrap();
        let Some(t) = v["T"].as_array() else { continue };
        let peer = v["peer"].as_str().unwrap().to_string();
        let mut rows = [[0.0; 4]; 4];
        for (i, x) in t.iter().enumerate() {
            rows[i / 4][i % 4] = x.as_f64().unwrap();
        }
        let pose = pose_from_rows(&rows).unwrap();
        let (m, deg) = pose_error(&pose, &truth);
        let (dm, ddeg) = pose_error(&pose, &ours.pose);
        println!(
            "{peer}: {:.2} cm {:.3} deg from the truth, {:.2} cm {:.3} deg from ours",
            m * 100.0,
            deg,
            dm * 100.0,
            ddeg
        );
        assert!(m < 0.02 && deg < 0.2, "{peer} off the truth: {m} m {deg} deg");
        assert!(dm < 0.02 && ddeg < 0.2, "{peer} disagrees with ours: {dm} m {ddeg} deg");
        assert!(v["ms"].as_f64().is_some_and(|ms| ms > 0.0));
        seen.push(peer);
    }
    assert_eq!(seen, ["small_gicp", "open3d"]);
}
