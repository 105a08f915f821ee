//! Stream decoder tests: any chunking, every event kind, resynchronisation properties over many
//! seeded random streams (garbage, stray sync bytes, lost bytes, flipped bytes), time stamps.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use crate::mip::command::{MipReply, BASE_SET, CMD_IMU_BASE_RATE, CMD_PING, DM3_SET, NACK_UNKNOWN_COMMAND};
use crate::mip::{GpsTime, MipData, MipDecoder, PacketWriter, ReplyData};
use crate::sample::{ImuEvent, RawSample, STANDARD_GRAVITY_M_S2};
use crate::timing::{LatencyModel, Timestamper};
use crate::witmotion::frame::{self, WitFrame, TYPE_ACCEL, TYPE_ANGLE, TYPE_GYRO, TYPE_QUATERNION};
use crate::witmotion::WitDecoder;
use crate::{ImuDecoder, Protocol};
use starc_time::{Clock, Stamp};

/// xorshift64*: a deterministic generator for random streams.
struct Rng(u64);

impl Rng {
    fn new(seed: u64) -> Self {
        Self(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1)
    }
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }
    fn byte(&mut self) -> u8 {
        self.next() as u8
    }
    fn chance(&mut self, p: f64) -> bool {
        (self.next() >> 11) as f64 / (1u64 << 53) as f64 > 1.0 - p
    }
}

fn no_latency() -> Timestamper {
    Timestamper::new(LatencyModel::new(0, 0))
}

fn host(ns: u64) -> Stamp {
    Stamp::new(ns, Clock::Host)
}

/// Pushes `bytes` in random chunks (1..=max) and returns the events.
fn push_chunked(d: &mut ImuDecoder, bytes: &[u8], rng: &mut Rng, max: usize) -> Vec<ImuEvent> {
    let mut out = Vec::new();
    let mut rest = bytes;
    let mut t = 1_000_000_000;
    while !rest.is_empty() {
        let n = (1 + rng.below(max)).min(rest.len());
        let (now, later) = rest.split_at(n);
        d.push(now, host(t), &mut out);
        rest = later;
        t += 1_000_000;
    }
    out
}

fn samples(events: &[ImuEvent]) -> Vec<&crate::ImuSample> {
    events
        .iter()
        .filter_map(|e| match e {
            ImuEvent::Sample(s) => Some(s),
            _ => None,
        })
        .collect()
}

// ---------------------------------------------------------------------------------------------
// MIP

fn mip_data(k: u32) -> MipData {
    MipData {
        accel_g: Some([k as f32 * 1e-3, 0.5, -1.0]),
        gyro_rad_s: Some([k as f32 * 1e-4, -0.25, 0.125]),
        gps_time: Some(GpsTime { tow_s: f64::from(k) * 0.01, week: 2300, flags: 7 }),
        ..MipData::default()
    }
}

fn mip_packet(k: u32) -> Vec<u8> {
    let mut b = Vec::new();
    mip_data(k).encode(&mut b).unwrap();
    b
}

fn mip_tow_index(e: &crate::ImuSample) -> u32 {
    match &e.raw {
        RawSample::Mip(d) => (d.gps_time.unwrap().tow_s * 100.0).round() as u32,
        RawSample::WitMotion(_) => panic!("not MIP"),
    }
}

