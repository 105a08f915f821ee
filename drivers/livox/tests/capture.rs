//! Captures: the real Tele-15 pcap, hand-made pcap/pcapng/.lvx files, writers, summaries and the
//! PyPI `livox-lvx` cross-check.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use starc_livox::capture::lvx::{LvxDevice, LvxVersion, LvxWriter};
use starc_livox::capture::net::build_udp_frame;
use starc_livox::capture::pcap::{PcapWriter, TsPrecision};
use starc_livox::capture::summary::{summarize, Summarizer};
use starc_livox::capture::{self, Capture, CaptureFormat, Datagram};
use starc_livox::control::{CommandId, ControlFrame, Message, Request, Response};
use starc_livox::data::{
    encode_imu_packet, encode_point_packet, DataHeader, DataPacket, DataType, ImuSample, Return, StatusWord, SyncState,
    SystemStatus,
};
use starc_livox::LivoxError;
use starc_time::{Clock, Stamp};
use std::io::Read;
use std::net::{Ipv4Addr, SocketAddrV4};
use std::path::PathBuf;

fn tele15_path() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/livox/tele15_small.pcap")
}

fn tmp(name: &str) -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("starc-livox-capture");
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(format!("{}-{name}", std::process::id()))
}

fn addr(last: u8, port: u16) -> SocketAddrV4 {
    SocketAddrV4::new(Ipv4Addr::new(192, 168, 1, last), port)
}

fn header(data_type: DataType, ns: u64, clock: Clock) -> DataHeader {
    DataHeader {
        version: 5,
        slot: 1,
        lidar_id: 1,
        status: StatusWord::from_raw(StatusWord::compose(SyncState::Ptp, SystemStatus::Normal, true, false)),
        data_type,
        timestamp: Stamp::new(ns, clock),
    }
}

/// A point packet whose every 4th return is empty, or an IMU packet.
fn packet(data_type: DataType, ns: u64, clock: Clock) -> Vec<u8> {
    let h = header(data_type, ns, clock);
    let mut out = Vec::new();
    if data_type == DataType::Imu {
        let s = ImuSample { gyro_rad_s: [0.1, -0.2, 0.3], acc_g: [0.0, -0.5, 1.0] };
        encode_imu_packet(&h, &s, &mut out).unwrap();
    } else {
        let returns: Vec<Return> = (0..data_type.returns_per_packet())
            .map(|i| {
                if i % 4 == 3 {
                    Return::EMPTY
                } else {
                    // Negative coordinates on purpose (livox-lvx reads them as unsigned).
                    Return { x_m: 4.0 + i as f32 * 0.01, y_m: -1.5, z_m: -0.25, reflectivity: i as u8, tag: 0x10 }
                }
            })
            .collect();
        encode_point_packet(&h, &returns, &mut out).unwrap();
    }
    out
}

fn read_all(c: Capture) -> Vec<Datagram> {
    c.map(|d| d.unwrap()).collect()
}

// ---------------------------------------------------------------------------------------------
// The real capture.

#[test]
fn tele15_capture_has_its_known_counts() {
    let path = tele15_path();
    if !path.exists() {
        println!("skipped: {} is absent", path.display());
        return;
    }
    let mut cap = capture::open(&path).unwrap();
    assert_eq!(cap.format(), CaptureFormat::Pcap);
    let (mut points, mut imu, mut other) = (0, 0, 0);
    for d in &mut cap {
        let d = d.unwrap();
        assert_eq!(d.dst.map(|a| a.port()), Some(56001));
        assert_eq!(d.time.clock, Clock::Host);
        let p = DataPacket::parse(&d.payload).unwrap();
        assert_eq!(p.header.timestamp_type(), 1, "all PTP-stamped");
        assert_eq!(p.header.timestamp.clock, Clock::Ptp);
        match p.header.data_type {
            DataType::ExtendedCartesian => {
                assert_eq!(d.src.map(|a| a.port()), Some(60001));
                assert_eq!(p.count_returns().returns, 96);
                points += 1;
            }
            DataType::Imu => {
                assert_eq!(d.src.map(|a| a.port()), Some(60003));
                imu += 1;
            }
            _ => other += 1,
        }
    }
    assert_eq!((points, imu, other), (926, 74, 0));
    assert_eq!(cap.stats().datagrams, 1000);
    assert_eq!(cap.stats().records, 1000);
    assert_eq!((cap.stats().non_udp, cap.stats().fragments, cap.stats().truncated), (0, 0, 0));

    let mut cap = capture::open(&path).unwrap();
    let s = summarize(&mut cap);
    assert_eq!(s.records, 1000);
    assert_eq!(s.point_packets, 926);
    assert_eq!(s.points, 926 * 96);
    assert_eq!(s.imu_packets, 74);
    assert_eq!(s.data_types.get("extended_cartesian"), Some(&926));
    assert_eq!(s.data_types.get("imu"), Some(&74));
    assert_eq!(s.timestamp_types.get("ptp"), Some(&1000));
    assert_eq!(s.timestamp_types.get("none"), Some(&0));
    assert_eq!(s.flows.get("60001->56001"), Some(&926));
    assert_eq!(s.flows.get("60003->56001"), Some(&74));
    assert_eq!((s.undecodable, s.decode_errors, s.crc_failures), (0, 0, 0));
    assert_eq!(s.devices.len(), 1);
    assert!(s.read_error.is_none());
    assert!(s.duration_s > 0.0 && s.capture_duration_s > 0.0);
    assert_eq!(s.timestamp_clock, Some(Clock::Ptp));
    let json = serde_json::to_value(&s).unwrap();
    for key in [
        "format",
        "records",
        "point_packets",
        "points",
        "non_empty_points",
        "imu_packets",
        "data_types",
        "timestamp_types",
        "sync_sources",
        "first_timestamp_ns",
        "last_timestamp_ns",
        "duration_s",
        "gaps",
        "lost_packets",
        "reordered",
        "control_frames",
        "crc_failures",
        "decode_errors",
        "devices",
        "undecodable",
    ] {
        assert!(json.get(key).is_some(), "missing key {key}");
    }
    assert_eq!(json["format"], "pcap");

    // Streaming in odd small reads gives the same datagrams as reading from memory.
    let bytes = std::fs::read(&path).unwrap();
    let from_memory = read_all(capture::from_bytes(bytes.clone()).unwrap());
    let dribble = Capture::from_reader(Box::new(Dribble { bytes, at: 0, step: 997 })).unwrap();
    assert_eq!(read_all(dribble), from_memory);
    assert_eq!(from_memory.len(), 1000);
}

