//! The Rust PointPillars inference against the reference runtime: the shipped weights
//! (config/models/pillars.stpw) run here, and the same network exported as ONNX
//! (config/models/pfn.onnx, backbone.onnx) run by onnxruntime from the peers' venv, on the same
//! pillars of a synthetic room; both stages must agree.

use starc_pipeline::detect::pillars::grid::pillarize;
use starc_pipeline::detect::pillars::net::{Net, HEAD_CHANNELS, HEAD_GRID, PILLAR_CHANNELS};
use starc_pipeline::detect::pillars::weights::Weights;
use std::path::PathBuf;
use std::process::Command;

#[path = "support/room.rs"]
mod room;
use room::room;
#[path = "support/pillars_io.rs"]
mod pillars_io;
use pillars_io::{read_f32_npy, write_inputs};

fn root() -> PathBuf {
    PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/.."))
}

fn assert_close(what: &str, ours: &[f32], reference: &[f32]) {
    assert_eq!(ours.len(), reference.len(), "{what}: lengths");
    let scale = reference.iter().fold(1.0f32, |m, v| m.max(v.abs()));
    let worst = ours.iter().zip(reference).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
    println!("{what}: {} values, largest |value| {scale:.3}, max abs difference {worst:.2e}", ours.len());
    assert!(worst <= 1e-4 * scale, "{what}: max abs difference {worst} (scale {scale})");
}

#[test]
fn the_rust_network_matches_onnxruntime_on_the_shipped_weights() {
    let models = root().join("config/models");
    let bytes = std::fs::read(models.join("pillars.stpw")).unwrap_or_else(|e| panic!("pillars.stpw: {e}"));
    let weights = Weights::parse(&bytes).unwrap_or_else(|e| panic!("{e}"));
    let net = Net::load(&weights).unwrap_or_else(|e| panic!("{e}"));
    let pillars = pillarize(&room());
    assert!(pillars.len() > 1_000, "{} pillars", pillars.len());

    let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
    write_inputs(dir.path(), &pillars);

    let python = root().join(".venv/bin/python");
    let out = Command::new(&python)
        .arg(root().join("scripts/train/onnx_reference.py"))
        .arg("--models")
        .arg(&models)
        .arg("--io")
        .arg(dir.path())
        .output()
        .unwrap_or_else(|e| panic!("{}: {e} (the peers' venv: scripts/test.sh makes it)", python.display()));
    assert!(out.status.success(), "onnx_reference.py failed: {}", String::from_utf8_lossy(&out.stderr));

    let features = net.pillar_features(&pillars);
    assert_eq!(features.len(), pillars.len() * PILLAR_CHANNELS);
    assert_close("pillar features", &features, &read_f32_npy(&dir.path().join("pillar_features.npy")));
    let head = net.backbone(&Net::canvas(&pillars, &features));
    assert_eq!((head.channels, head.rows, head.cols), (HEAD_CHANNELS, HEAD_GRID, HEAD_GRID));
    assert_close("head", &head.values, &read_f32_npy(&dir.path().join("head.npy")));
}