#[test]
fn mip_any_chunking_gives_the_same_events() {
    let mut bytes = Vec::new();
    for k in 0..50 {
        bytes.extend(mip_packet(k));
        if k % 10 == 3 {
            MipReply::ack(BASE_SET, CMD_PING, None).encode(&mut bytes).unwrap();
        }
    }
    let mut reference = None;
    for max in [1, 2, 3, 7, 36, 37, 100, 5000] {
        let mut d = ImuDecoder::new(Protocol::Mip, no_latency());
        let mut rng = Rng::new(max as u64);
        let events = push_chunked(&mut d, &bytes, &mut rng, max);
        let s = d.stats();
        assert_eq!((s.samples, s.replies, s.frames), (50, 5, 55));
        assert_eq!((s.bad_checksums, s.resyncs, s.skipped_bytes, s.malformed), (0, 0, 0, 0));
        assert_eq!(s.bytes, bytes.len() as u64);
        let idx: Vec<u32> = samples(&events).iter().map(|s| mip_tow_index(s)).collect();
        assert_eq!(idx, (0..50).collect::<Vec<_>>());
        // Everything but the host times is independent of the chunking.
        let values: Vec<_> =
            samples(&events).iter().map(|s| (s.gyro_rad_s, s.accel_m_s2, s.device_ns, s.raw.clone())).collect();
        match &reference {
            None => reference = Some(values),
            Some(r) => assert_eq!(r, &values, "chunks of up to {max}"),
        }
    }
}

#[test]
fn mip_samples_are_in_si_units_with_raw_values_kept() {
    let data = MipData {
        accel_g: Some([0.0, 0.5, -1.0]),
        gyro_rad_s: Some([0.1, -0.2, 0.3]),
        mag_gauss: Some([0.2, 0.0, 0.4]),
        quaternion: Some([0.5, 0.5, -0.5, 0.5]),
        euler_rad: Some([0.1, 0.2, -3.0]),
        gps_time: Some(GpsTime { tow_s: 10.5, week: 2, flags: 7 }),
        unknown_fields: 0,
    };
    let mut bytes = Vec::new();
    data.encode(&mut bytes).unwrap();
    let mut d = MipDecoder::new(no_latency());
    let mut out = Vec::new();
    d.push(&bytes, host(5), &mut out);
    let [ImuEvent::Sample(s)] = out.as_slice() else { panic!("{out:?}") };
    assert_eq!(s.accel_m_s2, [0.0, 0.5 * STANDARD_GRAVITY_M_S2, -STANDARD_GRAVITY_M_S2]);
    assert_eq!(s.gyro_rad_s, [0.1f32, -0.2, 0.3].map(f64::from));
    assert_eq!(s.orientation_wxyz, Some([0.5, 0.5, -0.5, 0.5]));
    assert_eq!(s.euler_rad, Some([0.1f32, 0.2, -3.0].map(f64::from)));
    assert_eq!(s.device_ns, Some((2 * 604_800 + 10) * 1_000_000_000 + 500_000_000));
    assert_eq!(s.raw, RawSample::Mip(data));
    assert_eq!((s.stamp, s.host_receive), (host(5), host(5)));
}

#[test]
fn mip_nan_and_infinite_readings_are_dropped_and_counted() {
    let good = |k: u32| MipData { quaternion: Some([1.0, 0.0, 0.0, 0.0]), ..mip_data(k) };
    let packets = [
        good(0),
        MipData { gyro_rad_s: Some([f32::NAN, 0.0, 0.0]), ..good(1) },
        MipData { accel_g: Some([0.0, f32::INFINITY, -1.0]), ..good(2) },
        MipData { accel_g: Some([0.0, 0.0, f32::NEG_INFINITY]), gyro_rad_s: Some([f32::NAN; 3]), ..good(3) },
        // Rates fine, the device's orientation not: the sample goes out without it.
        MipData { quaternion: Some([f32::NAN, 0.0, 0.0, 0.0]), euler_rad: Some([0.0, f32::INFINITY, 0.0]), ..good(4) },
        good(5),
    ];
    let mut bytes = Vec::new();
    for p in &packets {
        p.encode(&mut bytes).unwrap();
    }
    let mut d = ImuDecoder::new(Protocol::Mip, no_latency());
    let events = push_chunked(&mut d, &bytes, &mut Rng::new(3), 40);
    let out = samples(&events);
    assert_eq!(out.iter().map(|s| mip_tow_index(s)).collect::<Vec<_>>(), vec![0, 4, 5]);
    for s in &out {
        assert!(s.gyro_rad_s.iter().chain(s.accel_m_s2.iter()).all(|v| v.is_finite()), "{s:?}");
        assert!(s.orientation_wxyz.is_none_or(|q| q.iter().all(|v| v.is_finite())));
        assert!(s.euler_rad.is_none_or(|e| e.iter().all(|v| v.is_finite())));
    }
    assert_eq!(
        (out[0].orientation_wxyz, out[1].orientation_wxyz, out[1].euler_rad),
        (Some([1.0, 0.0, 0.0, 0.0]), None, None)
    );
    let st = d.stats();
    assert_eq!((st.samples, st.non_finite, st.non_finite_orientation, st.frames), (3, 3, 1, 6));
}