/// A reader handing out at most `step` bytes per read.
struct Dribble {
    bytes: Vec<u8>,
    at: usize,
    step: usize,
}

impl Read for Dribble {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = buf.len().min(self.step).min(self.bytes.len() - self.at);
        buf[..n].copy_from_slice(&self.bytes[self.at..self.at + n]);
        self.at += n;
        Ok(n)
    }
}

// ---------------------------------------------------------------------------------------------
// Classic pcap.

#[test]
fn pcap_writer_round_trips_in_both_precisions() {
    for precision in [TsPrecision::Micro, TsPrecision::Nano] {
        let path = tmp(&format!("rt-{precision:?}.pcap"));
        let mut w = PcapWriter::create(&path, precision).unwrap();
        let mut sent = Vec::new();
        for i in 0..50u64 {
            let dt = if i % 5 == 4 { DataType::Imu } else { DataType::DualCartesian };
            let p = packet(dt, 1_000_000 + i * 200_000, Clock::Ptp);
            let t = 1_700_000_000_123_456_789 + i * 200_123;
            let port = if dt == DataType::Imu { 60003 } else { 60001 };
            w.write_udp(t, addr(10, port), addr(50, 56001), &p).unwrap();
            sent.push((t, p));
        }
        assert_eq!(w.records(), 50);
        w.finish().unwrap();
        let cap = capture::open(&path).unwrap();
        assert_eq!(cap.pcap_header().map(|h| h.precision), Some(precision));
        let got = read_all(cap);
        assert_eq!(got.len(), sent.len());
        for (d, (t, p)) in got.iter().zip(&sent) {
            let expect_t = match precision {
                TsPrecision::Micro => t / 1000 * 1000,
                TsPrecision::Nano => *t,
            };
            assert_eq!(d.time, Stamp::new(expect_t, Clock::Host));
            assert_eq!(&d.payload, p);
            assert_eq!(d.dst, Some(addr(50, 56001)));
        }
        let _ = std::fs::remove_file(&path);
    }
}

fn pcap_file(big_endian: bool, nanos: bool, link: u32, records: &[(u32, u32, Vec<u8>, u32)]) -> Vec<u8> {
    let w32 = |v: u32| if big_endian { v.to_be_bytes() } else { v.to_le_bytes() };
    let w16 = |v: u16| if big_endian { v.to_be_bytes() } else { v.to_le_bytes() };
    let mut f = Vec::new();
    f.extend_from_slice(&w32(if nanos { 0xa1b2_3c4d } else { 0xa1b2_c3d4 }));
    f.extend_from_slice(&w16(2));
    f.extend_from_slice(&w16(4));
    f.extend_from_slice(&[0; 8]);
    f.extend_from_slice(&w32(65535));
    f.extend_from_slice(&w32(link));
    for (sec, frac, data, orig) in records {
        f.extend_from_slice(&w32(*sec));
        f.extend_from_slice(&w32(*frac));
        f.extend_from_slice(&w32(data.len() as u32));
        f.extend_from_slice(&w32(*orig));
        f.extend_from_slice(data);
    }
    f
}

