//! Recording throughput: 10 s of a realistic mix (Avia scans at 10 Hz with 24 000 points each,
//! IMU at 200 Hz) written to MCAP with and without LZ4, then read back and decoded. Two scan
//! sources: synthetic scans where every point is a return, and the real Avia frame in
//! shared/data/livox/avia_frame.pcd repeated (21 187 of its 24 000 points have no return).
//!
//! Run with `cargo bench -p starc-pipeline --bench record`. Prints per configuration: wall time,
//! messages/s, payload MB/s (CDR bytes handed to the writer), file MB/s and file size, and the
//! part spent in CDR encoding alone; then the read-back rate, from memory and streamed from the
//! file. Files go to the temp directory (page cache); `none+sync` is `sync_chunks: true`, an
//! fdatasync per chunk: what surviving a power cut costs on this disk. With `STARC_BENCH_PY=1` it also times the PyPI `mcap` writer
//! writing the very same payloads (tests/peers/mcap_write_bench.py, run from `.venv/bin/python`).
#![allow(clippy::unwrap_used, clippy::expect_used)]

use starc_pipeline::cloud::{CloudPoint, PointCloud};
use starc_pipeline::record::msgs::{Header, RosMessage, Time};
use starc_pipeline::record::reader::{self, ReadMode};
use starc_pipeline::record::writer::cloud_to_msg;
use starc_pipeline::record::{ChunkCompression, Recorder, RecorderOptions};
use starc_time::{Clock, Stamp};
use std::path::Path;
use std::time::Instant;

const SECONDS: u64 = 10;
const POINTS_PER_SCAN: usize = 24_000;
const T0_NS: u64 = 1_763_719_200_000_000_000;

/// A scan that compresses like a real one: ranges from a room with noise, a rosette-like
/// direction pattern, Livox-style intensities, lines and offsets.
fn scan(k: u64, seed: &mut u64) -> PointCloud {
    let points = (0..POINTS_PER_SCAN)
        .map(|i| {
            *seed ^= *seed << 13;
            *seed ^= *seed >> 7;
            *seed ^= *seed << 17;
            let noise = (*seed >> 40) as f32 / (1u64 << 24) as f32 - 0.5;
            let a = i as f32 * 0.001_3 + k as f32 * 0.37;
            let (az, el) = (0.6 * (a * 3.1).sin() * a.cos(), 0.6 * (a * 3.1).sin() * a.sin());
            let range = 3.0 + 4.0 * (az * 2.0).cos().abs() + 0.02 * noise;
            CloudPoint {
                x_m: range * el.cos() * az.cos(),
                y_m: range * el.cos() * az.sin(),
                z_m: range * el.sin(),
                intensity: ((*seed >> 16) % 160) as f32,
                offset_ns: (i as u32) * 4_166,
                line: (i % 6) as u8,
                tag: 0,
            }
        })
        .collect();
    PointCloud::new(Some(Stamp::new(T0_NS + k * 100_000_000, Clock::Ptp)), points)
}

fn write(path: &Path, compression: ChunkCompression, sync_chunks: bool, scans: &[PointCloud]) -> (f64, u64) {
    let options = RecorderOptions { compression, sync_chunks, ..RecorderOptions::default() };
    let t = Instant::now();
    let mut rec = Recorder::create(path, options).unwrap();
    for i in 0..SECONDS * 200 {
        let ns = T0_NS + i * 5_000_000;
        rec.imu(Stamp::new(ns, Clock::Ptp), [0.001, -0.002, 0.01], [0.05, -0.02, 9.81]).unwrap();
        if i % 20 == 0 {
            rec.point_cloud(&scans[(i / 20) as usize]).unwrap();
        }
    }
    let stats = rec.finish().unwrap();
    (t.elapsed().as_secs_f64(), stats.payload_bytes)
}

/// The real Avia frame (shared/data/livox/avia_frame.pcd), repeated with the scan's stamps and
/// per-point offsets; its no-return points (0, 0, 0) are kept, as the file has them.
fn real_scans() -> Option<Vec<PointCloud>> {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/livox/avia_frame.pcd");
    let frame = starc_pipeline::cloud::read(&path).ok()?;
    let zero = frame.points.iter().filter(|p| p.is_zero()).count();
    println!("real frame: {} points, {zero} without a return ({})", frame.len(), path.display());
    Some(
        (0..SECONDS * 10)
            .map(|k| {
                let mut points = frame.points.clone();
                for (i, p) in points.iter_mut().enumerate() {
                    p.offset_ns = i as u32 * 4_166;
                }
                PointCloud::new(Some(Stamp::new(T0_NS + k * 100_000_000, Clock::Ptp)), points)
            })
            .collect(),
    )
}

