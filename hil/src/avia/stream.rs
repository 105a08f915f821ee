//! Point and IMU packets at the real rates, stamped from the device clock.
//!
//! The Avia fires every 4167 ns (240,000 firings/s). A point packet carries 96 firings in single
//! return mode (one packet every 400,032 ns), 48 in dual (200,016 ns) and 30 in triple
//! (125,010 ns); its time stamp is its first firing, and firings are contiguous across packets.
//! IMU packets (data_type 6) come every 5 ms. A packet is sent once its last firing is done, so
//! the transport may poll in bursts (every 1-2 ms) without moving any stamp.

use crate::avia::source::{FiringRequest, PointSource};
use serde::{Deserialize, Serialize};
use starc_livox::control::ReturnMode;
use starc_livox::data::packet::DATA_VERSION;
use starc_livox::data::{
    encode_imu_packet, encode_point_packet, DataHeader, DataType, Return, StatusWord, SyncState, SystemStatus,
};
use starc_time::{Clock, Stamp};
use std::fmt;
use std::str::FromStr;

pub const NS_PER_S: u64 = 1_000_000_000;
/// IMU packets are pushed at 200 Hz.
pub const IMU_INTERVAL_NS: u64 = 5_000_000;

/// Where the device's packet time stamps come from (the wire's timestamp_type).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TimeSource {
    /// No synchronisation: the free-running device clock (timestamp_type 0).
    None,
    /// PTP (timestamp_type 1), the default of a device on a PTP network.
    #[default]
    Ptp,
    /// GPS/UTC (timestamp_type 3): a GPS receiver's NMEA + PPS, or the host's UTC push.
    Gps,
    /// PPS only (timestamp_type 4): nanoseconds since the last pulse.
    Pps,
}

impl TimeSource {
    pub const ALL: [TimeSource; 4] = [Self::None, Self::Ptp, Self::Gps, Self::Pps];

    pub fn name(self) -> &'static str {
        match self {
            Self::None => "none",
            Self::Ptp => "ptp",
            Self::Gps => "gps",
            Self::Pps => "pps",
        }
    }

    /// The wire's timestamp_type.
    pub fn timestamp_type(self) -> u8 {
        match self {
            Self::None => 0,
            Self::Ptp => 1,
            Self::Gps => 3,
            Self::Pps => 4,
        }
    }

    /// The status word bits of this source: sync state (14-16), PTP ok (13), PPS ok (9).
    pub fn status_bits(self) -> u32 {
        let (sync, ptp_ok, pps_ok) = match self {
            Self::None => (SyncState::None, false, false),
            Self::Ptp => (SyncState::Ptp, true, false),
            Self::Gps => (SyncState::Gps, false, true),
            Self::Pps => (SyncState::Pps, false, true),
        };
        StatusWord::compose(sync, SystemStatus::Normal, ptp_ok, pps_ok)
    }
}

impl fmt::Display for TimeSource {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for TimeSource {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Self::ALL
            .into_iter()
            .find(|t| t.name().eq_ignore_ascii_case(s))
            .ok_or_else(|| format!("unknown time source {s:?} (none, ptp, gps, pps)"))
    }
}

/// The return mode a mock starts in.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ReturnSetting {
    /// First return (data types 2/3, 96 firings per packet).
    #[default]
    Single,
    /// Dual return (data types 4/5, 48 firings per packet).
    Dual,
    /// Triple return (data types 7/8, 30 firings per packet).
    Triple,
}

impl ReturnSetting {
    pub fn mode(self) -> ReturnMode {
        match self {
            Self::Single => ReturnMode::First,
            Self::Dual => ReturnMode::Dual,
            Self::Triple => ReturnMode::Triple,
        }
    }
}

impl FromStr for ReturnSetting {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.to_ascii_lowercase().as_str() {
            "single" => Ok(Self::Single),
            "dual" => Ok(Self::Dual),
            "triple" => Ok(Self::Triple),
            _ => Err(format!("unknown return mode {s:?} (single, dual, triple)")),
        }
    }
}