fn eth_frame(payload: &[u8]) -> Vec<u8> {
    let mut f = Vec::new();
    build_udp_frame(addr(10, 60001), addr(50, 56001), 1, payload, &mut f);
    f
}

#[test]
fn big_endian_pcap_with_nanoseconds() {
    let p = packet(DataType::Imu, 5, Clock::Device);
    let f = eth_frame(&p);
    let bytes = pcap_file(true, true, 1, &[(3, 7, f.clone(), f.len() as u32)]);
    let cap = capture::from_bytes(bytes).unwrap();
    assert_eq!(cap.pcap_header().map(|h| (h.big_endian, h.snaplen)), Some((true, 65535)));
    let got = read_all(cap);
    assert_eq!(got.len(), 1);
    assert_eq!(got[0].time.ns, 3_000_000_007);
    assert_eq!(got[0].payload, p);
}

#[test]
fn cooked_vlan_and_raw_link_types() {
    let payload = b"livox?".to_vec();
    let eth = eth_frame(&payload);
    let ip = eth[14..].to_vec();
    // SLL: packet type, ARPHRD, address length, 8-byte address, protocol.
    let mut sll = vec![0, 0, 0, 1, 0, 6, 2, 0, 0, 0, 0, 0, 0, 0, 0x08, 0x00];
    sll.extend_from_slice(&ip);
    // SLL2: protocol, reserved, ifindex, ARPHRD, packet type, address length, address.
    let mut sll2 = vec![0x08, 0x00, 0, 0, 0, 0, 0, 2, 0, 1, 0, 6, 2, 0, 0, 0, 0, 0, 0, 0];
    sll2.extend_from_slice(&ip);
    // 802.1ad outer tag, 802.1Q inner tag.
    let mut vlan = eth[..12].to_vec();
    vlan.extend_from_slice(&[0x88, 0xa8, 0x00, 0x64, 0x81, 0x00, 0x00, 0x0a, 0x08, 0x00]);
    vlan.extend_from_slice(&ip);
    let mut null = 2u32.to_le_bytes().to_vec();
    null.extend_from_slice(&ip);
    for (link, frame) in [(113, sll), (276, sll2), (1, vlan), (101, ip.clone()), (228, ip.clone()), (0, null)] {
        let bytes = pcap_file(false, false, link, &[(1, 2, frame.clone(), frame.len() as u32)]);
        let got = read_all(capture::from_bytes(bytes).unwrap());
        assert_eq!(got.len(), 1, "link {link}");
        assert_eq!(got[0].payload, payload, "link {link}");
        assert_eq!(got[0].src, Some(addr(10, 60001)), "link {link}");
        assert_eq!(got[0].time.ns, 1_000_002_000);
    }
    let bytes = pcap_file(false, false, 105, &[]);
    assert!(matches!(capture::from_bytes(bytes), Err(LivoxError::UnsupportedLinkType(105))));
}

#[test]
fn skipped_records_are_counted() {
    let eth = eth_frame(b"0123456789");
    let mut frag = eth.clone();
    frag[20] = 0x20; // more fragments
    let mut tcp = eth.clone();
    tcp[23] = 6;
    let mut arp = eth.clone();
    arp[12..14].copy_from_slice(&[0x08, 0x06]);
    let cut = eth[..eth.len() - 4].to_vec();
    let mut bad_udp = eth.clone();
    bad_udp[39] = 200; // UDP length beyond the IP packet
    let records = vec![
        (1, 0, eth.clone(), eth.len() as u32),
        (2, 0, frag, eth.len() as u32),
        (3, 0, tcp, eth.len() as u32),
        (4, 0, arp, eth.len() as u32),
        (5, 0, cut, eth.len() as u32),
        (6, 0, bad_udp, eth.len() as u32),
        // Truncated only in its frame check sequence: the datagram is whole and is kept.
        (7, 0, eth.clone(), eth.len() as u32 + 4),
    ];
    let mut cap = capture::from_bytes(pcap_file(false, false, 1, &records)).unwrap();
    let got: Vec<Datagram> = (&mut cap).map(|d| d.unwrap()).collect();
    assert_eq!(got.len(), 2);
    let s = cap.stats();
    assert_eq!((s.records, s.datagrams, s.fragments, s.non_udp, s.truncated, s.malformed), (7, 2, 1, 2, 2, 1));
}

