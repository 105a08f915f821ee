//! [`CaptureSource`]: replays the point and IMU packets of a capture (pcap, pcapng, .lvx) through
//! the mock, re-stamped onto the mock's clock, keeping their relative timing, looping at the end.
//!
//! The capture is read lazily (a few packets ahead of the device) through
//! [`starc_livox::capture::open`] and turned into firings with their recorded times (the packet
//! stamp plus k firing intervals) and IMU samples with theirs. The device then packetizes the firings in
//! its own return mode and coordinate system: a firing lands in the slot of the device's firing
//! clock nearest its recorded time; a gap in the recording stays a gap. Recorded times come from
//! the packets' header stamps (exact, unlike capture times); a stamp jump (a clock change, a PPS
//! wrap) is bridged as if the packets were contiguous. Only the first device seen in the capture
//! is replayed (by source IP, or .lvx device index).

use crate::avia::source::{FiringRequest, PointSource};
use crate::avia::stream::{IMU_INTERVAL_NS, NS_PER_S};
use crate::error::{HilError, Result};
use starc_livox::capture::{self, Capture, Datagram};
use starc_livox::data::{DataPacket, ImuSample, Point, Return};
use std::collections::VecDeque;
use std::net::Ipv4Addr;
use std::path::{Path, PathBuf};

/// Stamp steps outside this range (ns) are clock jumps, bridged as contiguous.
const MAX_STEP_BACK_NS: i64 = 100_000_000;
const MAX_STEP_FORWARD_NS: i64 = 2 * NS_PER_S as i64;
/// Read-ahead bounds: about 0.25 s of firings while looking for IMU, 1 s of IMU samples.
const MAX_QUEUED_FIRINGS: usize = 60_000;
const MAX_QUEUED_IMU: usize = 200;
/// Replay times start here so that small backward steps never go negative.
const REPLAY_ORIGIN_NS: i64 = NS_PER_S as i64;
const AT_REST: ImuSample = ImuSample { gyro_rad_s: [0.0; 3], acc_g: [0.0, 0.0, 1.0] };

#[derive(Clone, Debug)]
enum Origin {
    File(PathBuf),
    Bytes(Vec<u8>),
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum DeviceKey {
    Ip(Ipv4Addr),
    Index(u8),
    Unknown,
}

#[derive(Clone, Copy, Debug)]
struct Firing {
    /// Replay time (ns).
    at: i64,
    returns: [Return; 3],
    echoes: u8,
}

/// Replays a capture's point and IMU packets.
pub struct CaptureSource {
    origin: Origin,
    capture: Capture,
    device: Option<DeviceKey>,
    firings: VecDeque<Firing>,
    imu: VecDeque<(i64, ImuSample)>,
    /// (stamp ns, replay ns) of the last packet taken.
    prev: Option<(u64, i64)>,
    /// Where the next pass starts (replay ns): right after the last firing of this one (or
    /// 5 ms after its last IMU sample when it has no points), so the firing clock runs on.
    end: i64,
    point_end: i64,
    imu_end: i64,
    /// Stamp of the first packet of the current pass.
    pass_first_stamp: u64,
    /// How far the first point packet lies after the first packet of a pass (learnt in the
    /// first pass), so a pass that opens with IMU still puts its first firing at `end`.
    lead_ns: Option<i64>,
    /// (replay ns, device ns) that map onto each other since the last `start`.
    anchor: Option<(i64, u64)>,
    start_ns: u64,
    packets_this_pass: u64,
    points_this_pass: u64,
    imu_this_pass: u64,
    /// A whole pass held no point (IMU) packets: stop looking for them.
    no_points: bool,
    no_imu: bool,
    passes: u64,
    exhausted: bool,
    last_imu: ImuSample,
    points: Vec<Point>,
    /// Replay at the recorded times: a packet stamped `s` leaves at device time `s - epoch`,
    /// once, with no looping (see [`CaptureSource::at_recorded_time`]).
    recorded_epoch_ns: Option<u64>,
}

impl std::fmt::Debug for CaptureSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let origin = match &self.origin {
            Origin::File(p) => p.display().to_string(),
            Origin::Bytes(b) => format!("{} bytes in memory", b.len()),
        };
        f.debug_struct("CaptureSource")
            .field("origin", &origin)
            .field("device", &self.device)
            .field("passes", &self.passes)
            .finish_non_exhaustive()
    }
}

