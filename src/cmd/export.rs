//! `starc export FILE --format pcd|ply --out DIR [--period-ms 100] [--device IP|INDEX]
//! [--filter fastlio|all]`: the scans of a capture as point-cloud files.
//!
//! Datagrams from the capture (pcap, pcapng, .lvx) are parsed as Livox data packets, grouped by
//! device (source IPv4 address, or .lvx device index), assembled into fixed-period scans by
//! [`ScanAssembler`], and written as `DIR/<device>/scan_000000.<ext>`, one file per scan, with the
//! scan start in the file's `starc` comment and each point's firing time after it.

use anyhow::Context;
use starc_livox::capture::{self, Datagram};
use starc_livox::data::DataPacket;
use starc_livox::scan::{Scan, ScanAssembler, ScanConfig, TagFilter};
use starc_pipeline::cloud::{self, CloudFormat};
use starc_time::Clock;
use std::collections::BTreeMap;
use std::fmt;
use std::io::{IsTerminal, Write as _};
use std::net::Ipv4Addr;
use std::path::{Path, PathBuf};
use std::str::FromStr;
use std::time::{Duration, Instant};

#[derive(clap::Args)]
pub struct Args {
    /// Capture file: pcap, pcapng or .lvx (recognised by its first bytes).
    pub file: PathBuf,
    /// Output format: pcd or ply (binary), pcd-ascii, ply-ascii, or kitti (.bin).
    #[arg(long, default_value = "pcd")]
    pub format: CloudFormat,
    /// Output directory; each device gets a sub-directory named after it.
    #[arg(long)]
    pub out: PathBuf,
    /// Scan period in milliseconds.
    #[arg(long, default_value_t = 100.0)]
    pub period_ms: f64,
    /// Export one device only: its source IPv4 address (pcap, pcapng) or its .lvx device index.
    #[arg(long)]
    pub device: Option<DeviceSelector>,
    /// Which returns to keep by their Livox tag: fastlio (return 0 or 1), strict (and no noise
    /// flags), or all.
    #[arg(long, value_enum, default_value_t = Filter::Fastlio)]
    pub filter: Filter,
    /// Drop points closer than this (the robot itself); 0 keeps everything.
    #[arg(long, default_value_t = 0.5)]
    pub blind_m: f32,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Filter {
    Fastlio,
    Strict,
    All,
}

impl Filter {
    fn name(self) -> &'static str {
        match self {
            Self::Fastlio => "fastlio",
            Self::Strict => "strict",
            Self::All => "all",
        }
    }
}

impl From<Filter> for TagFilter {
    fn from(f: Filter) -> Self {
        match f {
            Filter::Fastlio => TagFilter::FastLio,
            Filter::Strict => TagFilter::Strict,
            Filter::All => TagFilter::All,
        }
    }
}

/// A device as the capture tells them apart.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum DeviceKey {
    /// .lvx device index.
    Lvx(u8),
    /// Source address of the datagrams (pcap, pcapng).
    Ip(Ipv4Addr),
    /// Neither is known.
    Unknown,
}

impl DeviceKey {
    pub fn of(d: &Datagram) -> Self {
        match (d.device_index, d.src) {
            (Some(i), _) => Self::Lvx(i),
            (None, Some(src)) => Self::Ip(*src.ip()),
            (None, None) => Self::Unknown,
        }
    }
}

impl fmt::Display for DeviceKey {
    /// Also the name of the device's output directory.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Lvx(i) => write!(f, "device_{i}"),
            Self::Ip(ip) => write!(f, "{ip}"),
            Self::Unknown => f.write_str("unknown"),
        }
    }
}

/// `--device`: an IPv4 address or an .lvx device index.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DeviceSelector {
    Ip(Ipv4Addr),
    Index(u8),
}

impl DeviceSelector {
    pub fn matches(self, key: DeviceKey) -> bool {
        match (self, key) {
            (Self::Ip(a), DeviceKey::Ip(b)) => a == b,
            (Self::Index(a), DeviceKey::Lvx(b)) => a == b,
            _ => false,
        }
    }
}

impl FromStr for DeviceSelector {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        if let Ok(ip) = s.parse::<Ipv4Addr>() {
            return Ok(Self::Ip(ip));
        }
        s.parse::<u8>()
            .map(Self::Index)
            .map_err(|_| format!("{s:?} is neither an IPv4 address nor a device index (0-255)"))
    }
}

impl fmt::Display for DeviceSelector {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Ip(ip) => write!(f, "{ip}"),
            Self::Index(i) => write!(f, "device index {i}"),
        }
    }
}

