//! The learned detector's time per window on one core, split into its stages, beside the
//! geometric detector (with its gates, and with the trees) on the same window and onnxruntime (one thread) on the same network.
//!
//! `cargo bench -p starc-pipeline --bench pillars [-- RUNS]` times RUNS (default 200) windows of
//! a synthetic room (about 60,000 returns, the size of the robot's 0.3 s window) with the
//! shipped weights, and prints the median and p99 of: the floor estimate and model frame, the
//! pillarization, the pillar feature net, the backbone and head, the decoding and NMS, each box's
//! points, and the whole detector. The
//! onnxruntime figure comes from scripts/train/onnx_reference.py in the peers' venv (.venv),
//! timing its own two sessions on the same pillars; it is left out when that venv is missing.
#![allow(clippy::unwrap_used, clippy::expect_used)]

#[path = "../tests/support/pillars_io.rs"]
#[allow(dead_code)] // read_f32_npy is the onnxruntime test's
mod pillars_io;
#[path = "../tests/support/room.rs"]
mod room;

use nalgebra::{Isometry3, Translation3, UnitQuaternion};
use starc_pipeline::detect::pillars::grid::pillarize;
use starc_pipeline::detect::pillars::PillarsDetector;
use starc_pipeline::detect::{DetectConfig, DetectWindow, Detector, DetectorKind, GeometricDetector, WindowPoint};
use starc_time::{Clock, Stamp};
use std::path::PathBuf;
use std::process::Command;
use std::time::Instant;

/// (median, p99) in ms.
fn spread(mut v: Vec<f64>) -> (f64, f64) {
    v.sort_by(f64::total_cmp);
    (v[v.len() / 2], v[(v.len() * 99 / 100).min(v.len() - 1)])
}

fn main() {
    let runs: usize = std::env::args().skip(1).find_map(|a| a.parse().ok()).unwrap_or(200);
    // The room's model frame is the world: the sensor 0.45 m over the floor at the origin,
    // looking along x; points fire 5 us apart over 0.3 s.
    let sensor = Isometry3::from_parts(Translation3::new(0.0, 0.0, 0.45), UnitQuaternion::identity());
    let points: Vec<WindowPoint> = room::room()
        .iter()
        .enumerate()
        .map(|(i, p)| WindowPoint { x_m: p[0], y_m: p[1], z_m: p[2], t_ns: 1_000_000_000 + i as u64 * 5_000 })
        .collect();
    let window = DetectWindow {
        stamp: Stamp::new(points.last().map_or(0, |p| p.t_ns), Clock::Ptp),
        sensor_pose: sensor,
        points: &points,
    };
    let cfg = DetectConfig::default();
    let mut pillars = PillarsDetector::new(&cfg).unwrap();
    let mut trees = GeometricDetector::new(DetectConfig { kind: DetectorKind::Trees, ..cfg.clone() }).unwrap();
    let mut geometric = GeometricDetector::new(DetectConfig { kind: DetectorKind::Geometric, ..cfg }).unwrap();
    let (mut found, mut stages, mut total, mut geo) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut scored = Vec::new();
    for _ in 0..runs {
        found.clear();
        let t0 = Instant::now();
        pillars.detect(&window, &mut found);
        total.push(t0.elapsed().as_secs_f64() * 1e3);
        stages.push(pillars.last_times());
        found.clear();
        let t0 = Instant::now();
        geometric.detect(&window, &mut found);
        geo.push(t0.elapsed().as_secs_f64() * 1e3);
        found.clear();
        let t0 = Instant::now();
        trees.detect(&window, &mut found);
        scored.push(t0.elapsed().as_secs_f64() * 1e3);
    }
    let model_points: Vec<[f32; 3]> = room::room();
    let p = pillarize(&model_points);
    println!("{runs} windows of {} returns, {} pillars; ms, median / p99:", points.len(), p.len());
    let line = |name: &str, v: Vec<f64>| {
        let (m, p99) = spread(v);
        println!("  {name:<28} {m:7.3} / {p99:7.3}");
        m
    };
    line("floor + model frame", stages.iter().map(|s| s.frame_ms).collect());
    line("pillarize", stages.iter().map(|s| s.pillarize_ms).collect());
    let pfn = line("pillar feature net", stages.iter().map(|s| s.net.pfn_ms).collect());
    let backbone = line("backbone + head", stages.iter().map(|s| s.net.backbone_ms).collect());
    line("decode + rotated NMS", stages.iter().map(|s| s.decode_ms).collect());
    line("each box's points", stages.iter().map(|s| s.points_ms).collect());
    line("pointpillars, whole window", total);
    line("geometric, same window", geo);
    line("trees, same window", scored);

    let root = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/.."));
    let python = root.join(".venv/bin/python");
    if !python.exists() {
        println!("  onnxruntime: no .venv (scripts/test.sh makes it): left out");
        return;
    }
    let dir = std::env::temp_dir().join(format!("starc-pillars-bench-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    pillars_io::write_inputs(&dir, &p);
    let out = Command::new(&python)
        .arg(root.join("scripts/train/onnx_reference.py"))
        .args(["--models", root.join("config/models").to_str().unwrap(), "--io", dir.to_str().unwrap()])
        .args(["--repeat", &runs.to_string()])
        .output()
        .unwrap();
    let _ = std::fs::remove_dir_all(&dir);
    let text = String::from_utf8_lossy(&out.stdout);
    print!("  {text}");
    if let Some(ms) = text.split("median ").nth(1).and_then(|t| t.split(' ').next()).and_then(|t| t.parse::<f64>().ok())
    {
        println!("  ours (pillar net + backbone) / onnxruntime: {:.2}", (pfn + backbone) / ms);
    }
}
