//! What a capture holds: packet and point counts, time stamps, loss, control traffic, devices.
//!
//! Pure library code behind `starc inspect`; the JSON keys are documented in docs/inspect.md and
//! are stable. Points are counted, never decoded ([`DataPacket::count_returns`]).

use super::{Capture, CaptureFormat, Datagram, LvxHeader, ReadStats};
use crate::control::{Body, CmdType, CommandId, ControlFrame, RawFrame};
use crate::data::{DataPacket, DataType, GapDetector, SyncState};
use crate::error::LivoxError;
use crate::ports::DEVICE_CMD_PORT;
use serde::Serialize;
use starc_time::Clock;
use std::collections::{BTreeMap, HashMap};
use std::net::Ipv4Addr;

/// Counts of one control command.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct ControlCounts {
    pub cmd: u64,
    pub ack: u64,
    pub msg: u64,
    /// ACKs whose return code is 0.
    pub ack_ok: u64,
    /// ACKs whose return code is not 0.
    pub ack_error: u64,
}

/// Traffic of one device (a source IPv4 address, or an .lvx device index).
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct DeviceSummary {
    /// Data packets (points and IMU).
    pub packets: u64,
    pub point_packets: u64,
    pub imu_packets: u64,
    /// Returns, empty ones included.
    pub points: u64,
    pub non_empty_points: u64,
    pub gaps: u64,
    pub lost_packets: u64,
    pub reordered: u64,
    /// Control frames to or from the device.
    pub control_frames: u64,
    /// From the .lvx device list.
    pub lidar_sn: Option<String>,
    pub device_type: Option<u8>,
}

/// Everything `starc inspect` reports.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct CaptureSummary {
    pub format: CaptureFormat,
    /// Datagrams (pcap, pcapng) or packages (.lvx) read.
    pub records: u64,
    pub point_packets: u64,
    /// Returns in point packets, empty ones included.
    pub points: u64,
    pub non_empty_points: u64,
    pub imu_packets: u64,
    /// Data packets by data type name (only types seen).
    pub data_types: BTreeMap<String, u64>,
    /// Data packets by time stamp type: none, ptp, gps, pps (all four always present).
    pub timestamp_types: BTreeMap<String, u64>,
    /// Data packets by the status word's time sync state (only states seen).
    pub sync_sources: BTreeMap<String, u64>,
    /// Earliest and latest data packet stamps on `timestamp_clock` (the first packet's clock).
    pub first_timestamp_ns: Option<u64>,
    pub last_timestamp_ns: Option<u64>,
    pub timestamp_clock: Option<Clock>,
    pub duration_s: f64,
    /// Host capture times (pcap, pcapng).
    pub capture_start_ns: Option<u64>,
    pub capture_end_ns: Option<u64>,
    pub capture_duration_s: f64,
    pub gaps: u64,
    pub lost_packets: u64,
    pub reordered: u64,
    /// Stamps that jumped more than [`crate::data::gaps::CLOCK_JUMP_NS`] either way within one
    /// stream (a resynchronised clock, a corrupted stamp); not counted as loss or reordering.
    pub clock_jumps: u64,
    pub control_frames: BTreeMap<String, ControlCounts>,
    pub crc_failures: u64,
    pub decode_errors: u64,
    pub undecodable: u64,
    /// Datagrams by "source_port->destination_port" (pcap, pcapng).
    pub flows: BTreeMap<String, u64>,
    pub devices: BTreeMap<String, DeviceSummary>,
    pub read: ReadStats,
    /// Why reading stopped early, if it did (what was read before is summarized).
    pub read_error: Option<String>,
    pub lvx: Option<LvxHeader>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
enum DeviceKey {
    Ip(Ipv4Addr),
    Lvx(u8),
    Unknown,
}

impl DeviceKey {
    fn name(self) -> String {
        match self {
            Self::Ip(ip) => ip.to_string(),
            Self::Lvx(i) => format!("lvx:{i}"),
            Self::Unknown => "unknown".into(),
        }
    }
}

#[derive(Clone, Debug, Default)]
struct DeviceAcc {
    summary: DeviceSummary,
    points: GapDetector,
    imu: GapDetector,
}

/// Accumulates a summary datagram by datagram.
#[derive(Clone, Debug, Default)]
pub struct Summarizer {
    records: u64,
    point_packets: u64,
    points: u64,
    non_empty_points: u64,
    imu_packets: u64,
    data_types: [u64; 9],
    timestamp_types: [u64; 4],
    sync: BTreeMap<String, u64>,
    sync_fast: [u64; 5],
    clock: Option<Clock>,
    first_ns: u64,
    last_ns: u64,
    capture_start: Option<u64>,
    capture_end: Option<u64>,
    control: BTreeMap<String, ControlCounts>,
    crc_failures: u64,
    decode_errors: u64,
    undecodable: u64,
    flows: HashMap<(u16, u16), u64>,
    devices: HashMap<DeviceKey, DeviceAcc>,
}