#[test]
fn mip_replies_incomplete_unknown_and_malformed_packets() {
    let mut bytes = Vec::new();
    MipReply::ack(DM3_SET, CMD_IMU_BASE_RATE, Some(ReplyData::ImuBaseRate(1000))).encode(&mut bytes).unwrap();
    MipReply::nack(BASE_SET, 0x03, NACK_UNKNOWN_COMMAND).encode(&mut bytes).unwrap();
    MipData { accel_g: Some([0.0; 3]), ..MipData::default() }.encode(&mut bytes).unwrap();
    let mut w = PacketWriter::new(0x82); // estimation filter data: not decoded
    w.field(0x03, &[0; 16]).unwrap();
    w.finish(&mut bytes);
    let mut w = PacketWriter::new(0x80); // gyro field of the wrong length
    w.field(0x05, &[0; 8]).unwrap();
    w.finish(&mut bytes);
    // A field that runs past the payload, under a good checksum.
    let mut bad = vec![0x75, 0x65, 0x80, 0x03, 0x05, 0x04, 0x00];
    bad.extend(crate::mip::fletcher16(&bad).to_be_bytes());
    bytes.extend(&bad);
    let mut d = MipDecoder::new(no_latency());
    let mut out = Vec::new();
    d.push(&bytes, host(1), &mut out);
    assert_eq!(out.len(), 3, "{out:?}");
    assert!(matches!(&out[0], ImuEvent::MipReply(r) if r.data == Some(ReplyData::ImuBaseRate(1000)) && r.is_ack()));
    assert!(matches!(&out[1], ImuEvent::MipReply(r) if r.code == NACK_UNKNOWN_COMMAND));
    assert!(matches!(&out[2], ImuEvent::Incomplete(_)));
    let s = d.stats();
    assert_eq!((s.frames, s.replies, s.incomplete, s.unknown, s.malformed, s.samples), (6, 2, 1, 1, 2, 0));
}

/// One random stream: packets, each intact or damaged, with garbage between some.
/// Returns the bytes, the indices of the intact packets and their total length.
fn mip_damaged_stream(rng: &mut Rng, packets: u32) -> (Vec<u8>, Vec<u32>, usize) {
    let mut bytes = Vec::new();
    let mut intact = Vec::new();
    let mut intact_len = 0;
    for k in 0..packets {
        if rng.chance(0.2) {
            // Garbage, often holding a sync pair and a header (a long declared length too).
            let n = 1 + rng.below(20);
            for _ in 0..n {
                bytes.push(rng.byte());
            }
            if rng.chance(0.5) {
                bytes.extend([0x75, 0x65, 0x80, rng.byte()]);
            }
            if rng.chance(0.3) {
                bytes.push(0x75);
            }
        }
        let mut p = mip_packet(k);
        // The last packet stays intact so that the stream ends in sync.
        let damage = if k + 1 == packets { 0 } else { rng.below(5) };
        match damage {
            1 => {
                p.remove(rng.below(p.len()));
            }
            2 => {
                let at = rng.below(p.len());
                p[at] ^= 1 + rng.below(255) as u8;
            }
            _ => {
                intact.push(k);
                intact_len += p.len();
            }
        }
        bytes.extend(p);
    }
    (bytes, intact, intact_len)
}