/// The point data type for a return mode and coordinate system.
pub fn point_data_type(mode: ReturnMode, spherical: bool) -> DataType {
    match (mode.echoes(), spherical) {
        (2, false) => DataType::DualCartesian,
        (2, true) => DataType::DualSpherical,
        (3, false) => DataType::TripleCartesian,
        (3, true) => DataType::TripleSpherical,
        (_, false) => DataType::ExtendedCartesian,
        (_, true) => DataType::ExtendedSpherical,
    }
}

/// Maps the device's free-running clock (ns since power-on) onto the stamp of each time source.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Timebase {
    pub source: TimeSource,
    /// PTP time = device ns + this.
    pub ptp_offset_ns: i64,
    /// UTC (Unix ns) = device ns + this; GPS stamps, and PPS as UTC modulo one second.
    pub utc_offset_ns: i64,
}

impl Timebase {
    pub fn stamp(&self, device_ns: u64) -> Stamp {
        match self.source {
            TimeSource::None => Stamp::new(device_ns, Clock::Device),
            TimeSource::Ptp => Stamp::new(device_ns.saturating_add_signed(self.ptp_offset_ns), Clock::Ptp),
            TimeSource::Gps => Stamp::new(device_ns.saturating_add_signed(self.utc_offset_ns), Clock::Gps),
            TimeSource::Pps => Stamp::new(device_ns.saturating_add_signed(self.utc_offset_ns) % NS_PER_S, Clock::Pps),
        }
    }
}

/// Point data or IMU.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum PacketKind {
    Points,
    Imu,
}

/// One encoded data packet.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Packet {
    pub kind: PacketKind,
    /// Device time of the first firing (points) or of the sample (IMU).
    pub device_ns: u64,
    pub bytes: Vec<u8>,
}

/// What the device tells the streamer at each poll.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StreamParams {
    pub data_type: DataType,
    pub imu: bool,
    pub status: u32,
    pub timebase: Timebase,
}

/// Counters of one streamer.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct StreamStats {
    pub point_packets: u64,
    pub imu_packets: u64,
    /// Packets never built because the transport fell more than `max_lag_ns` behind.
    pub skipped_packets: u64,
    /// Packets that could not be encoded (a GPS time outside 2000-2255).
    pub encode_errors: u64,
}

/// The firing clock and packetizer of one streaming session.
#[derive(Debug)]
pub struct Streamer {
    next_firing_ns: u64,
    firing_index: u64,
    pending_points: Option<u64>,
    next_imu_ns: u64,
    pending_imu: Option<u64>,
    max_lag_ns: u64,
    returns: Vec<Return>,
    stats: StreamStats,
}

impl Streamer {
    /// Starts firing at device time `start_ns`. Packets due more than `max_lag_ns` before a poll
    /// are skipped (a stalled transport does not send a burst of stale packets).
    pub fn start(start_ns: u64, max_lag_ns: u64, source: &mut dyn PointSource) -> Self {
        source.start(start_ns);
        Self {
            next_firing_ns: start_ns,
            firing_index: 0,
            pending_points: None,
            next_imu_ns: start_ns,
            pending_imu: None,
            max_lag_ns,
            returns: Vec::new(),
            stats: StreamStats::default(),
        }
    }

    pub fn stats(&self) -> StreamStats {
        self.stats
    }

    /// Device time of the next firing the streamer will packetize.
    pub fn next_firing_ns(&self) -> u64 {
        self.pending_points.unwrap_or(self.next_firing_ns)
    }