/// What happened to one device's packets.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct DeviceStats {
    pub point_packets: u64,
    pub imu_packets: u64,
    /// Packets older than the scan in progress (reordered in the capture): their points are dropped.
    pub late_packets: u64,
    /// Packets missing, from time-stamp gaps.
    pub lost_packets: u64,
    pub scans: u64,
    pub points: u64,
    pub returns: u64,
    pub empty: u64,
    pub filtered: u64,
}

/// What an export did.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Summary {
    pub datagrams: u64,
    /// Datagrams that are not Livox data packets (control traffic, other protocols).
    pub other_datagrams: u64,
    /// Datagrams of devices left out by `--device`.
    pub unselected_datagrams: u64,
    pub devices: BTreeMap<DeviceKey, DeviceStats>,
    /// Set when reading the capture stopped early; everything before it was exported.
    pub read_error: Option<String>,
}

impl Summary {
    fn scans(&self) -> u64 {
        self.devices.values().map(|d| d.scans).sum()
    }

    fn points(&self) -> u64 {
        self.devices.values().map(|d| d.points).sum()
    }
}

struct Device {
    dir: PathBuf,
    assembler: ScanAssembler,
    stats: DeviceStats,
    done: Vec<Scan>,
}

impl Device {
    /// Writes the finished scans.
    fn flush(&mut self, format: CloudFormat) -> anyhow::Result<()> {
        for scan in self.done.drain(..) {
            let path = self.dir.join(format!("scan_{:06}.{}", self.stats.scans, format.extension()));
            if self.stats.scans == 0 {
                std::fs::create_dir_all(&self.dir).with_context(|| format!("creating {}", self.dir.display()))?;
            }
            cloud::write(&path, &starc_bridge::livox::scan_to_cloud(&scan), format)?;
            self.stats.scans += 1;
            self.stats.points += scan.points.len() as u64;
            self.stats.returns += scan.returns;
            self.stats.empty += scan.empty;
            self.stats.filtered += scan.filtered;
        }
        Ok(())
    }
}

/// The export itself, without printing (tests call it).
pub fn export(
    capture: impl Iterator<Item = starc_livox::Result<Datagram>>,
    out: &Path,
    format: CloudFormat,
    config: &ScanConfig,
    device: Option<DeviceSelector>,
    mut progress: impl FnMut(&Summary),
) -> anyhow::Result<Summary> {
    // Fails early on a bad --period-ms and the like.
    ScanAssembler::new(config.clone()).map_err(|e| anyhow::anyhow!("{e}"))?;
    let mut summary = Summary::default();
    let mut devices: BTreeMap<DeviceKey, Device> = BTreeMap::new();
    for item in capture {
        let datagram = match item {
            Ok(d) => d,
            Err(e) => {
                summary.read_error = Some(e.to_string());
                break;
            }
        };
        summary.datagrams += 1;
        let key = DeviceKey::of(&datagram);
        if device.is_some_and(|sel| !sel.matches(key)) {
            summary.unselected_datagrams += 1;
            continue;
        }
        let Ok(packet) = DataPacket::parse(&datagram.payload) else {
            summary.other_datagrams += 1;
            continue;
        };
        let dev = match devices.entry(key) {
            std::collections::btree_map::Entry::Occupied(e) => e.into_mut(),
            std::collections::btree_map::Entry::Vacant(e) => e.insert(Device {
                dir: out.join(key.to_string()),
                assembler: ScanAssembler::new(config.clone()).map_err(|e| anyhow::anyhow!("{e}"))?,
                stats: DeviceStats::default(),
                done: Vec::new(),
            }),
        };
        if packet.is_imu() {
            dev.stats.imu_packets += 1;
            continue;
        }
        dev.stats.point_packets += 1;
        let host = (datagram.time.clock == Clock::Host).then_some(datagram.time);
        dev.assembler.push(&packet, host, &mut dev.done);
        if !dev.done.is_empty() {
            dev.flush(format)?;
            summary.devices.insert(key, dev.stats.clone());
            progress(&summary);
        }
    }
    for (key, dev) in devices.iter_mut() {
        dev.done.extend(dev.assembler.finish());
        dev.flush(format)?;
        dev.stats.lost_packets = dev.assembler.lost_packets();
        dev.stats.late_packets = dev.assembler.late_packets();
        summary.devices.insert(*key, dev.stats.clone());
    }
    Ok(summary)
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let config = ScanConfig {
        period_ms: args.period_ms,
        tags: args.filter.into(),
        blind_m: args.blind_m,
        ..ScanConfig::default()
    };
    config.validate().map_err(|e| anyhow::anyhow!("{e}"))?;
    let cap = capture::open(&args.file).with_context(|| format!("opening {}", args.file.display()))?;
    let started = Instant::now();
    let show = std::io::stderr().is_terminal();
    let mut last = Instant::now();
    let summary = export(cap, &args.out, args.format, &config, args.device, |s| {
        if show && last.elapsed() >= Duration::from_millis(200) {
            last = Instant::now();
            eprint!("\r{} datagrams, {} scans, {} points written   ", s.datagrams, s.scans(), s.points());
            let _ = std::io::stderr().flush();
        }
    })?;
    if show {
        eprint!("\r{:60}\r", "");
    }
    print!("{}", report(&args, &summary, started.elapsed()));
    if let Some(sel) = args.device {
        if summary.devices.is_empty() {
            anyhow::bail!("no data packets from {sel} in {}", args.file.display());
        }
    }
    if let Some(e) = &summary.read_error {
        anyhow::bail!("{}: reading stopped early (everything before was exported): {e}", args.file.display());
    }
    Ok(())
}