/// Every intact packet comes out, in order, and nothing else but exact originals (a lost last
/// byte can be "repaired" by the next byte when it happens to be equal).
#[test]
fn mip_resync_keeps_every_intact_packet() {
    let (mut damaged, mut repaired) = (0, 0);
    for seed in 0..400 {
        let mut rng = Rng::new(seed);
        let (bytes, intact, _) = mip_damaged_stream(&mut rng, 40);
        let mut d = ImuDecoder::new(Protocol::Mip, no_latency());
        let events = push_chunked(&mut d, &bytes, &mut rng, 64);
        let got: Vec<&crate::ImuSample> = samples(&events);
        let idx: Vec<u32> = got.iter().map(|s| mip_tow_index(s)).collect();
        assert!(intact.iter().all(|k| idx.contains(k)), "seed {seed}: {idx:?} misses some of {intact:?}");
        assert!(idx.windows(2).all(|w| w[0] < w[1]), "seed {seed}: {idx:?}");
        for s in &got {
            assert_eq!(s.raw, RawSample::Mip(mip_data(mip_tow_index(s))), "seed {seed}");
        }
        let st = d.stats();
        let accepted_len = idx.len() * mip_packet(0).len();
        assert_eq!(st.skipped_bytes as usize + accepted_len, bytes.len(), "seed {seed}: every byte accounted for");
        assert_eq!(d_buffered(&d), 0);
        damaged += 40 - intact.len();
        repaired += idx.len() - intact.len();
    }
    assert!(damaged > 3000, "the streams must be damaged: {damaged}");
    assert!(repaired * 100 < damaged, "{repaired} of {damaged}");
}

fn d_buffered(d: &ImuDecoder) -> usize {
    match d {
        ImuDecoder::Mip(m) => m.buffered(),
        ImuDecoder::WitMotion(w) => w.buffered(),
    }
}

#[test]
fn mip_garbage_never_grows_the_buffer() {
    let mut d = ImuDecoder::new(Protocol::Mip, no_latency());
    let mut out = Vec::new();
    let mut rng = Rng::new(7);
    let mut max = 0;
    for _ in 0..2000 {
        // False headers declaring 255-byte payloads, back to back.
        let chunk: Vec<u8> = (0..97)
            .map(|i| {
                if i % 4 == 0 {
                    0x75
                } else if i % 4 == 1 {
                    0x65
                } else {
                    0xFF
                }
            })
            .collect();
        d.push(&chunk, host(1), &mut out);
        let junk: Vec<u8> = (0..rng.below(300)).map(|_| rng.byte()).collect();
        d.push(&junk, host(2), &mut out);
        max = max.max(d_buffered(&d));
    }
    assert!(max <= crate::mip::packet::MAX_PACKET_LEN, "{max}");
    d.push(&mip_packet(1), host(3), &mut out);
    assert_eq!(samples(&out).len(), 1, "the next good packet is found");
}

// ---------------------------------------------------------------------------------------------
// WitMotion

/// The four frames of cycle `k`: acc, gyro, angle, quaternion.
fn wit_cycle(k: u16) -> Vec<[u8; 11]> {
    let k = k as i16;
    vec![
        WitFrame::from_values(TYPE_ACCEL, [k, -k, 2048, 2500]).encode(),
        WitFrame::from_values(TYPE_GYRO, [k.wrapping_mul(3), 1, -1, 2500]).encode(),
        WitFrame::from_values(TYPE_ANGLE, [100, 200, k, 0x5510]).encode(),
        WitFrame::from_values(TYPE_QUATERNION, [32767, 0, 0, k]).encode(),
    ]
}

fn wit_stream(cycles: std::ops::Range<u16>) -> Vec<u8> {
    cycles.flat_map(wit_cycle).flatten().collect()
}

fn wit_index(s: &crate::ImuSample) -> u16 {
    match &s.raw {
        RawSample::WitMotion(g) => g.accel.unwrap()[0] as u16,
        RawSample::Mip(_) => panic!("not WitMotion"),
    }
}