#[test]
fn broken_files_are_typed_errors() {
    let eth = eth_frame(b"abc");
    let good = pcap_file(false, false, 1, &[(1, 0, eth.clone(), eth.len() as u32), (2, 0, eth.clone(), 17)]);
    // Cut anywhere inside the second record: one datagram, then a truncation error.
    for cut in [good.len() - 1, good.len() - eth.len(), good.len() - eth.len() - 3] {
        let mut cap = capture::from_bytes(good[..cut].to_vec()).unwrap();
        assert!(cap.next().is_some_and(|d| d.is_ok()));
        assert!(matches!(cap.next(), Some(Err(LivoxError::CaptureTruncated { format: "pcap", .. }))), "cut {cut}");
        assert!(cap.next().is_none(), "finished after an error");
    }
    // A header alone is an empty capture.
    assert_eq!(read_all(capture::from_bytes(good[..24].to_vec()).unwrap()).len(), 0);
    // A header cut short.
    assert!(matches!(capture::from_bytes(good[..20].to_vec()), Err(LivoxError::CaptureTruncated { .. })));
    // A record claiming a gigabyte.
    let mut huge = good[..24].to_vec();
    huge.extend_from_slice(&[0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0x40, 0, 0, 0, 0x40]);
    let mut cap = capture::from_bytes(huge).unwrap();
    assert!(matches!(cap.next(), Some(Err(LivoxError::RecordTooLarge { .. }))));
    // Garbage and empty input.
    assert!(matches!(
        capture::from_bytes(b"hello world, not a capture".to_vec()),
        Err(LivoxError::UnknownCaptureFormat(_))
    ));
    assert!(capture::from_bytes(Vec::new()).is_err());
    let path = tmp("empty.pcap");
    std::fs::write(&path, b"").unwrap();
    assert!(capture::open(&path).is_err());
    assert!(matches!(capture::open(&tmp("does-not-exist")), Err(LivoxError::Io { .. })));
    let _ = std::fs::remove_file(&path);
}

// ---------------------------------------------------------------------------------------------
// pcapng.

struct Ng {
    big: bool,
    out: Vec<u8>,
}

impl Ng {
    fn w32(&self, v: u32) -> [u8; 4] {
        if self.big {
            v.to_be_bytes()
        } else {
            v.to_le_bytes()
        }
    }

    fn w16(&self, v: u16) -> [u8; 2] {
        if self.big {
            v.to_be_bytes()
        } else {
            v.to_le_bytes()
        }
    }

    fn block(&mut self, block_type: u32, body: &[u8]) {
        let mut body = body.to_vec();
        while body.len() & 3 != 0 {
            body.push(0);
        }
        let len = (body.len() + 12) as u32;
        let (t, l) = (self.w32(block_type), self.w32(len));
        self.out.extend_from_slice(&t);
        self.out.extend_from_slice(&l);
        self.out.extend_from_slice(&body);
        self.out.extend_from_slice(&l);
    }

    fn shb(&mut self) {
        let mut b = self.w32(0x1a2b_3c4d).to_vec();
        b.extend_from_slice(&self.w16(1));
        b.extend_from_slice(&self.w16(0));
        b.extend_from_slice(&[0xff; 8]); // section length unknown
        self.block(0x0a0d_0d0a, &b);
    }

    fn idb(&mut self, link: u16, snaplen: u32, tsresol: Option<u8>, tsoffset: Option<i64>) {
        let mut b = self.w16(link).to_vec();
        b.extend_from_slice(&[0, 0]);
        b.extend_from_slice(&self.w32(snaplen));
        if let Some(r) = tsresol {
            b.extend_from_slice(&self.w16(9));
            b.extend_from_slice(&self.w16(1));
            b.extend_from_slice(&[r, 0, 0, 0]);
        }
        if let Some(o) = tsoffset {
            b.extend_from_slice(&self.w16(14));
            b.extend_from_slice(&self.w16(8));
            let o = if self.big { o.to_be_bytes() } else { o.to_le_bytes() };
            b.extend_from_slice(&o);
        }
        b.extend_from_slice(&[0; 4]); // opt_endofopt
        self.block(1, &b);
    }

    fn epb(&mut self, interface: u32, ticks: u64, data: &[u8], orig: u32) {
        let mut b = self.w32(interface).to_vec();
        b.extend_from_slice(&self.w32((ticks >> 32) as u32));
        b.extend_from_slice(&self.w32(ticks as u32));
        b.extend_from_slice(&self.w32(data.len() as u32));
        b.extend_from_slice(&self.w32(orig));
        b.extend_from_slice(data);
        while b.len() & 3 != 0 {
            b.push(0);
        }
        // A comment option, to be skipped.
        b.extend_from_slice(&self.w16(1));
        b.extend_from_slice(&self.w16(3));
        b.extend_from_slice(b"hi!\0");
        b.extend_from_slice(&[0; 4]);
        self.block(6, &b);
    }

    fn opb(&mut self, interface: u16, ticks: u64, data: &[u8]) {
        let mut b = self.w16(interface).to_vec();
        b.extend_from_slice(&self.w16(0));
        b.extend_from_slice(&self.w32((ticks >> 32) as u32));
        b.extend_from_slice(&self.w32(ticks as u32));
        b.extend_from_slice(&self.w32(data.len() as u32));
        b.extend_from_slice(&self.w32(data.len() as u32));
        b.extend_from_slice(data);
        self.block(2, &b);
    }

