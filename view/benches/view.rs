//! What the live views cost (starc-view): publishing a 640 x 480 AR frame into the hub (PNG
//! encode and copy, once per frame however many viewers), converting and writing it to a
//! framebuffer (a file in /dev/shm standing in for the device), and the frame rate a browser
//! stream delivers on loopback when the renderer publishes at 30 Hz and as fast as it can.
//!
//! Run with `cargo bench -p starc-view --bench view`. The frame is a rendered scene (`ar::render`: ~20k rig
//! points, 3 people behind a wall, boxes and the status line), the camera swaying from frame
//! to frame so each PNG differs.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};
use starc_pipeline::ar::{render, ArFrame, ArPerson, ArStatus, CameraModel, OrientedBox, RenderConfig};
use starc_view::framebuffer::{FbGeometry, Framebuffer};
use starc_view::{ViewHub, ViewStatus};
use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::time::{Duration, Instant};

struct Rng(u64);

impl Rng {
    fn range(&mut self, lo: f64, hi: f64) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        let u = (self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 / (1u64 << 53) as f64;
        lo + (hi - lo) * u
    }
}

/// Frames of a room (walls, floor, ceiling, a dividing wall at x = 4 m) with three people
/// behind the wall, seen from eye height as the camera sways.
fn frames(n: usize) -> Vec<ArFrame> {
    let mut rng = Rng(0x9E37_79B9_7F4A_7C15);
    let rig: Vec<Vector3<f64>> = (0..20_000)
        .map(|i| match i % 6 {
            0 => Vector3::new(rng.range(-2.0, 10.0), rng.range(-4.0, 4.0), 0.0),
            1 => Vector3::new(rng.range(-2.0, 10.0), rng.range(-4.0, 4.0), 2.7),
            2 => Vector3::new(rng.range(-2.0, 10.0), 4.0, rng.range(0.0, 2.7)),
            3 => Vector3::new(rng.range(-2.0, 10.0), -4.0, rng.range(0.0, 2.7)),
            _ => Vector3::new(4.0, rng.range(-4.0, 4.0), rng.range(0.0, 2.7)),
        })
        .collect();
    let people: Vec<ArPerson> = [(6.0, 0.5), (7.5, -1.8), (8.5, 2.0)]
        .iter()
        .map(|&(x, y)| {
            let centre = Vector3::new(x, y, 0.875);
            ArPerson {
                points_world: (0..700)
                    .map(|_| {
                        centre + Vector3::new(rng.range(-0.2, 0.2), rng.range(-0.25, 0.25), rng.range(-0.875, 0.875))
                    })
                    .collect(),
                bbox: Some(OrientedBox { centre_m: centre, size_m: Vector3::new(0.4, 0.5, 1.75), yaw_rad: 0.3 }),
                age_ns: 80_000_000,
                pose: None,
            }
        })
        .collect();
    let optical = Matrix3::new(0.0, 0.0, 1.0, -1.0, 0.0, 0.0, 0.0, -1.0, 0.0);
    let optical = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(optical));
    let status = ArStatus { aligned: true, detection_age_ms: Some(80.0), link: "OK".into(), text: String::new() };
    let camera = CameraModel::default();
    (0..n)
        .map(|i| {
            let yaw = 0.1 * (i as f64 * 0.2).sin();
            let pose = Isometry3::from_parts(
                Translation3::new(0.0, 0.0, 1.6),
                UnitQuaternion::from_euler_angles(0.0, 0.0, yaw) * optical,
            );
            render(&camera, &pose, &rig, &people, &status, &RenderConfig::default())
        })
        .collect()
}

fn status(seq: u64) -> ViewStatus {
    ViewStatus {
        aligned: true,
        detection_age_ms: Some(80.0),
        link: "OK".into(),
        people: 3,
        frame_seq: seq,
        stamp_ns: seq,
    }
}

fn report(name: &str, mut times: Vec<Duration>) {
    times.sort();
    let q = |p: f64| times[((times.len() - 1) as f64 * p).round() as usize];
    println!("{name:<48} median {:>7.2} ms   p99 {:>7.2} ms", q(0.5).as_secs_f64() * 1e3, q(0.99).as_secs_f64() * 1e3);
}