#[test]
fn wit_any_chunking_gives_the_same_samples() {
    let bytes = wit_stream(0..60);
    for max in [1, 2, 10, 11, 12, 44, 1000] {
        let mut d = ImuDecoder::new(Protocol::WitMotion, no_latency());
        let mut rng = Rng::new(max as u64);
        let events = push_chunked(&mut d, &bytes, &mut rng, max);
        let idx: Vec<u16> = samples(&events).iter().map(|s| wit_index(s)).collect();
        assert_eq!(idx, (0..60).collect::<Vec<_>>(), "chunks of up to {max}");
        let s = d.stats();
        assert_eq!((s.frames, s.samples, s.incomplete), (240, 60, 0));
        assert_eq!((s.bad_checksums, s.resyncs, s.skipped_bytes), (0, 0, 0));
    }
}

#[test]
fn wit_samples_are_in_si_units_with_raw_values_kept() {
    let bytes = wit_stream(0..3);
    let mut d = WitDecoder::new(no_latency());
    let mut out = Vec::new();
    d.push(&bytes, host(9), &mut out);
    let s = samples(&out);
    assert_eq!(s.len(), 3, "{out:?}");
    let one = s[1];
    assert!((one.accel_m_s2[2] - STANDARD_GRAVITY_M_S2).abs() < 1e-12);
    assert!((one.accel_m_s2[0] - 16.0 / 32768.0 * STANDARD_GRAVITY_M_S2).abs() < 1e-12);
    assert!((one.gyro_rad_s[0] - (3.0 * 2000.0 / 32768.0f64).to_radians()).abs() < 1e-12);
    assert_eq!(one.orientation_wxyz, Some([32767.0 / 32768.0, 0.0, 0.0, 1.0 / 32768.0]));
    assert!(one.euler_rad.is_some_and(|e| (e[0] - (100.0 * 180.0 / 32768.0f64).to_radians()).abs() < 1e-12));
    let RawSample::WitMotion(g) = &one.raw else { panic!() };
    assert_eq!(g.angle, Some([100, 200, 1, 0x5510]));
    assert_eq!(frame::temperature_c(&g.accel.unwrap()), 25.0);
}

/// The case PyPI `witmotion` gets wrong: a stray 0x55 right before a frame.
#[test]
fn wit_stray_header_byte_does_not_cost_the_next_frame() {
    for stray in [&[0x55][..], &[0x55, 0x55], &[0x55, 0x51], &[0x00, 0x55, 0x52, 0x01]] {
        let mut bytes = wit_stream(0..2);
        bytes.extend_from_slice(stray);
        bytes.extend(wit_stream(2..5));
        for max in [1, 3, 11, 1000] {
            let mut d = ImuDecoder::new(Protocol::WitMotion, no_latency());
            let events = push_chunked(&mut d, &bytes, &mut Rng::new(max as u64), max);
            let idx: Vec<u16> = samples(&events).iter().map(|s| wit_index(s)).collect();
            assert_eq!(idx, vec![0, 1, 2, 3, 4], "stray {stray:02x?}, chunks {max}");
            let s = d.stats();
            assert_eq!((s.frames, s.resyncs, s.skipped_bytes), (20, 1, stray.len() as u64), "stray {stray:02x?}");
        }
    }
}

#[test]
fn wit_lost_byte_costs_only_its_frame() {
    for cut in 0..11 {
        let mut frames: Vec<Vec<u8>> = wit_cycle(0).into_iter().chain(wit_cycle(1)).map(|f| f.to_vec()).collect();
        frames[5].remove(cut); // cycle 1's gyro loses a byte
        let mut bytes: Vec<u8> = frames.concat();
        bytes.extend(wit_stream(2..4));
        let mut d = ImuDecoder::new(Protocol::WitMotion, no_latency());
        let mut out = Vec::new();
        d.push(&bytes, host(1), &mut out);
        let idx: Vec<u16> = samples(&out).iter().map(|s| wit_index(s)).collect();
        assert_eq!(idx, vec![0, 2, 3], "cut at {cut}");
        let s = d.stats();
        // Cycle 1 splits at the gap: its acc alone, its angle and quaternion together.
        assert_eq!((s.frames, s.incomplete, s.skipped_bytes), (15, 2, 10), "cut at {cut}");
    }
}