    fn spb(&mut self, data: &[u8]) {
        let mut b = self.w32(data.len() as u32).to_vec();
        b.extend_from_slice(data);
        self.block(3, &b);
    }
}

#[test]
fn pcapng_in_both_byte_orders_with_every_packet_block() {
    let payloads: Vec<Vec<u8>> = (0..5u8).map(|i| vec![i; 10 + usize::from(i)]).collect();
    let frames: Vec<Vec<u8>> = payloads.iter().map(|p| eth_frame(p)).collect();
    let mut file = Vec::new();
    for big in [false, true] {
        let mut ng = Ng { big, out: Vec::new() };
        ng.shb();
        ng.idb(1, 0, None, None); // microseconds by default
        ng.idb(1, 0, Some(9), Some(10)); // nanoseconds, 10 s offset
        ng.idb(1, 0, Some(0x80 | 20), None); // 2^-20 s
        ng.block(0x0000_0bad, &[1, 2, 3, 4]); // unknown block
        ng.block(5, &[0; 8]); // interface statistics
        ng.epb(0, 1_500_000, &frames[0], frames[0].len() as u32);
        ng.epb(1, 2_000_000_007, &frames[1], frames[1].len() as u32);
        ng.epb(2, 3 << 20, &frames[2], frames[2].len() as u32);
        ng.spb(&frames[3]);
        ng.opb(1, 42, &frames[4]);
        file.extend_from_slice(&ng.out);
    }
    for (name, bytes) in [("both sections", file.clone()), ("little only", file[..file.len() / 2].to_vec())] {
        let mut cap = capture::from_bytes(bytes).unwrap();
        assert_eq!(cap.format(), CaptureFormat::Pcapng);
        let got: Vec<Datagram> = (&mut cap).map(|d| d.unwrap()).collect();
        let sections = if name == "both sections" { 2 } else { 1 };
        assert_eq!(got.len(), 5 * sections, "{name}");
        assert_eq!(cap.stats().skipped_blocks, 2 * sections as u64);
        for section in got.chunks(5) {
            let times: Vec<u64> = section.iter().map(|d| d.time.ns).collect();
            // SPB has no time stamp: it repeats the previous packet's.
            assert_eq!(times, vec![1_500_000_000, 12_000_000_007, 3_000_000_000, 3_000_000_000, 10_000_000_042]);
            for (d, p) in section.iter().zip(&payloads) {
                assert_eq!(&d.payload, p);
            }
        }
    }
}

#[test]
fn pcapng_structure_errors_are_typed() {
    let frame = eth_frame(b"x");
    let mut ng = Ng { big: false, out: Vec::new() };
    ng.shb();
    ng.idb(1, 0, None, None);
    let head = ng.out.clone();
    ng.epb(0, 1, &frame, frame.len() as u32);
    let good = ng.out.clone();
    assert_eq!(read_all(capture::from_bytes(good.clone()).unwrap()).len(), 1);

    let epb_at = head.len();
    let expect_bad_block = |bytes: Vec<u8>, what: &str| {
        let mut cap = capture::from_bytes(bytes).unwrap();
        let e = cap.next();
        assert!(matches!(e, Some(Err(LivoxError::BadBlock { .. }))), "{what}: {e:?}");
    };
    let mut trailer = good.clone();
    let n = trailer.len();
    trailer[n - 4] ^= 4;
    expect_bad_block(trailer, "trailing length");
    let mut odd = good.clone();
    odd[epb_at + 4] += 2;
    expect_bad_block(odd, "not a multiple of 4");
    let mut tiny = good.clone();
    tiny[epb_at + 4..epb_at + 8].copy_from_slice(&8u32.to_le_bytes());
    expect_bad_block(tiny, "below 12");
    let mut caplen = good.clone();
    caplen[epb_at + 20..epb_at + 24].copy_from_slice(&5000u32.to_le_bytes());
    expect_bad_block(caplen, "captured length");
    let mut iface = good.clone();
    iface[epb_at + 8] = 3;
    let mut cap = capture::from_bytes(iface).unwrap();
    assert!(matches!(cap.next(), Some(Err(LivoxError::UnknownInterface { interface: 3, known: 1, .. }))));
    let mut huge = good.clone();
    huge[epb_at + 4..epb_at + 8].copy_from_slice(&0x7fff_fff0u32.to_le_bytes());
    let mut cap = capture::from_bytes(huge).unwrap();
    assert!(matches!(cap.next(), Some(Err(LivoxError::RecordTooLarge { .. }))));
    let mut cap = capture::from_bytes(good[..good.len() - 2].to_vec()).unwrap();
    assert!(matches!(cap.next(), Some(Err(LivoxError::CaptureTruncated { format: "pcapng", .. }))));
    let mut bom = good.clone();
    bom[8] = 0;
    assert!(matches!(capture::from_bytes(bom), Err(LivoxError::BadBlock { .. })));
}