    /// Appends every packet due at `now_ns` to `out`, in time order.
    pub fn poll(&mut self, now_ns: u64, p: &StreamParams, source: &mut dyn PointSource, out: &mut Vec<Packet>) {
        let dt = p.data_type;
        let firings = dt.firings_per_packet();
        let interval = dt.firing_interval_ns();
        let span = firings as u64 * u64::from(interval);
        if !p.imu {
            self.pending_imu = None;
            self.next_imu_ns = self.next_imu_ns.max(now_ns);
        }
        loop {
            let t_points = match self.pending_points {
                Some(t) => t,
                None => {
                    let t = source.next_firing_ns(self.next_firing_ns).max(self.next_firing_ns);
                    self.pending_points = Some(t);
                    t
                }
            };
            let points_due = t_points.saturating_add(span);
            if points_due.saturating_add(self.max_lag_ns) < now_ns {
                let behind = now_ns - self.max_lag_ns - points_due;
                let skip = behind / span + 1;
                self.next_firing_ns = t_points + skip * span;
                self.firing_index += skip * firings as u64;
                self.pending_points = None;
                self.stats.skipped_packets += skip;
                continue;
            }
            let t_imu = if p.imu {
                let t = match self.pending_imu {
                    Some(t) => t,
                    None => {
                        let t = source.next_imu_ns(self.next_imu_ns).max(self.next_imu_ns);
                        self.pending_imu = Some(t);
                        t
                    }
                };
                if t.saturating_add(self.max_lag_ns) < now_ns {
                    let skip = (now_ns - self.max_lag_ns - t) / IMU_INTERVAL_NS + 1;
                    self.next_imu_ns = t + skip * IMU_INTERVAL_NS;
                    self.pending_imu = None;
                    self.stats.skipped_packets += skip;
                    continue;
                }
                Some(t)
            } else {
                None
            };
            match t_imu {
                Some(t) if t <= now_ns && t < points_due => self.emit_imu(t, p, source, out),
                _ if points_due <= now_ns => self.emit_points(t_points, dt, p, source, out),
                _ => break,
            }
        }
    }

    fn emit_points(
        &mut self,
        t0: u64,
        dt: DataType,
        p: &StreamParams,
        source: &mut dyn PointSource,
        out: &mut Vec<Packet>,
    ) {
        let firings = dt.firings_per_packet();
        let interval = dt.firing_interval_ns();
        let req = FiringRequest {
            first_index: self.firing_index,
            first_ns: t0,
            interval_ns: interval,
            firings,
            echoes: dt.echoes(),
        };
        self.returns.clear();
        source.fill(&req, &mut self.returns);
        self.returns.resize(dt.returns_per_packet(), Return::EMPTY);
        let header = DataHeader {
            version: DATA_VERSION,
            slot: 1,
            lidar_id: 1,
            status: StatusWord::from_raw(p.status),
            data_type: dt,
            timestamp: p.timebase.stamp(t0),
        };
        let mut bytes = Vec::with_capacity(dt.packet_len());
        match encode_point_packet(&header, &self.returns, &mut bytes) {
            Ok(()) => {
                self.stats.point_packets += 1;
                out.push(Packet { kind: PacketKind::Points, device_ns: t0, bytes });
            }
            Err(e) => {
                self.stats.encode_errors += 1;
                tracing::debug!("point packet at {t0} ns not encoded: {e}");
            }
        }
        self.next_firing_ns = t0 + firings as u64 * u64::from(interval);
        self.firing_index += firings as u64;
        self.pending_points = None;
    }

    fn emit_imu(&mut self, t: u64, p: &StreamParams, source: &mut dyn PointSource, out: &mut Vec<Packet>) {
        let sample = source.imu(t);
        let header = DataHeader {
            version: DATA_VERSION,
            slot: 1,
            lidar_id: 1,
            status: StatusWord::from_raw(p.status),
            data_type: DataType::Imu,
            timestamp: p.timebase.stamp(t),
        };
        let mut bytes = Vec::with_capacity(DataType::Imu.packet_len());
        match encode_imu_packet(&header, &sample, &mut bytes) {
            Ok(()) => {
                self.stats.imu_packets += 1;
                out.push(Packet { kind: PacketKind::Imu, device_ns: t, bytes });
            }
            Err(e) => {
                self.stats.encode_errors += 1;
                tracing::debug!("imu packet at {t} ns not encoded: {e}");
            }
        }
        self.next_imu_ns = t + IMU_INTERVAL_NS;
        self.pending_imu = None;
    }
}