/// Bytes, (cycle, position) of the intact frames, cycles with intact acc and gyro, faults.
type DamagedStream = (Vec<u8>, Vec<(u16, usize)>, Vec<u16>, usize);

/// A random WitMotion stream: cycles of four frames, some damaged (a byte lost or changed), with
/// garbage (stray headers and types in it) before some frames. With `spaced`, every fault is
/// followed by at least two intact frames. Returns the bytes, the (cycle, position) of the
/// intact frames, and the cycles whose acc and gyro are intact.
fn wit_damaged_stream(rng: &mut Rng, cycles: u16, spaced: bool) -> DamagedStream {
    let mut bytes = Vec::new();
    let (mut intact, mut complete, mut faults) = (Vec::new(), Vec::new(), 0);
    // The decoder starts out hunting, as after a fault.
    let mut clean_run = 0;
    for k in 0..cycles + 2 {
        let mut acc_gyro_ok = true;
        for (i, f) in wit_cycle(k).into_iter().enumerate() {
            // The last two cycles stay clean so that the stream ends in sync.
            let may_fault = k < cycles && (!spaced || clean_run >= 2);
            let mut f = f.to_vec();
            let mut faulted = false;
            if may_fault && rng.chance(0.1) {
                let n = 1 + rng.below(12);
                for _ in 0..n {
                    bytes.push(if rng.chance(0.3) { 0x55 } else { rng.byte() });
                }
                faulted = true;
                // Garbage that could hide a lost frame splits the cycle (acc | gyro ...).
                if i == 1 && n >= 10 {
                    acc_gyro_ok = false;
                }
            }
            let damage = if may_fault && !faulted { rng.below(8) } else { 0 };
            match damage {
                1 => {
                    f.remove(rng.below(11));
                }
                2 => {
                    let at = rng.below(11);
                    f[at] ^= 1 + rng.below(255) as u8;
                }
                _ => intact.push((k, i)),
            }
            if damage == 1 || damage == 2 {
                faulted = true;
                if i < 2 {
                    acc_gyro_ok = false;
                }
            }
            faults += usize::from(faulted);
            clean_run = if faulted { 0 } else { clean_run + 1 };
            bytes.extend(f);
        }
        if acc_gyro_ok {
            complete.push(k);
        }
    }
    (bytes, intact, complete, faults)
}

/// What a decoder made of a damaged WitMotion stream: the cycle indices of the samples (in
/// order) and how many samples were not exact originals.
fn wit_check(events: &[ImuEvent], seed: u64) -> (Vec<u16>, usize) {
    let (mut idx, mut false_samples) = (Vec::new(), 0);
    for s in samples(events) {
        let RawSample::WitMotion(g) = &s.raw else { panic!() };
        let k = wit_index(s);
        let cycle = wit_cycle(k);
        let exact = g.accel == Some(WitFrame::parse(&cycle[0]).unwrap().values())
            && g.gyro == Some(WitFrame::parse(&cycle[1]).unwrap().values());
        if exact {
            idx.push(k);
        } else {
            false_samples += 1;
        }
    }
    assert!(idx.windows(2).all(|w| w[0] < w[1]), "seed {seed}: {idx:?}");
    (idx, false_samples)
}

/// Faults with two good frames between them: every intact frame is decoded, every cycle with
/// intact acc and gyro makes a sample, and nothing else comes out but exact originals.
#[test]
fn wit_resync_keeps_every_intact_frame_between_single_faults() {
    let (mut faults_total, mut extra_total) = (0, 0);
    for seed in 0..400 {
        let mut rng = Rng::new(seed);
        let (bytes, intact, complete, faults) = wit_damaged_stream(&mut rng, 30, true);
        let mut d = ImuDecoder::new(Protocol::WitMotion, no_latency());
        let events = push_chunked(&mut d, &bytes, &mut rng, 40);
        let s = d.stats();
        assert!(s.frames >= intact.len() as u64, "seed {seed}: {} frames of {} intact", s.frames, intact.len());
        assert_eq!(s.skipped_bytes + 11 * s.frames, bytes.len() as u64, "seed {seed}: every byte accounted for");
        let (got, false_samples) = wit_check(&events, seed);
        assert_eq!(false_samples, 0, "seed {seed}");
        assert!(complete.iter().all(|k| got.contains(k)), "seed {seed}: {got:?} misses some of {complete:?}");
        faults_total += faults;
        extra_total += s.frames - intact.len() as u64;
    }
    assert!(faults_total > 4000, "{faults_total}");
    assert!(extra_total * 100 < faults_total as u64, "{extra_total} repaired of {faults_total}");
}