// ---------------------------------------------------------------------------------------------
// .lvx.

fn devices() -> Vec<LvxDevice> {
    let mut a = LvxDevice::new("3WEDH7600101621", 0, 7);
    a.extrinsic_enable = true;
    a.roll_deg = 1.5;
    a.z_m = -0.25;
    let b = LvxDevice::new("0TFDFCE00502151", 1, 2);
    vec![a, b]
}

#[test]
fn lvx_v1_1_round_trips_and_cuts_frames() {
    let path = tmp("rt.lvx");
    let mut w = LvxWriter::create(&path, 50, &devices()).unwrap();
    let mut sent = Vec::new();
    let types = [DataType::ExtendedCartesian, DataType::Imu, DataType::TripleSpherical, DataType::DualCartesian];
    for i in 0..200u64 {
        let dt = types[(i % 4) as usize];
        let device = (i % 3 == 0) as u8;
        let p = packet(dt, 10_000_000_000 + i * 1_000_000, Clock::Ptp);
        w.write_packet(device, &p).unwrap();
        sent.push((device, p));
    }
    assert!(matches!(w.write_packet(9, &sent[0].1), Err(LivoxError::LvxUnknownDevice(9))));
    assert!(w.write_packet(0, &sent[0].1[..100]).is_err());
    w.finish().unwrap();

    let mut cap = capture::open(&path).unwrap();
    assert_eq!(cap.format(), CaptureFormat::Lvx);
    let h = cap.lvx_header().cloned().unwrap();
    assert_eq!(h.version, LvxVersion::V1_1);
    assert_eq!(h.frame_duration_ms, Some(50));
    assert_eq!(h.devices, devices());
    assert_eq!(h.devices[0].lidar_sn_text(), "3WEDH7600101621");
    let got: Vec<Datagram> = (&mut cap).map(|d| d.unwrap()).collect();
    // 200 ms of packets in 50 ms frames.
    assert_eq!(cap.stats().lvx_frames, 4);
    assert_eq!(got.len(), sent.len());
    for (d, (device, p)) in got.iter().zip(&sent) {
        assert_eq!(d.device_index, Some(*device));
        assert_eq!(&d.payload, p);
        assert_eq!(d.time, DataPacket::parse(p).unwrap().header.timestamp);
        assert_eq!((d.src, d.dst), (None, None));
    }
    let s = summarize(&mut capture::open(&path).unwrap());
    assert_eq!(s.records, 200);
    assert_eq!(s.imu_packets, 50);
    assert_eq!(s.point_packets, 150);
    assert_eq!(s.points, 50 * 96 + 50 * 90 + 50 * 96);
    assert_eq!(s.devices.get("lvx:0").and_then(|d| d.lidar_sn.clone()).as_deref(), Some("3WEDH7600101621"));
    assert_eq!(s.devices.values().map(|d| d.packets).sum::<u64>(), 200);
    let _ = std::fs::remove_file(&path);
}

fn lvx_v1_0(packets: &[(u8, Vec<u8>)], next_offset_fix: i64) -> Vec<u8> {
    let mut f = b"livox_tech".to_vec();
    f.resize(16, 0);
    f.extend_from_slice(&[1, 0, 0, 0]);
    f.extend_from_slice(&0xac0e_a767u32.to_le_bytes());
    f.push(1); // device count
    let mut sn = *b"1HDDGAU00100091\0";
    f.extend_from_slice(&sn);
    sn = [0; 16];
    f.extend_from_slice(&sn);
    f.extend_from_slice(&[0, 3]); // index, type (Horizon)
    for v in [0.0f32, 2.0, 0.0, 0.1, 0.2, 0.3] {
        f.extend_from_slice(&v.to_le_bytes());
    }
    let body: Vec<u8> = packets.iter().flat_map(|(i, p)| std::iter::once(*i).chain(p.iter().copied())).collect();
    let current = f.len() as u64;
    let next = (current + 32 + body.len() as u64) as i64 + next_offset_fix;
    f.extend_from_slice(&current.to_le_bytes());
    f.extend_from_slice(&(next as u64).to_le_bytes());
    f.extend_from_slice(&0u64.to_le_bytes());
    f.extend_from_slice(&(packets.len() as u64).to_le_bytes());
    f.extend_from_slice(&body);
    f
}

