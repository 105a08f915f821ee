//! Assembling point packets into fixed-period scans ready for de-skew.
//!
//! Each kept point carries its firing time as an offset from the scan start, so a de-skew stage
//! can move it to the scan end with the motion in between. Scans start at multiples of the period
//! on the packets' clock, so scans of two devices on one PTP clock line up.

use crate::data::{DataHeader, DataPacket, Gap, GapDetector, Point, ReturnCounts};
use serde::{Deserialize, Serialize};
use starc_time::Stamp;

/// Which returns to keep, by their Livox tag.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TagFilter {
    /// Keep everything.
    All,
    /// FAST-LIO's rule: keep return numbers 0 and 1 (tag & 0x30 is 0x00 or 0x10).
    #[default]
    FastLio,
    /// FAST-LIO's rule and both noise confidences normal (tag & 0x0f == 0).
    Strict,
}

impl TagFilter {
    #[inline]
    pub fn keeps(self, tag: u8) -> bool {
        match self {
            Self::All => true,
            Self::FastLio => matches!(tag & 0x30, 0x00 | 0x10),
            Self::Strict => matches!(tag & 0x30, 0x00 | 0x10) && tag & 0x0f == 0,
        }
    }
}

/// Point filters in the style of FAST-LIO's preprocessing (`[scan]` in a config file).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ScanConfig {
    /// Scan period; 100 ms matches a 10 Hz LIO.
    pub period_ms: f64,
    pub tags: TagFilter,
    /// Points closer than this are dropped (the robot itself, the operator's hands).
    pub blind_m: f32,
    /// Points farther than this are dropped (0 disables).
    pub max_range_m: f32,
    /// Keep one point in this many (FAST-LIO's point_filter_num); 1 keeps all.
    pub decimation: u32,
    /// Keep only lines below this (FAST-LIO's N_SCANS; 6 on the Avia).
    pub lines: u8,
    /// Kept points per second of scan at most: a scan holds at most this times its period
    /// ([`ScanConfig::max_points`]); points beyond are cut and counted. An Avia fires at most
    /// 720,000 returns/s (triple return), so only a broken or hostile sender (one repeating a
    /// time stamp, which would grow one scan for ever) reaches the default.
    pub max_points_per_s: u32,
}

/// Default of [`ScanConfig::max_points_per_s`]: 1.4 times an Avia's triple-return rate.
pub const DEFAULT_MAX_POINTS_PER_S: u32 = 1_000_000;

impl Default for ScanConfig {
    fn default() -> Self {
        Self {
            period_ms: 100.0,
            tags: TagFilter::FastLio,
            blind_m: 0.5,
            max_range_m: 0.0,
            decimation: 1,
            lines: 6,
            max_points_per_s: DEFAULT_MAX_POINTS_PER_S,
        }
    }
}

impl ScanConfig {
    /// Checks the values; the error names the field.
    pub fn validate(&self) -> Result<(), String> {
        if !(1.0..=10_000.0).contains(&self.period_ms) {
            return Err(format!("scan.period_ms must be within 1..=10000, got {}", self.period_ms));
        }
        if self.decimation == 0 {
            return Err("scan.decimation must be at least 1".into());
        }
        if self.blind_m.is_nan() || self.max_range_m.is_nan() || self.blind_m < 0.0 || self.max_range_m < 0.0 {
            return Err("scan.blind_m and scan.max_range_m must be >= 0".into());
        }
        if self.max_points_per_s == 0 {
            return Err("scan.max_points_per_s must be at least 1".into());
        }
        Ok(())
    }

    pub fn period_ns(&self) -> u64 {
        (self.period_ms * 1e6).round() as u64
    }

    /// Points one scan holds at most: `max_points_per_s` over the period, rounded up, at least 1.
    pub fn max_points(&self) -> usize {
        let n = (f64::from(self.max_points_per_s) * self.period_ms * 1e-3).ceil();
        // period_ms <= 10 000 (validate) keeps n below 2^32 * 10: no saturation in practice.
        (n as usize).max(1)
    }
}

/// One point of a scan.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct ScanPoint {
    pub x_m: f32,
    pub y_m: f32,
    pub z_m: f32,
    pub reflectivity: u8,
    pub tag: u8,
    pub line: u8,
    /// Firing time after the scan start.
    pub offset_ns: u32,
}