impl CaptureSource {
    /// Opens a capture file; fails when it cannot be read or holds no Livox data packet.
    pub fn open(path: &Path) -> Result<Self> {
        let origin = Origin::File(path.to_path_buf());
        let capture = Self::reopen(&origin)?;
        Self::with(origin, capture)
    }

    /// A capture held in memory (tests).
    pub fn from_bytes(bytes: Vec<u8>) -> Result<Self> {
        let origin = Origin::Bytes(bytes);
        let capture = Self::reopen(&origin)?;
        Self::with(origin, capture)
    }

    fn path(origin: &Origin) -> PathBuf {
        match origin {
            Origin::File(p) => p.clone(),
            Origin::Bytes(_) => PathBuf::from("<memory>"),
        }
    }

    fn reopen(origin: &Origin) -> Result<Capture> {
        let opened = match origin {
            Origin::File(p) => capture::open(p),
            Origin::Bytes(b) => capture::from_bytes(b.clone()),
        };
        opened.map_err(|source| HilError::Capture { path: Self::path(origin), source })
    }

    fn with(origin: Origin, capture: Capture) -> Result<Self> {
        let mut probe = Self::blank(origin, capture);
        if !probe.read_more() {
            return Err(HilError::EmptyCapture { path: Self::path(&probe.origin), reason: "no Livox data packets" });
        }
        // The probe only proved the capture holds data. Start over, so that `for_device` and
        // `at_recorded_time`, given after opening, apply to the first packet too (else it went
        // out at once, whichever device it came from).
        let capture = Self::reopen(&probe.origin)?;
        Ok(Self::blank(probe.origin, capture))
    }

    fn blank(origin: Origin, capture: Capture) -> Self {
        Self {
            origin,
            capture,
            device: None,
            firings: VecDeque::new(),
            imu: VecDeque::new(),
            prev: None,
            end: REPLAY_ORIGIN_NS,
            point_end: REPLAY_ORIGIN_NS,
            imu_end: REPLAY_ORIGIN_NS,
            pass_first_stamp: 0,
            lead_ns: None,
            anchor: None,
            start_ns: 0,
            packets_this_pass: 0,
            points_this_pass: 0,
            imu_this_pass: 0,
            no_points: false,
            no_imu: false,
            passes: 0,
            exhausted: false,
            last_imu: AT_REST,
            recorded_epoch_ns: None,
            points: Vec::new(),
        }
    }

    /// Replays only the device at `ip` (by default, the first device seen).
    pub fn for_device(mut self, ip: Ipv4Addr) -> Self {
        self.device = Some(DeviceKey::Ip(ip));
        self
    }

    /// Replays at the recorded times instead of from the start of streaming: a packet stamped
    /// `s` goes out when the device's clock reads `s - epoch_ns`, so with the device's PTP epoch
    /// set to `epoch_ns` its packets carry their recorded stamps, and several devices replayed
    /// this way keep their recorded relative timing (a recorded run played back live, its truth
    /// still valid). What lies before the device started streaming is skipped; the capture is
    /// played once.
    pub fn at_recorded_time(mut self, epoch_ns: u64) -> Self {
        self.recorded_epoch_ns = Some(epoch_ns);
        self
    }

    /// Times the capture has been started over.
    pub fn loops(&self) -> u64 {
        self.passes
    }