#[test]
fn lvx_v1_0_by_hand() {
    let packets = vec![
        (0, packet(DataType::ExtendedCartesian, 1_000, Clock::Device)),
        (0, packet(DataType::Imu, 2_000, Clock::Device)),
        (0, packet(DataType::Cartesian, 3_000, Clock::Device)),
    ];
    let bytes = lvx_v1_0(&packets, 0);
    let mut cap = capture::from_bytes(bytes.clone()).unwrap();
    let h = cap.lvx_header().cloned().unwrap();
    assert_eq!((h.version, h.frame_duration_ms, h.devices.len()), (LvxVersion::V1_0, None, 1));
    let d = h.devices[0];
    assert_eq!((d.lidar_sn_text().as_str(), d.device_type, d.extrinsic_enable), ("1HDDGAU00100091", 3, false));
    assert_eq!((d.pitch_deg, d.z_m), (2.0, 0.3));
    let got: Vec<Datagram> = (&mut cap).map(|d| d.unwrap()).collect();
    assert_eq!(got.len(), 3);
    assert_eq!(got[2].payload, packets[2].1);
    assert_eq!(got[1].time, Stamp::new(2_000, Clock::Device));

    // A frame whose next_offset cuts a package, and one whose file ends early.
    let mut cap = capture::from_bytes(lvx_v1_0(&packets, -5)).unwrap();
    let results: Vec<_> = (&mut cap).collect();
    assert!(matches!(results.last(), Some(Err(LivoxError::MalformedCapture { format: "lvx", .. }))));
    let mut cap = capture::from_bytes(bytes[..bytes.len() - 10].to_vec()).unwrap();
    let results: Vec<_> = (&mut cap).collect();
    assert_eq!(results.len(), 3);
    assert!(matches!(results.last(), Some(Err(LivoxError::CaptureTruncated { format: "lvx", .. }))));
    // Unknown data type inside a frame.
    let mut bad = bytes.clone();
    let first_package = bytes.len() - packets.iter().map(|(_, p)| p.len() + 1).sum::<usize>();
    bad[first_package + 10] = 9;
    let mut cap = capture::from_bytes(bad).unwrap();
    assert!(matches!(cap.next(), Some(Err(LivoxError::LvxDataType { data_type: 9, .. }))));
    // Wrong current_offset, bad magic, unknown version.
    let mut bad = bytes.clone();
    bad[first_package - 32] ^= 1;
    let mut cap = capture::from_bytes(bad).unwrap();
    assert!(matches!(cap.next(), Some(Err(LivoxError::LvxFrame { .. }))));
    let mut bad = bytes.clone();
    bad[20] = 0;
    assert!(matches!(capture::from_bytes(bad), Err(LivoxError::MalformedCapture { .. })));
    let mut bad = bytes;
    bad[16] = 2;
    assert!(matches!(capture::from_bytes(bad), Err(LivoxError::UnsupportedCaptureVersion { major: 2, .. })));
}

// ---------------------------------------------------------------------------------------------
// Summaries of control traffic, loss and junk.

#[test]
fn summary_counts_control_frames_loss_and_junk() {
    let device = addr(10, 65000);
    let host = addr(50, 55501);
    let mut s = Summarizer::new();
    let mut t = 0;
    let mut push = |s: &mut Summarizer, src, dst, payload: Vec<u8>| {
        t += 1;
        s.observe(&Datagram {
            time: Stamp::new(t, Clock::Host),
            src: Some(src),
            dst: Some(dst),
            device_index: None,
            payload,
        });
    };
    let hb = ControlFrame::request(1, Request::Heartbeat).encode().unwrap();
    let ack = ControlFrame::response(1, Response::Heartbeat { ret: 0, work_state: 1, feature: 0, status: 0 })
        .encode()
        .unwrap();
    let refused = ControlFrame::response(2, Response::Ret { id: CommandId::Sampling, ret: 1 }).encode().unwrap();
    let code = starc_livox::control::BroadcastCode::from_text("3WEDH7600101621").unwrap();
    let bc = ControlFrame::message(0, Message::Broadcast { code, device_type: starc_livox::control::DeviceType::Avia })
        .encode()
        .unwrap();
    push(&mut s, host, device, hb.clone());
    push(&mut s, device, host, ack);
    // The official SDK's handshake request carries cmd_type 1 (ACK); it is still a request.
    let hs_payload = [127, 0, 0, 1, 0xc1, 0xda, 0xcd, 0xd8, 0xc1, 0xda];
    let sdk_handshake = starc_livox::control::RawFrame {
        cmd_type: starc_livox::control::CmdType::Ack,
        seq: 2,
        cmd_set: 0,
        cmd_id: 1,
        payload: &hs_payload,
    }
    .encode()
    .unwrap();
    push(&mut s, host, device, sdk_handshake);
    push(
        &mut s,
        device,
        host,
        ControlFrame::response(2, Response::Ret { id: CommandId::Handshake, ret: 0 }).encode().unwrap(),
    );
    push(&mut s, device, host, refused);
    push(&mut s, device, addr(255, 55000), bc);
    let mut bad_crc = hb.clone();
    let n = bad_crc.len();
    bad_crc[n - 1] ^= 1;
    push(&mut s, host, device, bad_crc);
    // Points with 2 missing packets (a gap of 3 intervals), one reordered packet.
    let data = addr(10, 60001);
    let interval = DataType::ExtendedCartesian.packet_interval_ns();
    for k in [0u64, 1, 2, 5, 4, 6] {
        push(&mut s, data, host, packet(DataType::ExtendedCartesian, 1_000_000 + k * interval, Clock::Ptp));
    }
    push(&mut s, data, host, b"junk".to_vec());
    let mut wrong_len = packet(DataType::Imu, 1, Clock::Ptp);
    wrong_len.push(0);
    push(&mut s, data, host, wrong_len);
    let sum = s.finish(CaptureFormat::Pcap, Default::default(), None, None);
    let hb_counts = sum.control_frames.get("heartbeat").copied().unwrap();
    assert_eq!((hb_counts.cmd, hb_counts.ack, hb_counts.ack_ok, hb_counts.ack_error), (1, 1, 1, 0));
    let sampling = sum.control_frames.get("sampling").copied().unwrap();
    assert_eq!((sampling.ack, sampling.ack_error), (1, 1));
    assert_eq!(sum.control_frames.get("broadcast").map(|c| c.msg), Some(1));
    let hs = sum.control_frames.get("handshake").copied().unwrap();
    assert_eq!((hs.cmd, hs.ack, hs.ack_ok), (1, 1, 1));
    assert_eq!(sum.crc_failures, 1);
    assert_eq!(sum.point_packets, 6);
    assert_eq!(sum.points, 6 * 96);
    assert_eq!(sum.non_empty_points, 6 * 72);
    assert_eq!((sum.gaps, sum.lost_packets, sum.reordered), (1, 2, 1));
    assert_eq!((sum.undecodable, sum.decode_errors), (1, 1));
    assert_eq!(sum.sync_sources.get("ptp"), Some(&6));
    let dev = sum.devices.get("192.168.1.10").unwrap();
    assert_eq!((dev.control_frames, dev.point_packets, dev.lost_packets), (6, 6, 2));
    assert_eq!(sum.first_timestamp_ns, Some(1_000_000));
    assert_eq!(sum.last_timestamp_ns, Some(1_000_000 + 6 * interval));
}