/// A scan: all kept points fired in [start, start + period).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Scan {
    pub start: Stamp,
    pub period_ns: u64,
    pub points: Vec<ScanPoint>,
    /// Point packets that contributed.
    pub packets: u32,
    /// Returns seen, empty returns, and returns dropped by the filters.
    pub returns: u64,
    pub empty: u64,
    pub filtered: u64,
    /// Packets missing inside this scan, from time-stamp gaps.
    pub lost_packets: u64,
    /// Host receive time of the last packet, when known.
    pub last_host_receive: Option<Stamp>,
}

impl Scan {
    fn empty_at(start: Stamp, period_ns: u64) -> Self {
        Self {
            start,
            period_ns,
            points: Vec::new(),
            packets: 0,
            returns: 0,
            empty: 0,
            filtered: 0,
            lost_packets: 0,
            last_host_receive: None,
        }
    }

    pub fn end(&self) -> Stamp {
        Stamp::new(self.start.ns.saturating_add(self.period_ns), self.start.clock)
    }
}

/// Turns a stream of point packets of one device into scans.
#[derive(Debug)]
pub struct ScanAssembler {
    config: ScanConfig,
    period_ns: u64,
    current: Option<Scan>,
    decimation_counter: u32,
    gaps: GapDetector,
    scratch: Vec<Point>,
    late_packets: u64,
    /// `config.max_points()`, computed once.
    max_points: usize,
    /// Whether the scan in progress has been cut at `max_points` (it is counted once).
    current_cut: bool,
    cut_points: u64,
    cut_scans: u64,
    non_finite_points: u64,
}

impl ScanAssembler {
    pub fn new(config: ScanConfig) -> Result<Self, String> {
        config.validate()?;
        let period_ns = config.period_ns();
        let max_points = config.max_points();
        Ok(Self {
            config,
            period_ns,
            current: None,
            decimation_counter: 0,
            gaps: GapDetector::new(),
            scratch: Vec::new(),
            late_packets: 0,
            max_points,
            current_cut: false,
            cut_points: 0,
            cut_scans: 0,
            non_finite_points: 0,
        })
    }

    pub fn config(&self) -> &ScanConfig {
        &self.config
    }

    fn aligned_start(&self, t: Stamp) -> Stamp {
        Stamp::new(t.ns - t.ns % self.period_ns, t.clock)
    }

    /// Adds a point packet (IMU packets are ignored) and appends finished scans to `done`.
    pub fn push(&mut self, packet: &DataPacket<'_>, host_receive: Option<Stamp>, done: &mut Vec<Scan>) {
        if packet.is_imu() {
            return;
        }
        let mut scratch = std::mem::take(&mut self.scratch);
        scratch.clear();
        let counts = packet.decode_points(&mut scratch);
        self.push_points(&packet.header, &scratch, counts, host_receive, done);
        self.scratch = scratch;
    }

    /// Adds the points of a packet someone already decoded (with [`DataPacket::decode_points`]),
    /// so that a consumer that also wants the raw points decodes each packet once.
    pub fn push_points(
        &mut self,
        header: &DataHeader,
        points: &[Point],
        counts: ReturnCounts,
        host_receive: Option<Stamp>,
        done: &mut Vec<Scan>,
    ) {
        let stamp = header.timestamp;
        let gap = self.gaps.observe(stamp, header.data_type.packet_interval_ns());
        let mut counted_packet = false;
        let mut late = false;
        for p in points {
            let t = Stamp::new(stamp.ns.saturating_add(u64::from(p.offset_ns)), stamp.clock);
            if !self.roll_over(t, done) {
                late = true;
                continue;
            }
            let Some(scan) = self.current.as_mut() else { continue };
            if !counted_packet {
                count_packet(scan, counts, gap, host_receive);
                counted_packet = true;
            }
            if !(p.x_m.is_finite() && p.y_m.is_finite() && p.z_m.is_finite()) {
                // Wire points are integers and always finite; points handed in decoded by
                // someone else may not be, and one NaN poisons the LIO's map.
                self.non_finite_points += 1;
                scan.filtered += 1;
                continue;
            }
            if !keep(&self.config, p, &mut self.decimation_counter) {
                scan.filtered += 1;
                continue;
            }
            if scan.points.len() >= self.max_points {
                // A scan only gets here when its sender keeps stamping into one period (a
                // repeated time stamp): keep what it has, never grow it further.
                self.cut_points += 1;
                if !self.current_cut {
                    self.current_cut = true;
                    self.cut_scans += 1;
                }
                continue;
            }
            scan.points.push(ScanPoint {
                x_m: p.x_m,
                y_m: p.y_m,
                z_m: p.z_m,
                reflectivity: p.reflectivity,
                tag: p.tag,
                line: p.line,
                offset_ns: (t.ns - scan.start.ns) as u32,
            });
        }
        // A packet of empty returns still counts towards the scan it fell in.
        if points.is_empty() {
            if !self.roll_over(stamp, done) {
                late = true;
            } else if let Some(scan) = self.current.as_mut() {
                count_packet(scan, counts, gap, host_receive);
            }
        }
        self.late_packets += u64::from(late);
    }