/// Dense faults (garbage and damage back to back): each fault costs at most one intact frame
/// besides its own (a good frame between two faults is given up while hunting: an 8-bit sum
/// would otherwise let garbage through), and false samples are rare: a frame that lost a byte
/// and is followed by garbage passes the 8-bit sum 1 time in 256, and nothing can tell.
#[test]
fn wit_dense_faults_cost_little_and_rarely_give_false_samples() {
    let (mut lost_total, mut faults_total, mut false_total) = (0, 0, 0);
    for seed in 0..400 {
        let mut rng = Rng::new(1000 + seed);
        let (bytes, intact, _, faults) = wit_damaged_stream(&mut rng, 30, false);
        let mut d = ImuDecoder::new(Protocol::WitMotion, no_latency());
        let events = push_chunked(&mut d, &bytes, &mut rng, 40);
        let (_, false_samples) = wit_check(&events, seed);
        false_total += false_samples;
        let s = d.stats();
        assert_eq!(s.skipped_bytes + 11 * s.frames, bytes.len() as u64, "seed {seed}: every byte accounted for");
        let lost = (intact.len() as u64).saturating_sub(s.frames);
        assert!(lost <= faults as u64, "seed {seed}: lost {lost}, faults {faults}");
        lost_total += lost;
        faults_total += faults;
    }
    println!("dense faults: {lost_total} intact frames lost and {false_total} false samples for {faults_total} faults");
    assert!(false_total * 200 < faults_total, "{false_total} false samples for {faults_total} faults");
}

// ---------------------------------------------------------------------------------------------
// Time stamps

#[test]
fn stamps_follow_the_latency_model() {
    // 100 000 baud, 10 bits: 100 us per byte; 2 ms USB latency.
    let ts = Timestamper::new(LatencyModel { baud: 100_000, bits_per_byte: 10, usb_latency_ns: 2_000_000 });
    let mut d = ImuDecoder::new(Protocol::Mip, ts);
    let (a, b) = (mip_packet(1), mip_packet(2));
    let mut chunk = a.clone();
    chunk.extend(&b);
    let mut out = Vec::new();
    let t = 10_000_000_000;
    d.push(&chunk, host(t), &mut out);
    let s = samples(&out);
    let len = a.len() as u64;
    // The second packet ends the read; the first ended `len` bytes earlier.
    assert_eq!(s[1].host_receive, host(t));
    assert_eq!(s[0].host_receive, host(t - len * 100_000));
    assert_eq!(s[1].stamp, host(t - len * 100_000 - 2_000_000));
    assert_eq!(s[0].stamp, host(t - 2 * len * 100_000 - 2_000_000));
}

#[test]
fn stamps_map_onto_ptp() {
    use crate::timing::LinearClockMap;
    let map = LinearClockMap { target: Clock::Ptp, offset_ns: -5_000, skew_ppb: 0.0, reference_host_ns: 0 };
    let ts = Timestamper::new(LatencyModel::new(0, 0)).with_map(std::sync::Arc::new(map));
    let mut d = ImuDecoder::new(Protocol::WitMotion, ts);
    let mut out = Vec::new();
    d.push(&wit_stream(0..2), host(1_000_000), &mut out);
    let s = samples(&out);
    assert_eq!(s[0].stamp, Stamp::new(995_000, Clock::Ptp));
    assert_eq!(s[0].host_receive.clock, Clock::Host);
}
