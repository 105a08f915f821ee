//! Decode throughput of the serial IMU stream decoders on one core.
//!
//! Run with `cargo bench -p starc-imu --bench decode`. Cases: MIP packets (accel + gyro + GPS
//! time, 48 bytes) and WitMotion cycles (acc + gyro + angle, 3 x 11 bytes), clean and with a
//! stray sync byte before every 5th sample, pushed in 64-byte reads. Figures are frames (MIP
//! packets or WitMotion frames) and samples per second, best of several ~100 ms batches.
//!
//! When `.venv` has PyPI `witmotion`, the same WitMotion bytes (with strays) are also run through
//! its receive loop (tests/peers/witmotion_decode_rate.py) for a side-by-side figure; it reads
//! byte by byte from a stand-in port, as it would from pyserial.

use starc_imu::mip::{GpsTime, MipData};
use starc_imu::timing::{LatencyModel, Timestamper};
use starc_imu::witmotion::frame::{WitFrame, TYPE_ACCEL, TYPE_ANGLE, TYPE_GYRO};
use starc_imu::{ImuDecoder, Protocol};
use starc_time::{Clock, Stamp};
use std::hint::black_box;
use std::time::{Duration, Instant};

const SAMPLES: u32 = 20_000;

fn mip_stream(strays: bool) -> Vec<u8> {
    let mut b = Vec::new();
    for k in 0..SAMPLES {
        if strays && k % 5 == 4 {
            b.push(0x75);
        }
        let d = MipData {
            accel_g: Some([k as f32 * 1e-4, 0.5, -1.0]),
            gyro_rad_s: Some([0.01, -0.02, k as f32 * 1e-5]),
            gps_time: Some(GpsTime { tow_s: f64::from(k) * 0.005, week: 2300, flags: 7 }),
            ..MipData::default()
        };
        if d.encode(&mut b).is_err() {
            return Vec::new();
        }
    }
    b
}

fn wit_stream(strays: bool) -> Vec<u8> {
    let mut b = Vec::new();
    for k in 0..SAMPLES {
        if strays && k % 5 == 4 {
            b.push(0x55);
        }
        let k = k as i16;
        for (t, v) in [(TYPE_ACCEL, [k, -k, 2048, 2500]), (TYPE_GYRO, [k, 1, -1, 2500]), (TYPE_ANGLE, [1, 2, k, 0])] {
            b.extend_from_slice(&WitFrame::from_values(t, v).encode());
        }
    }
    b
}

/// Best and median seconds of one pass over `bytes`, and the frames and samples of a pass.
fn measure(protocol: Protocol, bytes: &[u8]) -> (f64, f64, u64, u64) {
    let mut times = Vec::new();
    let mut out = Vec::with_capacity(1024);
    let (mut frames, mut samples) = (0, 0);
    let deadline = Instant::now() + Duration::from_millis(800);
    while Instant::now() < deadline || times.len() < 5 {
        let mut d = ImuDecoder::new(protocol, Timestamper::new(LatencyModel::new(921_600, 1_000_000)));
        let t0 = Instant::now();
        for (i, chunk) in bytes.chunks(64).enumerate() {
            d.push(chunk, Stamp::new(i as u64 * 100_000, Clock::Host), &mut out);
            black_box(&out);
            out.clear();
        }
        times.push(t0.elapsed().as_secs_f64());
        let s = d.stats();
        (frames, samples) = (s.frames, s.samples);
    }
    times.sort_by(f64::total_cmp);
    (times[0], times[times.len() / 2], frames, samples)
}

fn python_witmotion(bytes: &[u8]) -> Option<(u64, f64)> {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let python = root.join(".venv/bin/python");
    let script = root.join("tests/peers/witmotion_decode_rate.py");
    if !python.exists() {
        return None;
    }
    let path = std::env::temp_dir().join(format!("starc-imu-bench-{}.bin", std::process::id()));
    std::fs::write(&path, bytes).ok()?;
    let out = std::process::Command::new(python).arg(script).arg(&path).output().ok();
    let _ = std::fs::remove_file(&path);
    let text = String::from_utf8(out?.stdout).ok()?;
    // {"frames": N, "seconds": S}
    let frames = text.split("\"frames\": ").nth(1)?.split(',').next()?.trim().parse().ok()?;
    let seconds = text.split("\"seconds\": ").nth(1)?.trim_end_matches(['}', '\n']).trim().parse().ok()?;
    Some((frames, seconds))
}

fn main() {
    println!("serial IMU decode, {SAMPLES} samples per pass, 64-byte reads, one core");
    println!("{:<28} {:>14} {:>14} {:>10} {:>12}", "case", "frames/s", "samples/s", "MB/s", "median/best");
    let cases = [
        ("mip clean", Protocol::Mip, mip_stream(false)),
        ("mip 1 stray per 5", Protocol::Mip, mip_stream(true)),
        ("witmotion clean", Protocol::WitMotion, wit_stream(false)),
        ("witmotion 1 stray per 5", Protocol::WitMotion, wit_stream(true)),
    ];
    for (name, protocol, bytes) in &cases {
        let (best, median, frames, samples) = measure(*protocol, bytes);
        println!(
            "{name:<28} {:>14.0} {:>14.0} {:>10.1} {:>12.2}",
            frames as f64 / best,
            samples as f64 / best,
            bytes.len() as f64 / best / 1e6,
            median / best
        );
    }
    if let Some((_, _, bytes)) = cases.last() {
        match python_witmotion(bytes) {
            Some((frames, seconds)) => println!(
                "{:<28} {:>14.0} {:>14} {:>10.3}   (PyPI witmotion, same bytes: {frames} of {} frames decoded)",
                "python witmotion, strays",
                frames as f64 / seconds,
                "-",
                bytes.len() as f64 / seconds / 1e6,
                3 * SAMPLES
            ),
            None => println!("python witmotion: not run (.venv with witmotion missing)"),
        }
    }
}