    /// Makes `t` fall inside the current scan, finishing the scan in progress when time has
    /// left it. Returns false for a point late for the scan in progress (a reordered packet,
    /// less than a period behind), which is then dropped: its scan is already out.
    fn roll_over(&mut self, t: Stamp, done: &mut Vec<Scan>) -> bool {
        if let Some(scan) = &self.current {
            if scan.start.clock == t.clock {
                if t.ns >= scan.start.ns && t.ns - scan.start.ns < self.period_ns {
                    return true;
                }
                if t.ns < scan.start.ns && scan.start.ns - t.ns <= self.period_ns {
                    return false;
                }
            }
            // Time moved on, or jumped (a resynchronised clock, another clock, a wild stamp).
            done.extend(self.current.take());
        }
        self.current = Some(Scan::empty_at(self.aligned_start(t), self.period_ns));
        self.current_cut = false;
        true
    }

    /// Finishes the scan in progress (end of a capture or a stop).
    pub fn finish(&mut self) -> Option<Scan> {
        self.current.take()
    }

    pub fn lost_packets(&self) -> u64 {
        self.gaps.lost_packets
    }

    /// Packets (some of) whose points arrived after their scan was finished; those points are
    /// dropped.
    pub fn late_packets(&self) -> u64 {
        self.late_packets
    }

    /// Points dropped because their scan already held [`ScanConfig::max_points`].
    pub fn cut_points(&self) -> u64 {
        self.cut_points
    }

    /// Scans that reached [`ScanConfig::max_points`] and were cut there.
    pub fn cut_scans(&self) -> u64 {
        self.cut_scans
    }

    /// Points with a NaN or infinite coordinate, dropped (counted in their scan's `filtered` too).
    pub fn non_finite_points(&self) -> u64 {
        self.non_finite_points
    }

    /// Points held by the scan in progress (never more than [`ScanConfig::max_points`]).
    pub fn pending_points(&self) -> usize {
        self.current.as_ref().map_or(0, |s| s.points.len())
    }
}

fn count_packet(scan: &mut Scan, counts: ReturnCounts, gap: Option<Gap>, host_receive: Option<Stamp>) {
    // Saturating: a sender repeating one time stamp feeds one scan for as long as it likes.
    scan.packets = scan.packets.saturating_add(1);
    scan.returns = scan.returns.saturating_add(u64::from(counts.returns));
    scan.empty = scan.empty.saturating_add(u64::from(counts.empty));
    scan.lost_packets = scan.lost_packets.saturating_add(gap.map_or(0, |g| g.lost_packets));
    scan.last_host_receive = host_receive.or(scan.last_host_receive);
}