// ---------------------------------------------------------------------------------------------
// The PyPI `livox-lvx` reader as a peer for our .lvx writer.

#[test]
fn livox_lvx_reads_our_writer() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..");
    let python = root.join(".venv/bin/python");
    let script = root.join("tests/peers/lvx_check.py");
    let importable = python.exists()
        && std::process::Command::new(&python).args(["-c", "import lvx"]).output().is_ok_and(|o| o.status.success());
    if !importable || !script.exists() {
        println!("skipped: livox-lvx not installed");
        return;
    }
    // livox-lvx knows data types 0-6 only; 7 and 8 are checked to be refused below.
    let path = tmp("peer.lvx");
    let mut w = LvxWriter::create(&path, 50, &devices()).unwrap();
    let types = [DataType::ExtendedCartesian, DataType::Imu, DataType::DualSpherical, DataType::Cartesian];
    let mut expect_points = 0;
    for i in 0..120u64 {
        let dt = types[(i % 4) as usize];
        expect_points += dt.firings_per_packet();
        w.write_packet((i % 2) as u8, &packet(dt, 5_000_000 + i * 1_250_000, Clock::Ptp)).unwrap();
    }
    let frames = {
        w.finish().unwrap();
        capture::open(&path).unwrap().count();
        let mut c = capture::open(&path).unwrap();
        for _ in &mut c {}
        c.stats().lvx_frames
    };
    let out = std::process::Command::new(&python).arg(&script).arg(&path).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    println!("livox-lvx read: {v}");
    assert_eq!(v["version"], serde_json::json!([1, 1, 0, 0]));
    assert_eq!(v["frame_duration"], 50);
    assert_eq!(v["devices"], 2);
    assert_eq!(v["frames"], frames);
    assert_eq!(v["packages"], 120);
    assert_eq!(v["points"], expect_points);
    assert_eq!(v["device_sn"][0], "3WEDH7600101621");
    // Our negative y (-1500 mm) comes back as 2^32 - 1500: livox-lvx reads x, y, z unsigned.
    assert_eq!(v["first_point_xyz"], serde_json::json!([4000, 4294965796u64, 4294967046u64]));

    let path7 = tmp("peer7.lvx");
    let mut w = LvxWriter::create(&path7, 50, &devices()).unwrap();
    w.write_packet(0, &packet(DataType::TripleCartesian, 1, Clock::Ptp)).unwrap();
    w.finish().unwrap();
    let out = std::process::Command::new(&python).arg(&script).arg(&path7).output().unwrap();
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    println!("livox-lvx on data type 7: {v}");
    assert!(v["error"].as_str().is_some_and(|e| e.contains("Unknown point type 7")), "{v}");
    let _ = std::fs::remove_file(&path);
    let _ = std::fs::remove_file(&path7);
}