    /// Reads datagrams until one data packet of the replayed device is queued; starts the
    /// capture over at its end. False when nothing can be had (a pass without data packets, or
    /// the file vanished).
    fn read_more(&mut self) -> bool {
        if self.exhausted {
            return false;
        }
        loop {
            match self.capture.next() {
                Some(Ok(d)) => {
                    if self.take(&d) {
                        return true;
                    }
                    continue;
                }
                Some(Err(e)) => tracing::warn!("capture {}: {e}; starting over", Self::path(&self.origin).display()),
                None => {}
            }
            if self.packets_this_pass == 0 || self.recorded_epoch_ns.is_some() {
                self.exhausted = true;
                return false;
            }
            self.no_points |= self.points_this_pass == 0;
            self.no_imu |= self.imu_this_pass == 0;
            self.end = if self.points_this_pass > 0 { self.point_end } else { self.imu_end };
            match Self::reopen(&self.origin) {
                Ok(c) => self.capture = c,
                Err(e) => {
                    tracing::warn!("{e}");
                    self.exhausted = true;
                    return false;
                }
            }
            self.passes += 1;
            self.packets_this_pass = 0;
            self.points_this_pass = 0;
            self.imu_this_pass = 0;
            self.prev = None;
        }
    }

    /// Queues a datagram if it is a data packet of the replayed device.
    fn take(&mut self, d: &Datagram) -> bool {
        let Ok(packet) = DataPacket::parse(&d.payload) else {
            return false;
        };
        let key = match (d.device_index, d.src) {
            (Some(i), _) => DeviceKey::Index(i),
            (None, Some(a)) => DeviceKey::Ip(*a.ip()),
            (None, None) => DeviceKey::Unknown,
        };
        match self.device {
            None => self.device = Some(key),
            Some(k) if k != key => return false,
            Some(_) => {}
        }
        let stamp = packet.header.timestamp.ns;
        let at = match self.prev {
            _ if self.recorded_epoch_ns.is_some() => i64::try_from(stamp).unwrap_or(i64::MAX),
            Some((prev_stamp, prev_at)) => {
                let step = (i128::from(stamp) - i128::from(prev_stamp))
                    .clamp(i128::from(i64::MIN), i128::from(i64::MAX)) as i64;
                if (-MAX_STEP_BACK_NS..=MAX_STEP_FORWARD_NS).contains(&step) {
                    prev_at.saturating_add(step)
                } else {
                    prev_at
                }
            }
            None => {
                self.pass_first_stamp = stamp;
                self.end.saturating_sub(self.lead_ns.unwrap_or(0))
            }
        };
        self.prev = Some((stamp, at));
        self.packets_this_pass += 1;
        let dt = packet.header.data_type;
        if let Some(sample) = packet.imu() {
            self.imu_this_pass += 1;
            // Unread samples (IMU push off) must not hold the points back: keep the newest.
            if self.imu.len() >= MAX_QUEUED_IMU {
                self.imu.pop_front();
            }
            self.imu.push_back((at, sample));
            self.imu_end = self.imu_end.max(at.saturating_add(IMU_INTERVAL_NS as i64));
            return true;
        }
        self.points_this_pass += 1;
        if self.lead_ns.is_none() {
            let lead = i128::from(stamp) - i128::from(self.pass_first_stamp);
            let lead = if (0..=i128::from(MAX_STEP_FORWARD_NS)).contains(&lead) { lead as i64 } else { 0 };
            self.lead_ns = Some(lead);
        }
        let interval = i64::from(dt.firing_interval_ns());
        let echoes = dt.echoes();
        let first = self.firings.len();
        for k in 0..dt.firings_per_packet() {
            self.firings.push_back(Firing {
                at: at + k as i64 * interval,
                returns: [Return::EMPTY; 3],
                echoes: echoes as u8,
            });
        }
        self.points.clear();
        packet.decode_points(&mut self.points);
        for p in &self.points {
            let k = (i64::from(p.offset_ns) / interval) as usize;
            let e = usize::from(p.echo);
            if let Some(f) = self.firings.get_mut(first + k) {
                if let Some(r) = f.returns.get_mut(e) {
                    *r = Return { x_m: p.x_m, y_m: p.y_m, z_m: p.z_m, reflectivity: p.reflectivity, tag: p.tag };
                }
            }
        }
        self.point_end = self.point_end.max(at + dt.firings_per_packet() as i64 * interval);
        true
    }