#[inline]
fn keep(config: &ScanConfig, p: &Point, decimation_counter: &mut u32) -> bool {
    if p.line >= config.lines || !config.tags.keeps(p.tag) {
        return false;
    }
    let r2 = p.x_m * p.x_m + p.y_m * p.y_m + p.z_m * p.z_m;
    if r2 < config.blind_m * config.blind_m {
        return false;
    }
    if config.max_range_m > 0.0 && r2 > config.max_range_m * config.max_range_m {
        return false;
    }
    *decimation_counter = decimation_counter.wrapping_add(1);
    (*decimation_counter - 1).is_multiple_of(config.decimation)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::{encode_point_packet, DataHeader, DataType, Point, Return, ReturnCounts, StatusWord};
    use starc_time::Clock;

    fn packet_bytes(ts_ns: u64, tag: u8, x_m: f32) -> Vec<u8> {
        let h = DataHeader {
            version: 5,
            slot: 1,
            lidar_id: 1,
            status: StatusWord::from_raw(0),
            data_type: DataType::ExtendedCartesian,
            timestamp: Stamp::new(ts_ns, Clock::Ptp),
        };
        let returns = vec![Return { x_m, y_m: x_m / 3.0, z_m: x_m / 6.0, reflectivity: 10, tag }; 96];
        let mut out = Vec::new();
        let _ = encode_point_packet(&h, &returns, &mut out);
        out
    }

    fn run(config: ScanConfig, packets: &[Vec<u8>]) -> Vec<Scan> {
        let Ok(mut a) = ScanAssembler::new(config) else { return Vec::new() };
        let mut done = Vec::new();
        for b in packets {
            if let Ok(p) = DataPacket::parse(b) {
                a.push(&p, None, &mut done);
            }
        }
        done.extend(a.finish());
        done
    }

    #[test]
    fn one_second_of_packets_makes_ten_scans_with_offsets_inside_the_period() {
        let packets: Vec<Vec<u8>> = (0..2500).map(|i| packet_bytes(5_000_000_000 + i * 400_008, 0, 3.0)).collect();
        let scans = run(ScanConfig::default(), &packets);
        assert_eq!(scans.len(), 11);
        let total: usize = scans.iter().map(|s| s.points.len()).sum();
        assert_eq!(total, 2500 * 96);
        for s in &scans {
            assert_eq!(s.start.ns % 100_000_000, 0);
            assert!(s.points.iter().all(|p| u64::from(p.offset_ns) < s.period_ns));
            assert!(s.points.windows(2).all(|w| w[0].offset_ns <= w[1].offset_ns));
        }
        let full = scans[1].points.len();
        assert!((24_000 - 96..=24_000 + 96).contains(&full), "a full scan holds {full} points");
    }

    #[test]
    fn filters_blind_tags_and_decimation() {
        let near = vec![packet_bytes(0, 0, 0.1)];
        assert_eq!(run(ScanConfig::default(), &near)[0].points.len(), 0);
        let noisy = vec![packet_bytes(0, 0x20, 3.0)];
        let s = &run(ScanConfig::default(), &noisy)[0];
        assert_eq!((s.points.len(), s.filtered), (0, 96));
        let all = ScanConfig { tags: TagFilter::All, decimation: 3, ..ScanConfig::default() };
        assert_eq!(run(all, &noisy)[0].points.len(), 32);
    }

    #[test]
    fn lost_packets_are_counted_in_their_scan() {
        let packets: Vec<Vec<u8>> =
            (0..100u64).filter(|i| *i != 50 && *i != 51).map(|i| packet_bytes(i * 400_000, 0, 3.0)).collect();
        let scans = run(ScanConfig::default(), &packets);
        assert_eq!(scans.iter().map(|s| s.lost_packets).sum::<u64>(), 2);
    }

    #[test]
    fn a_wild_time_stamp_costs_at_most_its_own_scans() {
        let mut packets: Vec<Vec<u8>> = (0..500u64).map(|i| packet_bytes(i * 400_000, 0, 3.0)).collect();
        packets[100] = packet_bytes(u64::MAX / 2, 0, 3.0);
        packets[300] = packet_bytes(3, 0, 3.0);
        let scans = run(ScanConfig::default(), &packets);
        let total: usize = scans.iter().map(|s| s.points.len()).sum();
        // Everything but the packet stamped at 3 ns (late for the scan in progress) is kept.
        assert_eq!(total, 499 * 96);
        assert!(scans.iter().filter(|s| s.points.len() > 20_000).count() >= 1);
    }

    #[test]
    fn a_packet_reordered_across_a_scan_boundary_is_dropped_and_counted() {
        let mut packets: Vec<Vec<u8>> = (0..500u64).map(|i| packet_bytes(i * 400_000, 0, 3.0)).collect();
        packets.swap(249, 250);
        let Ok(mut a) = ScanAssembler::new(ScanConfig::default()) else { return };
        let mut done = Vec::new();
        for b in &packets {
            if let Ok(p) = DataPacket::parse(b) {
                a.push(&p, None, &mut done);
            }
        }
        done.extend(a.finish());
        assert_eq!(a.late_packets(), 1);
        assert_eq!(done.iter().map(|s| s.points.len()).sum::<usize>(), 499 * 96);
        assert!(done.iter().all(|s| s.points.iter().all(|p| u64::from(p.offset_ns) < s.period_ns)));
    }

    #[test]
    fn a_repeated_time_stamp_cannot_grow_a_scan_past_its_cap() {
        // 20 000 packets all stamped 5 s: without the cap, one scan of 1.92 million points.
        let config = ScanConfig::default();
        let cap = config.max_points();
        assert_eq!(cap, 100_000);
        let Ok(mut a) = ScanAssembler::new(config) else { return };
        let bytes = packet_bytes(5_000_000_000, 0, 3.0);
        let Ok(p) = DataPacket::parse(&bytes) else { return };
        let mut done = Vec::new();
        for _ in 0..20_000 {
            a.push(&p, None, &mut done);
            assert!(a.pending_points() <= cap);
        }
        assert!(done.is_empty());
        assert_eq!(a.pending_points(), cap);
        assert_eq!(a.cut_points(), 20_000 * 96 - cap as u64);
        assert_eq!(a.cut_scans(), 1);
        // The next period starts a fresh scan, uncut; the cut one comes out with its packets.
        let next = packet_bytes(5_100_000_000, 0, 3.0);
        if let Ok(p) = DataPacket::parse(&next) {
            a.push(&p, None, &mut done);
        }
        assert_eq!(done.len(), 1);
        assert_eq!((done[0].points.len(), done[0].packets), (cap, 20_000));
        assert_eq!(a.pending_points(), 96);
        assert_eq!(a.cut_scans(), 1);
    }

    #[test]
    fn the_cap_scales_with_the_period_and_is_configurable() {
        let long = ScanConfig { period_ms: 1000.0, ..ScanConfig::default() };
        assert_eq!(long.max_points(), 1_000_000);
        let small = ScanConfig { max_points_per_s: 1000, ..ScanConfig::default() };
        assert_eq!(small.max_points(), 100);
        let packets: Vec<Vec<u8>> = (0..10u64).map(|i| packet_bytes(i * 400_000, 0, 3.0)).collect();
        let scans = run(small, &packets);
        assert_eq!(scans.iter().map(|s| s.points.len()).collect::<Vec<_>>(), vec![100]);
        assert!(ScanAssembler::new(ScanConfig { max_points_per_s: 0, ..ScanConfig::default() }).is_err());
    }

    #[test]
    fn non_finite_points_are_dropped_and_counted() {
        let Ok(mut a) = ScanAssembler::new(ScanConfig::default()) else { return };
        let header = DataHeader {
            version: 5,
            slot: 1,
            lidar_id: 1,
            status: StatusWord::from_raw(0),
            data_type: DataType::ExtendedCartesian,
            timestamp: Stamp::new(0, Clock::Ptp),
        };
        let good = Point { x_m: 3.0, y_m: 1.0, z_m: 0.5, ..Point::default() };
        let points = [
            good,
            Point { x_m: f32::NAN, ..good },
            Point { y_m: f32::INFINITY, ..good },
            Point { z_m: f32::NEG_INFINITY, ..good },
            good,
        ];
        let mut done = Vec::new();
        a.push_points(&header, &points, ReturnCounts { returns: 5, empty: 0 }, None, &mut done);
        done.extend(a.finish());
        assert_eq!(a.non_finite_points(), 3);
        assert_eq!((done[0].points.len(), done[0].filtered), (2, 3));
        assert!(done[0].points.iter().all(|p| p.x_m.is_finite() && p.y_m.is_finite() && p.z_m.is_finite()));
    }

    #[test]
    fn bad_configs_are_refused() {
        assert!(ScanAssembler::new(ScanConfig { decimation: 0, ..ScanConfig::default() }).is_err());
        assert!(ScanAssembler::new(ScanConfig { period_ms: 0.1, ..ScanConfig::default() }).is_err());
        assert!(ScanAssembler::new(ScanConfig { blind_m: f32::NAN, ..ScanConfig::default() }).is_err());
    }
}