fn report(args: &Args, s: &Summary, elapsed: Duration) -> String {
    use std::fmt::Write as _;
    let mut o = String::new();
    let _ = writeln!(
        o,
        "{}: {} datagrams ({} not Livox data, {} from other devices) in {:.2} s",
        args.file.display(),
        s.datagrams,
        s.other_datagrams,
        s.unselected_datagrams,
        elapsed.as_secs_f64()
    );
    for (key, d) in &s.devices {
        let _ = writeln!(
            o,
            "  {key}: {} scans, {} points -> {} ({} point packets, {} IMU, {} lost, {} late dropped; \
             returns {}, empty {}, filtered {})",
            d.scans,
            d.points,
            args.out.join(key.to_string()).display(),
            d.point_packets,
            d.imu_packets,
            d.lost_packets,
            d.late_packets,
            d.returns,
            d.empty,
            d.filtered
        );
    }
    let _ = writeln!(
        o,
        "total: {} scans, {} points as {} ({} ms scans, filter {})",
        s.scans(),
        s.points(),
        args.format,
        args.period_ms,
        args.filter.name()
    );
    o
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use starc_livox::capture::pcap::PcapWriter;
    use starc_livox::capture::TsPrecision;
    use starc_livox::data::{encode_point_packet, DataHeader, DataType, Return, StatusWord};
    use starc_time::Stamp;
    use std::net::SocketAddrV4;

    fn packet(ts_ns: u64, x_m: f32) -> Vec<u8> {
        let h = DataHeader {
            version: 5,
            slot: 1,
            lidar_id: 1,
            status: StatusWord::from_raw(0),
            data_type: DataType::ExtendedCartesian,
            timestamp: Stamp::new(ts_ns, Clock::Ptp),
        };
        let returns: Vec<Return> = (0..96)
            .map(
                |i| if i == 5 { Return::EMPTY } else { Return { x_m, y_m: 1.0, z_m: 0.5, reflectivity: i, tag: 0x10 } },
            )
            .collect();
        let mut out = Vec::new();
        encode_point_packet(&h, &returns, &mut out).unwrap();
        out
    }

    fn datagram(src: [u8; 4], payload: Vec<u8>) -> starc_livox::Result<Datagram> {
        Ok(Datagram {
            time: Stamp::new(1, Clock::Host),
            src: Some(SocketAddrV4::new(src.into(), 60001)),
            dst: Some(SocketAddrV4::new([192, 168, 1, 50].into(), 56001)),
            device_index: None,
            payload,
        })
    }

    #[test]
    fn two_devices_reordering_and_junk() {
        let dir = tempfile::tempdir().unwrap();
        let mut input = Vec::new();
        // 0.5 s of two devices, one packet reordered across a scan boundary, plus junk.
        for i in 0..1250u64 {
            input.push(datagram([192, 168, 1, 100], packet(1_000_000_000 + i * 400_000, 3.0)));
            input.push(datagram([192, 168, 1, 101], packet(1_000_000_000 + i * 400_000, -4.0)));
        }
        input.swap(2 * 249, 2 * 250);
        input.push(datagram([10, 0, 0, 1], vec![0xAA, 1, 2]));
        let config = ScanConfig::default();
        let s = export(input.into_iter(), dir.path(), CloudFormat::PcdBinary, &config, None, |_| {}).unwrap();
        assert_eq!((s.datagrams, s.other_datagrams), (2501, 1));
        assert_eq!(s.devices.len(), 2);
        let a = &s.devices[&DeviceKey::Ip([192, 168, 1, 100].into())];
        assert_eq!(a.scans, 5);
        assert_eq!(a.late_packets, 1);
        assert_eq!(a.points + a.empty + a.filtered, a.returns);
        let files: Vec<_> = std::fs::read_dir(dir.path().join("192.168.1.100")).unwrap().collect();
        assert_eq!(files.len(), 5);
        let first = cloud::read(&dir.path().join("192.168.1.100/scan_000000.pcd")).unwrap();
        assert_eq!(first.start, Some(Stamp::new(1_000_000_000, Clock::Ptp)));
        assert!(first.points.iter().all(|p| (p.x_m - 3.0).abs() < 1e-6 && u64::from(p.offset_ns) < 100_000_000));
        let b = cloud::read(&dir.path().join("192.168.1.101/scan_000004.pcd")).unwrap();
        assert!(!b.is_empty() && b.points.iter().all(|p| (p.x_m + 4.0).abs() < 1e-6));
        assert_eq!(s.devices[&DeviceKey::Ip([192, 168, 1, 101].into())].points, 1250 * 95);
    }

    #[test]
    fn device_selection_and_bad_periods() {
        let dir = tempfile::tempdir().unwrap();
        let input = || {
            vec![
                datagram([192, 168, 1, 100], packet(0, 3.0)),
                datagram([192, 168, 1, 101], packet(0, 3.0)),
                Ok(Datagram { device_index: Some(2), ..datagram([0, 0, 0, 0], packet(0, 3.0)).unwrap() }),
            ]
            .into_iter()
        };
        let config = ScanConfig::default();
        let sel = "192.168.1.101".parse::<DeviceSelector>().ok();
        let s = export(input(), dir.path(), CloudFormat::PlyBinary, &config, sel, |_| {}).unwrap();
        assert_eq!(s.devices.keys().copied().collect::<Vec<_>>(), vec![DeviceKey::Ip([192, 168, 1, 101].into())]);
        assert_eq!(s.unselected_datagrams, 2);
        let sel = "2".parse::<DeviceSelector>().ok();
        let s = export(input(), dir.path(), CloudFormat::Kitti, &config, sel, |_| {}).unwrap();
        assert_eq!(s.devices.keys().copied().collect::<Vec<_>>(), vec![DeviceKey::Lvx(2)]);
        assert!(dir.path().join("device_2/scan_000000.bin").is_file());
        assert!("300".parse::<DeviceSelector>().is_err());
        let bad = ScanConfig { period_ms: 0.0, ..ScanConfig::default() };
        assert!(export(input(), dir.path(), CloudFormat::PcdBinary, &bad, None, |_| {}).is_err());
    }

    #[test]
    fn pcap_file_round_trip_through_capture_open() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("two_scans.pcap");
        let mut w = PcapWriter::create(&path, TsPrecision::Nano).unwrap();
        let (src, dst) =
            (SocketAddrV4::new([192, 168, 1, 100].into(), 60001), SocketAddrV4::new([192, 168, 1, 5].into(), 56001));
        for i in 0..500u64 {
            w.write_udp(5_000_000_000 + i * 400_000, src, dst, &packet(7_000_000_000 + i * 400_000, 2.0)).unwrap();
        }
        w.finish().unwrap();
        let out = dir.path().join("out");
        let config = ScanConfig::default();
        let s = export(capture::open(&path).unwrap(), &out, CloudFormat::PcdAscii, &config, None, |_| {}).unwrap();
        let d = &s.devices[&DeviceKey::Ip([192, 168, 1, 100].into())];
        assert_eq!((d.scans, d.points, d.point_packets), (2, 500 * 95, 500));
        let total: usize =
            (0..2).map(|i| cloud::read(&out.join(format!("192.168.1.100/scan_{i:06}.pcd"))).unwrap().len()).sum();
        assert_eq!(total, 500 * 95);
    }

    #[test]
    fn real_tele15_capture() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data/livox/tele15_small.pcap");
        if !path.is_file() {
            println!("skipping: {} is absent", path.display());
            return;
        }
        let dir = tempfile::tempdir().unwrap();
        let config = ScanConfig { tags: TagFilter::All, blind_m: 0.0, ..ScanConfig::default() };
        let s =
            export(capture::open(&path).unwrap(), dir.path(), CloudFormat::PlyBinary, &config, None, |_| {}).unwrap();
        assert_eq!(s.read_error, None);
        assert_eq!(s.devices.len(), 1, "{:?}", s.devices.keys());
        let d = s.devices.values().next().unwrap();
        assert_eq!((d.point_packets, d.imu_packets, d.late_packets), (926, 74, 0));
        assert_eq!((d.returns, d.empty, d.filtered), (926 * 96, 52, 0));
        assert_eq!(d.points, 926 * 96 - 52);
        let key = s.devices.keys().next().unwrap().to_string();
        let mut read_back = 0;
        for i in 0..d.scans {
            let c = cloud::read(&dir.path().join(&key).join(format!("scan_{i:06}.ply"))).unwrap();
            assert_eq!(c.start.map(|t| t.clock), Some(Clock::Ptp));
            read_back += c.len() as u64;
        }
        assert_eq!(read_back, d.points);
    }
}