    /// Makes sure a firing is queued (reading ahead a bounded amount).
    fn want_firing(&mut self) -> bool {
        while self.firings.is_empty() {
            if self.no_points || !self.read_more() {
                return false;
            }
        }
        true
    }

    fn want_imu(&mut self) -> bool {
        while self.imu.is_empty() {
            if self.no_imu || self.firings.len() >= MAX_QUEUED_FIRINGS || !self.read_more() {
                return false;
            }
        }
        true
    }

    /// Device time of a replay time, anchoring the two at the first use after `start`.
    fn device_ns(&mut self, at: i64) -> u64 {
        if let Some(epoch) = self.recorded_epoch_ns {
            return u64::try_from(at).unwrap_or(0).saturating_sub(epoch);
        }
        let (r0, d0) = *self.anchor.get_or_insert((at, self.start_ns));
        d0.saturating_add_signed(at.saturating_sub(r0))
    }

    fn anchor_now(&mut self) {
        if self.anchor.is_none() {
            self.want_firing();
            self.want_imu();
            let first = match (self.firings.front(), self.imu.front()) {
                (Some(f), Some(i)) => Some(f.at.min(i.0)),
                (Some(f), None) => Some(f.at),
                (None, Some(i)) => Some(i.0),
                (None, None) => None,
            };
            if let Some(at) = first {
                self.anchor = Some((at, self.start_ns));
            }
        }
    }
}

impl PointSource for CaptureSource {
    fn start(&mut self, t_ns: u64) {
        self.start_ns = t_ns;
        self.anchor = None;
    }

    fn next_firing_ns(&mut self, nominal_ns: u64) -> u64 {
        self.anchor_now();
        let half = i64::from(starc_livox::data::packet::FIRING_INTERVAL_NS / 2);
        loop {
            if !self.want_firing() {
                return nominal_ns;
            }
            let Some(at) = self.firings.front().map(|f| f.at) else {
                return nominal_ns;
            };
            let t = self.device_ns(at);
            if t.saturating_add_signed(half) < nominal_ns {
                self.firings.pop_front(); // already past (the device skipped ahead)
                continue;
            }
            return t.max(nominal_ns);
        }
    }

    fn fill(&mut self, req: &FiringRequest, out: &mut Vec<Return>) {
        self.anchor_now();
        let half = u64::from(req.interval_ns / 2);
        for k in 0..req.firings {
            let slot = req.firing_ns(k);
            let mut firing = None;
            while self.want_firing() {
                let Some(front) = self.firings.front().copied() else { break };
                let t = self.device_ns(front.at);
                if t + half < slot {
                    self.firings.pop_front();
                } else {
                    if t < slot + half {
                        self.firings.pop_front();
                        firing = Some(front);
                    }
                    break;
                }
            }
            for e in 0..req.echoes {
                let r = firing.filter(|f| e < usize::from(f.echoes)).map(|f| f.returns[e]).unwrap_or(Return::EMPTY);
                out.push(r);
            }
        }
    }

    fn next_imu_ns(&mut self, nominal_ns: u64) -> u64 {
        self.anchor_now();
        let half = IMU_INTERVAL_NS / 2;
        loop {
            if !self.want_imu() {
                return nominal_ns;
            }
            let Some(at) = self.imu.front().map(|i| i.0) else {
                return nominal_ns;
            };
            let t = self.device_ns(at);
            if t + half < nominal_ns {
                self.imu.pop_front();
                continue;
            }
            return t.max(nominal_ns);
        }
    }

    fn imu(&mut self, t_ns: u64) -> ImuSample {
        let half = IMU_INTERVAL_NS / 2;
        if let Some((at, sample)) = self.imu.front().copied() {
            let t = self.device_ns(at);
            if t < t_ns + half {
                self.imu.pop_front();
                self.last_imu = sample;
            }
        }
        self.last_imu
    }
}