fn main() {
    let mut seed = 0x9e37_79b9_7f4a_7c15_u64;
    let synthetic: Vec<PointCloud> = (0..SECONDS * 10).map(|k| scan(k, &mut seed)).collect();
    run_mix("synthetic scans (every point a return)", &synthetic);
    match real_scans() {
        Some(real) => run_mix("the real Avia frame, repeated", &real),
        None => println!("real frame not found: skipped"),
    }
}

fn run_mix(label: &str, scans: &[PointCloud]) {
    println!("\n== {label} ==");
    let messages = SECONDS * (200 + 10);
    let dir = std::env::temp_dir().join(format!("starc-record-bench-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    println!(
        "mix: {SECONDS} s of Avia scans at 10 Hz x {POINTS_PER_SCAN} points + IMU at 200 Hz = {messages} messages; files in {}",
        dir.display()
    );

    // CDR encoding alone (the scan part dominates).
    let t = Instant::now();
    let mut encoded = 0usize;
    for s in scans {
        let header = Header { stamp: Time::from_ns(s.start.unwrap().ns).unwrap(), frame_id: "avia".into() };
        encoded += cloud_to_msg(s, header).to_cdr().len();
    }
    let enc_s = t.elapsed().as_secs_f64();
    println!(
        "encode only: {} scans, {:.1} MB of CDR in {:.1} ms = {:.0} MB/s",
        scans.len(),
        encoded as f64 / 1e6,
        enc_s * 1e3,
        encoded as f64 / 1e6 / enc_s
    );

    let configs = [
        ("none", ChunkCompression::None, false),
        ("lz4", ChunkCompression::Lz4, false),
        ("none+sync", ChunkCompression::None, true),
    ];
    for (name, compression, sync) in configs {
        let path = dir.join(format!("mix_{name}.mcap"));
        let mut best = f64::MAX;
        let mut payload = 0;
        for _ in 0..3 {
            let (s, p) = write(&path, compression, sync, scans);
            best = best.min(s);
            payload = p;
        }
        let file = std::fs::metadata(&path).unwrap().len();
        println!(
            "write {name:<9}: best of 3 {:7.1} ms = {:8.0} msg/s, payload {:6.0} MB/s, file {:6.0} MB/s, file {:.1} MB ({:.0}% of payload); {:.1}x real time",
            best * 1e3,
            messages as f64 / best,
            payload as f64 / 1e6 / best,
            file as f64 / 1e6 / best,
            file as f64 / 1e6,
            100.0 * file as f64 / payload as f64,
            SECONDS as f64 / best
        );

        let bytes = reader::read_file(&path).unwrap();
        let t = Instant::now();
        let mut n = 0u64;
        for m in reader::messages(&bytes, ReadMode::Strict).unwrap() {
            m.unwrap().decode().unwrap();
            n += 1;
        }
        let s = t.elapsed().as_secs_f64();
        assert_eq!(n, messages);
        println!(
            "read  {name:<9}: {:7.1} ms = {:8.0} msg/s, {:6.0} MB/s of payload (scan + typed decode, from memory)",
            s * 1e3,
            n as f64 / s,
            payload as f64 / 1e6 / s
        );
        let t = Instant::now();
        let mut n = 0u64;
        for m in reader::open(&path, ReadMode::Strict).unwrap() {
            m.unwrap().decode().unwrap();
            n += 1;
        }
        let s = t.elapsed().as_secs_f64();
        assert_eq!(n, messages);
        println!(
            "stream {name:<8}: {:7.1} ms = {:8.0} msg/s, {:6.0} MB/s of payload (scan + typed decode, file streamed)",
            s * 1e3,
            n as f64 / s,
            payload as f64 / 1e6 / s
        );
    }

    if std::env::var_os("STARC_BENCH_PY").is_some() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
        let out = std::process::Command::new(root.join(".venv/bin/python"))
            .arg(root.join("tests/peers/mcap_write_bench.py"))
            .arg(dir.join("mix_none.mcap"))
            .arg(dir.join("py_out.mcap"))
            .output()
            .expect("running .venv/bin/python");
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        print!("{}", String::from_utf8_lossy(&out.stdout));
    }
    let _ = std::fs::remove_dir_all(&dir);
}
