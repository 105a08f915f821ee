//! Decode throughput of Livox data packets on one core, next to a plain memcpy of the same bytes.
//!
//! Run with `cargo bench -p starc-livox --bench decode`. Cases: realistic packets built with the
//! crate's encoder (extended Cartesian, dual Cartesian, extended spherical) and, when
//! shared/data is present, the real Tele-15 capture's point packets. Each case reports:
//!
//! - decode+timing: `DataPacket::parse` + `decode_points` into a reused Vec + absolute firing
//!   times into a reused Vec, in returns per second (empty returns included: they are decoded too);
//! - memcpy: copying the same packet bytes, and decode time over memcpy time;
//! - the scan assembler (decode, timing, filters, 100 ms scans), in returns per second.
//!
//! Timings are the best of several ~100 ms batches (about 0.7 s per measurement), which keeps out
//! most noise from other processes; the median is printed beside it.

use starc_livox::data::{encode_point_packet, DataHeader, DataPacket, DataType, Point, Return, StatusWord};
use starc_livox::scan::{ScanAssembler, ScanConfig};
use starc_time::{Clock, Stamp};
use std::hint::black_box;
use std::ops::Range;
use std::time::{Duration, Instant};

/// Packets of one case, stored back to back.
struct Case {
    name: String,
    bytes: Vec<u8>,
    packets: Vec<Range<usize>>,
    /// Returns per pass (all point packets).
    returns: u64,
}

/// A small deterministic generator (xorshift64*), so every run measures the same packets.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }

    /// Uniform in [0, 1).
    fn unit(&mut self) -> f32 {
        (self.next() >> 40) as f32 / (1u64 << 24) as f32
    }
}

/// `count` packets of an Avia-like scene: a rosette sweep over a 70 x 77 degree field of view,
/// ranges 1-80 m, about 2% empty returns, tags mostly 0x10 as in the real capture, timestamps
/// one packet interval apart.
fn synthetic(dt: DataType, count: usize) -> Option<Case> {
    let mut rng = Rng(0x5eed_0000 + dt as u64);
    let mut bytes = Vec::with_capacity(count * dt.packet_len());
    let mut packets = Vec::with_capacity(count);
    let mut firing = 0u64;
    for k in 0..count {
        let header = DataHeader {
            version: 5,
            slot: 1,
            lidar_id: 1,
            status: StatusWord::from_raw(1 << 14),
            data_type: dt,
            timestamp: Stamp::new(1_700_000_000_000_000_000 + k as u64 * dt.packet_interval_ns(), Clock::Ptp),
        };
        let mut returns = Vec::with_capacity(dt.returns_per_packet());
        for _ in 0..dt.firings_per_packet() {
            let t = firing as f32 * 1e-4;
            firing += 1;
            let az = (35.0 * (t * 7.3).sin() * (t * 0.91).cos()).to_radians();
            let el = (38.0 * (t * 7.3).sin() * (t * 0.91).sin()).to_radians();
            let range = 1.0 + 79.0 * rng.unit() * rng.unit();
            for echo in 0..dt.echoes() {
                let r = range + echo as f32 * 0.7;
                let tag = match rng.next() % 100 {
                    0..=1 => 0x18,
                    2..=3 => 0x00,
                    4 => 0x20,
                    _ => 0x10,
                };
                returns.push(if rng.next() % 50 == 7 {
                    Return::EMPTY
                } else {
                    Return {
                        x_m: r * el.cos() * az.cos(),
                        y_m: r * el.cos() * az.sin(),
                        z_m: r * el.sin(),
                        reflectivity: (rng.next() % 256) as u8,
                        tag,
                    }
                });
            }
        }
        let at = bytes.len();
        encode_point_packet(&header, &returns, &mut bytes).ok()?;
        packets.push(at..bytes.len());
    }
    let returns = (count * dt.returns_per_packet()) as u64;
    Some(Case { name: format!("{} (type {})", dt.name(), dt as u8), bytes, packets, returns })
}

/// The point packets of the real Tele-15 capture (classic pcap, Ethernet, IPv4, UDP).
fn real_capture() -> Option<Case> {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/livox/tele15_small.pcap");
    let file = std::fs::read(&path).ok()?;
    let mut bytes = Vec::new();
    let mut packets = Vec::new();
    let mut returns = 0u64;
    let mut at = 24usize;
    while let Some(rec) = file.get(at..at + 16) {
        let incl = u32::from_le_bytes([rec[8], rec[9], rec[10], rec[11]]) as usize;
        let frame = file.get(at + 16..at + 16 + incl)?;
        at += 16 + incl;
        let ihl = usize::from(frame.get(14)? & 0x0f) * 4;
        let payload = frame.get(14 + ihl + 8..)?;
        if let Ok(p) = DataPacket::parse(payload) {
            if !p.is_imu() {
                returns += p.header.data_type.returns_per_packet() as u64;
                let start = bytes.len();
                bytes.extend_from_slice(payload);
                packets.push(start..bytes.len());
            }
        }
    }
    Some(Case { name: "real Tele-15 capture (type 2)".into(), bytes, packets, returns })
}