/// Reads parts of the multipart stream for `secs`, returning how many arrived.
fn count_stream_parts(addr: std::net::SocketAddr, secs: f64) -> u64 {
    let s = TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
    (&s).write_all(b"GET /stream HTTP/1.1\r\n\r\n").unwrap();
    let mut r = BufReader::new(s);
    let (mut line, mut parts) = (String::new(), 0u64);
    let end = Instant::now() + Duration::from_secs_f64(secs);
    let mut len = None;
    while Instant::now() < end {
        line.clear();
        if r.read_line(&mut line).unwrap() == 0 {
            break;
        }
        if let Some(v) = line.strip_prefix("Content-Length: ") {
            len = Some(v.trim().parse::<usize>().unwrap());
        } else if line == "\r\n" {
            if let Some(n) = len.take() {
                let mut body = vec![0; n];
                r.read_exact(&mut body).unwrap();
                parts += 1;
            }
        }
    }
    parts
}

fn main() {
    let frames = frames(60);
    let hub = ViewHub::new();

    // 1. Publishing (a copy, per frame), and the PNG encode the first viewer of a frame pays.
    let (mut times, mut encode_times) = (Vec::new(), Vec::new());
    let mut png_bytes = 0;
    for round in 0..5u64 {
        for (i, f) in frames.iter().enumerate() {
            let t0 = Instant::now();
            let s = hub.publish(f, status(round * 100 + i as u64)).unwrap();
            times.push(t0.elapsed());
            let t0 = Instant::now();
            png_bytes += s.png().unwrap().len();
            encode_times.push(t0.elapsed());
        }
    }
    println!("PNG of a 640x480 AR frame: {} KiB on average", png_bytes / times.len() / 1024);
    report("hub.publish (copy), 640x480", times);
    report("snapshot.png() (PNG encode, once per frame, by its first viewer), 640x480", encode_times);

    // 2. Framebuffer: scale, convert, pwrite.
    let dir = std::env::temp_dir();
    let shm = if std::path::Path::new("/dev/shm").is_dir() { std::path::PathBuf::from("/dev/shm") } else { dir };
    for (w, h, bpp) in [(480u32, 320u32, 16u32), (800, 480, 32), (1920, 1080, 32)] {
        let device = shm.join(format!("starc_view_bench_fb_{}", std::process::id()));
        std::fs::write(&device, b"").unwrap();
        let stride = w * bpp / 8;
        let mut fb = Framebuffer::open_with_geometry(
            &device,
            FbGeometry { width: w, height: h, bits_per_pixel: bpp, stride_bytes: stride },
        )
        .unwrap();
        let mut times = Vec::new();
        for _ in 0..5 {
            for f in &frames {
                let t0 = Instant::now();
                fb.write_frame(f).unwrap();
                times.push(t0.elapsed());
            }
        }
        let _ = std::fs::remove_file(&device);
        report(&format!("framebuffer {w}x{h} at {bpp} bpp (convert + pwrite)"), times);
    }

    // 3. Browser stream on loopback.
    let rt = tokio::runtime::Builder::new_multi_thread().worker_threads(2).enable_all().build().unwrap();
    let (stop, shutdown) = tokio::sync::watch::channel(false);
    let (addr, _task) =
        rt.block_on(starc_view::serve_http("127.0.0.1:0".parse().unwrap(), hub.clone(), shutdown)).unwrap();
    for rate_hz in [Some(30.0), None] {
        let running = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(true));
        let publisher = {
            let (hub, frames, running) = (hub.clone(), frames.clone(), running.clone());
            std::thread::spawn(move || {
                let t0 = Instant::now();
                let mut k = 0u64;
                while running.load(std::sync::atomic::Ordering::Relaxed) {
                    hub.publish(&frames[k as usize % frames.len()], status(k)).unwrap();
                    k += 1;
                    if let Some(hz) = rate_hz {
                        let next = t0 + Duration::from_secs_f64(k as f64 / hz);
                        std::thread::sleep(next.saturating_duration_since(Instant::now()));
                    }
                }
                k as f64 / t0.elapsed().as_secs_f64()
            })
        };
        let secs = 3.0;
        let parts = count_stream_parts(addr, secs);
        running.store(false, std::sync::atomic::Ordering::Relaxed);
        let published_hz = publisher.join().unwrap();
        let label = rate_hz.map_or("as fast as possible".to_string(), |hz| format!("{hz} Hz"));
        println!(
            "browser stream, renderer at {label:<20} published {published_hz:>5.1} fps, stream delivered {:>5.1} fps",
            parts as f64 / secs
        );
    }
    stop.send(true).unwrap();
}