impl Summarizer {
    pub fn new() -> Self {
        Self::default()
    }

    /// Counts one datagram.
    pub fn observe(&mut self, d: &Datagram) {
        self.records += 1;
        if d.time.clock == Clock::Host && d.device_index.is_none() {
            let t = d.time.ns;
            self.capture_start = Some(self.capture_start.map_or(t, |s| s.min(t)));
            self.capture_end = Some(self.capture_end.map_or(t, |e| e.max(t)));
        }
        if let (Some(s), Some(t)) = (d.src, d.dst) {
            *self.flows.entry((s.port(), t.port())).or_insert(0) += 1;
        }
        let payload = d.payload.as_slice();
        let src_control = d.src.is_some_and(|a| a.port() == DEVICE_CMD_PORT);
        let dst_control = d.dst.is_some_and(|a| a.port() == DEVICE_CMD_PORT);
        if payload.first() == Some(&crate::control::frame::START_OF_FRAME) {
            match RawFrame::decode(payload) {
                Ok(raw) => {
                    let device = match (src_control, dst_control, d.src, d.dst) {
                        (true, _, Some(a), _) | (false, true, _, Some(a)) => DeviceKey::Ip(*a.ip()),
                        _ => DeviceKey::Unknown,
                    };
                    self.control_frame(&raw, device);
                    return;
                }
                Err(e) if src_control || dst_control => {
                    match e {
                        LivoxError::BadHeaderCrc { .. } | LivoxError::BadFrameCrc { .. } => self.crc_failures += 1,
                        _ => self.decode_errors += 1,
                    }
                    return;
                }
                Err(_) => {}
            }
        }
        match DataPacket::parse(payload) {
            Ok(packet) => {
                let device = match (d.device_index, d.src) {
                    (Some(i), _) => DeviceKey::Lvx(i),
                    (None, Some(a)) => DeviceKey::Ip(*a.ip()),
                    (None, None) => DeviceKey::Unknown,
                };
                self.data_packet(&packet, device);
            }
            Err(_) if payload.first() == Some(&crate::data::packet::DATA_VERSION) || d.device_index.is_some() => {
                self.decode_errors += 1;
            }
            Err(_) => self.undecodable += 1,
        }
    }

    fn control_frame(&mut self, raw: &RawFrame<'_>, device: DeviceKey) {
        let name = match CommandId::from_set_id(raw.cmd_set, raw.cmd_id) {
            Some(id) => id.name().to_string(),
            None => format!("unknown_{}_{}", raw.cmd_set, raw.cmd_id),
        };
        let counts = self.control.entry(name).or_default();
        let decoded = ControlFrame::from_raw(raw);
        // Count by what the frame is, not its cmd_type byte: the official SDK sends its
        // handshake request with cmd_type 1 (ACK), which the decoder reads as the request it is.
        match (&decoded, raw.cmd_type) {
            (Ok(ControlFrame { body: Body::Request(_), .. }), _) | (Err(_), CmdType::Cmd) => counts.cmd += 1,
            (Ok(ControlFrame { body: Body::Response(_), .. }), _) | (Err(_), CmdType::Ack) => counts.ack += 1,
            (Ok(ControlFrame { body: Body::Message(_), .. }), _) | (Err(_), CmdType::Msg) => counts.msg += 1,
        }
        match decoded {
            Ok(frame) => {
                if let Body::Response(r) = frame.body {
                    if r.ret() == 0 {
                        counts.ack_ok += 1;
                    } else {
                        counts.ack_error += 1;
                    }
                }
            }
            Err(LivoxError::UnknownCommand { .. }) => {}
            Err(_) => self.decode_errors += 1,
        }
        if device != DeviceKey::Unknown {
            self.devices.entry(device).or_default().summary.control_frames += 1;
        }
    }