/// Runs `pass` in batches of about 100 ms for about `total`; returns (best, median) seconds per pass.
fn measure(total: Duration, mut pass: impl FnMut()) -> (f64, f64) {
    let t0 = Instant::now();
    pass();
    let one = t0.elapsed().as_secs_f64().max(1e-7);
    let per_batch = ((0.1 / one) as usize).max(1);
    let mut samples = Vec::new();
    let start = Instant::now();
    while start.elapsed() < total || samples.len() < 3 {
        let t = Instant::now();
        for _ in 0..per_batch {
            pass();
        }
        samples.push(t.elapsed().as_secs_f64() / per_batch as f64);
    }
    samples.sort_by(f64::total_cmp);
    (samples[0], samples[samples.len() / 2])
}

fn rate(n: u64, secs: f64) -> String {
    let r = n as f64 / secs;
    if r >= 1e9 {
        format!("{:7.2} G", r / 1e9)
    } else {
        format!("{:7.1} M", r / 1e6)
    }
}

fn run_case(case: &Case, budget: Duration) {
    let mut points: Vec<Point> = Vec::with_capacity(400);
    let mut times: Vec<u64> = Vec::with_capacity(400);
    let decode = measure(budget, || {
        for r in &case.packets {
            let Ok(p) = DataPacket::parse(black_box(&case.bytes[r.clone()])) else { continue };
            points.clear();
            let counts = p.decode_points(&mut points);
            let base = p.header.timestamp.ns;
            times.clear();
            times.extend(points.iter().map(|pt| base + u64::from(pt.offset_ns)));
            black_box((&points, &times, counts));
        }
    });

    let mut dst = vec![0u8; case.bytes.len()];
    let memcpy = measure(budget, || {
        for r in &case.packets {
            dst[r.clone()].copy_from_slice(black_box(&case.bytes[r.clone()]));
            black_box(&dst);
        }
    });

    // The assembler needs time to move forward: each pass shifts every packet time by one span.
    let mut work = case.bytes.clone();
    let span = case.packets.iter().filter_map(|r| DataPacket::parse(&case.bytes[r.clone()]).ok()).fold(
        (u64::MAX, 0u64),
        |(lo, hi), p| {
            (lo.min(p.header.timestamp.ns), hi.max(p.header.timestamp.ns + p.header.data_type.packet_interval_ns()))
        },
    );
    let span_ns = span.1.saturating_sub(span.0);
    let mut assembler = ScanAssembler::new(ScanConfig::default()).ok();
    let mut done = Vec::new();
    let mut pass_no = 0u64;
    let mut scans = 0usize;
    let mut kept = 0usize;
    let assemble = measure(budget, || {
        pass_no += 1;
        let Some(a) = assembler.as_mut() else { return };
        for r in &case.packets {
            let Some(pkt) = work.get_mut(r.clone()) else { continue };
            let Some(ts) = pkt.get_mut(10..18) else { continue };
            let mut raw = [0u8; 8];
            raw.copy_from_slice(ts);
            ts.copy_from_slice(&u64::from_le_bytes(raw).wrapping_add(span_ns).to_le_bytes());
            if let Ok(p) = DataPacket::parse(pkt) {
                a.push(&p, None, &mut done);
            }
        }
        scans += done.len();
        kept += done.iter().map(|s| s.points.len()).sum::<usize>();
        done.clear();
    });

    let n = case.returns;
    let kept_share = if scans > 0 { kept as f64 / (pass_no as f64 * n as f64) * 100.0 } else { 0.0 };
    println!("{}: {} packets, {} returns, {} bytes per pass", case.name, case.packets.len(), n, case.bytes.len());
    println!(
        "  decode+timing  {}returns/s  ({:6.2} GB/s of packets; median {}returns/s)",
        rate(n, decode.0),
        case.bytes.len() as f64 / decode.0 / 1e9,
        rate(n, decode.1),
    );
    println!(
        "  memcpy         {}returns/s  ({:6.2} GB/s; median {:6.2} GB/s)",
        rate(n, memcpy.0),
        case.bytes.len() as f64 / memcpy.0 / 1e9,
        case.bytes.len() as f64 / memcpy.1 / 1e9,
    );
    println!("  decode / memcpy time: {:.1}x", decode.0 / memcpy.0);
    println!(
        "  scan assembler {}returns/s  (median {}returns/s; {scans} scans, {kept_share:.0}% of returns kept)",
        rate(n, assemble.0),
        rate(n, assemble.1),
    );
}

fn main() {
    // `cargo bench` passes `--bench`; a name filter may follow.
    let filter: Option<String> = std::env::args().skip(1).find(|a| !a.starts_with('-'));
    let budget = Duration::from_millis(700);
    let mut cases: Vec<Case> = [DataType::ExtendedCartesian, DataType::DualCartesian, DataType::ExtendedSpherical]
        .into_iter()
        .filter_map(|dt| synthetic(dt, 1000))
        .collect();
    match real_capture() {
        Some(c) => cases.push(c),
        None => println!("(shared/data/livox/tele15_small.pcap is absent: no real-capture case)"),
    }
    println!("Livox data packet decode, one core, best of ~100 ms batches over {} ms per figure", budget.as_millis());
    for case in cases.iter().filter(|c| filter.iter().all(|f| c.name.contains(f.as_str()))) {
        run_case(case, budget);
    }
}