    fn data_packet(&mut self, packet: &DataPacket<'_>, device: DeviceKey) {
        let h = &packet.header;
        let dt = h.data_type;
        if let Some(n) = self.data_types.get_mut(dt as usize) {
            *n += 1;
        }
        let ts_index = match h.timestamp.clock {
            Clock::Device | Clock::Host => 0,
            Clock::Ptp => 1,
            Clock::Gps => 2,
            Clock::Pps => 3,
        };
        if let Some(n) = self.timestamp_types.get_mut(ts_index) {
            *n += 1;
        }
        match h.status.sync {
            SyncState::None => self.sync_fast[0] += 1,
            SyncState::Ptp => self.sync_fast[1] += 1,
            SyncState::Gps => self.sync_fast[2] += 1,
            SyncState::Pps => self.sync_fast[3] += 1,
            SyncState::Abnormal => self.sync_fast[4] += 1,
            SyncState::Reserved(v) => *self.sync.entry(format!("reserved_{v}")).or_insert(0) += 1,
        }
        let stamp = h.timestamp;
        match self.clock {
            None => {
                self.clock = Some(stamp.clock);
                self.first_ns = stamp.ns;
                self.last_ns = stamp.ns;
            }
            Some(c) if c == stamp.clock => {
                self.first_ns = self.first_ns.min(stamp.ns);
                self.last_ns = self.last_ns.max(stamp.ns);
            }
            Some(_) => {}
        }
        let acc = self.devices.entry(device).or_default();
        acc.summary.packets += 1;
        if dt == DataType::Imu {
            self.imu_packets += 1;
            acc.summary.imu_packets += 1;
            acc.imu.observe(stamp, dt.packet_interval_ns());
        } else {
            let counts = packet.count_returns();
            let returns = u64::from(counts.returns);
            let kept = u64::from(counts.returns.saturating_sub(counts.empty));
            self.point_packets += 1;
            self.points += returns;
            self.non_empty_points += kept;
            acc.summary.point_packets += 1;
            acc.summary.points += returns;
            acc.summary.non_empty_points += kept;
            acc.points.observe(stamp, dt.packet_interval_ns());
        }
    }

    /// The summary so far.
    pub fn finish(
        &self,
        format: CaptureFormat,
        read: ReadStats,
        lvx: Option<LvxHeader>,
        read_error: Option<String>,
    ) -> CaptureSummary {
        let data_types = DataType::ALL
            .iter()
            .zip(self.data_types)
            .filter(|(_, n)| *n > 0)
            .map(|(dt, n)| (dt.name().to_string(), n))
            .collect();
        let timestamp_types =
            ["none", "ptp", "gps", "pps"].iter().zip(self.timestamp_types).map(|(k, n)| (k.to_string(), n)).collect();
        let mut sync_sources = self.sync.clone();
        for (name, n) in ["none", "ptp", "gps", "pps", "abnormal"].iter().zip(self.sync_fast) {
            if n > 0 {
                sync_sources.insert(name.to_string(), n);
            }
        }
        let (mut gaps, mut lost, mut reordered, mut jumps) = (0, 0, 0, 0);
        let mut devices = BTreeMap::new();
        let mut keys: Vec<&DeviceKey> = self.devices.keys().collect();
        keys.sort();
        for key in keys {
            let Some(acc) = self.devices.get(key) else { continue };
            let mut summary = acc.summary.clone();
            for stream in [&acc.points, &acc.imu] {
                summary.gaps += stream.gaps;
                summary.lost_packets += stream.lost_packets;
                summary.reordered += stream.reordered;
                jumps += stream.clock_jumps;
            }
            gaps += summary.gaps;
            lost += summary.lost_packets;
            reordered += summary.reordered;
            if let (DeviceKey::Lvx(i), Some(h)) = (key, lvx.as_ref()) {
                if let Some(info) = h.device(*i) {
                    summary.lidar_sn = Some(info.lidar_sn_text());
                    summary.device_type = Some(info.device_type);
                }
            }
            devices.insert(key.name(), summary);
        }
        let span = |a: Option<u64>, b: Option<u64>| match (a, b) {
            (Some(a), Some(b)) => b.saturating_sub(a) as f64 * 1e-9,
            _ => 0.0,
        };
        let (first, last) = match self.clock {
            Some(_) => (Some(self.first_ns), Some(self.last_ns)),
            None => (None, None),
        };
        CaptureSummary {
            format,
            records: self.records,
            point_packets: self.point_packets,
            points: self.points,
            non_empty_points: self.non_empty_points,
            imu_packets: self.imu_packets,
            data_types,
            timestamp_types,
            sync_sources,
            first_timestamp_ns: first,
            last_timestamp_ns: last,
            timestamp_clock: self.clock,
            duration_s: span(first, last),
            capture_start_ns: self.capture_start,
            capture_end_ns: self.capture_end,
            capture_duration_s: span(self.capture_start, self.capture_end),
            gaps,
            lost_packets: lost,
            reordered,
            clock_jumps: jumps,
            control_frames: self.control.clone(),
            crc_failures: self.crc_failures,
            decode_errors: self.decode_errors,
            undecodable: self.undecodable,
            flows: self.flows.iter().map(|((s, d), n)| (format!("{s}->{d}"), *n)).collect(),
            devices,
            read,
            read_error,
            lvx,
        }
    }
}

/// Reads the whole capture and summarizes it. A read error stops the reading; it is reported in
/// `read_error` and what came before it is summarized.
pub fn summarize(capture: &mut Capture) -> CaptureSummary {
    let mut s = Summarizer::new();
    let mut datagram = Datagram::default();
    let mut error = None;
    loop {
        match capture.read_into(&mut datagram) {
            Ok(true) => s.observe(&datagram),
            Ok(false) => break,
            Err(e) => {
                error = Some(e.to_string());
                break;
            }
        }
    }
    s.finish(capture.format(), *capture.stats(), capture.lvx_header().cloned(), error)
}
