//! When was a sample measured? Host receive times, a serial latency model, and a pluggable map of
//! host time onto another clock (the LiDAR's PTP time).
//!
//! A serial IMU sends no time the host can trust (MIP's GPS time needs a GPS; WitMotion's clock is
//! a free-running RTC), so the stamp is estimated from when the bytes arrived:
//!
//! ```text
//! stamp = t_read - usb_latency - (bytes after the frame in that read + frame bytes) * byte_time
//! ```
//!
//! `t_read` is the host clock when `read()` returned a chunk; bytes of one chunk are assumed to
//! have arrived back to back at the line rate (`byte_time` = bits per byte / baud, 10 bits for
//! 8N1), so a frame early in a chunk arrived earlier than the chunk's read. `usb_latency` is what
//! a USB-serial adapter adds (an FTDI's latency timer is 16 ms by default, 1 ms after
//! `setserial /dev/ttyUSB0 low_latency`; a CDC-ACM device such as a GX5's native USB is about
//! 1 ms). Device-side delays (filtering, transmit scheduling) are not modelled: measure them
//! against the LiDAR's IMU and put the difference into `usb_latency_ns`.

use serde::{Deserialize, Serialize};
use starc_time::{Clock, Stamp};
use std::collections::VecDeque;
use std::sync::Arc;

/// Serial transfer and USB latency of one link.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LatencyModel {
    /// Line rate in bits per second.
    pub baud: u32,
    /// Bits on the wire per byte: 10 for 8N1 (start + 8 data + stop).
    pub bits_per_byte: u32,
    /// Fixed latency added by the USB-serial path, in ns.
    pub usb_latency_ns: u64,
}

impl Default for LatencyModel {
    fn default() -> Self {
        Self { baud: 115_200, bits_per_byte: 10, usb_latency_ns: 1_000_000 }
    }
}

impl LatencyModel {
    pub fn new(baud: u32, usb_latency_ns: u64) -> Self {
        Self { baud, usb_latency_ns, ..Self::default() }
    }

    /// Time one byte takes on the wire (0 for a baud of 0, i.e. "no model").
    pub fn byte_time_ns(&self) -> u64 {
        if self.baud == 0 {
            return 0;
        }
        u64::from(self.bits_per_byte) * 1_000_000_000 / u64::from(self.baud)
    }

    /// Time `bytes` take on the wire.
    pub fn transfer_ns(&self, bytes: usize) -> u64 {
        self.byte_time_ns().saturating_mul(bytes as u64)
    }

    /// Bytes per second the line can carry.
    pub fn bytes_per_s(&self) -> f64 {
        if self.bits_per_byte == 0 {
            return 0.0;
        }
        f64::from(self.baud) / f64::from(self.bits_per_byte)
    }
}

/// Maps host-clock stamps onto another clock (the LiDAR's PTP time).
///
/// [`LinearClockMap`] takes an offset and skew from wherever they are known (e.g. `phc2sys`
/// statistics); a fitted clock model (drivers/time) can implement it as well.
pub trait HostClockMap: Send + Sync {
    /// `host` (on [`Clock::Host`]) on the target clock, or `None` while the map is unknown.
    fn map(&self, host: Stamp) -> Option<Stamp>;
}

/// `target = host + offset_ns + (host - reference_host_ns) * skew_ppb / 1e9`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LinearClockMap {
    pub target: Clock,
    pub offset_ns: i64,
    /// Rate error of the host clock against the target, in parts per billion.
    #[serde(default)]
    pub skew_ppb: f64,
    /// Host time at which `offset_ns` was measured.
    #[serde(default)]
    pub reference_host_ns: u64,
}

impl HostClockMap for LinearClockMap {
    fn map(&self, host: Stamp) -> Option<Stamp> {
        if host.clock != Clock::Host {
            return None;
        }
        let since = host.ns as i128 - i128::from(self.reference_host_ns);
        let drift = (since as f64 * self.skew_ppb * 1e-9).round();
        if !drift.is_finite() {
            return None;
        }
        let ns = host.ns as i128 + i128::from(self.offset_ns) + drift as i128;
        u64::try_from(ns).ok().map(|ns| Stamp::new(ns, self.target))
    }
}

/// Turns byte positions into time stamps: remembers when recent chunks were read.
#[derive(Clone)]
pub struct Timestamper {
    latency: LatencyModel,
    map: Option<Arc<dyn HostClockMap>>,
    /// (stream offset one past the chunk's last byte, host ns of its read), oldest first.
    chunks: VecDeque<(u64, u64)>,
}

impl std::fmt::Debug for Timestamper {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Timestamper").field("latency", &self.latency).field("mapped", &self.map.is_some()).finish()
    }
}

/// Chunks remembered at most; older ones are only needed for frames held across many tiny reads,
/// and for those the oldest remembered read is a fine (late) estimate.
const MAX_CHUNKS: usize = 64;

impl Timestamper {
    pub fn new(latency: LatencyModel) -> Self {
        Self { latency, map: None, chunks: VecDeque::with_capacity(MAX_CHUNKS) }
    }

    pub fn with_map(mut self, map: Arc<dyn HostClockMap>) -> Self {
        self.map = Some(map);
        self
    }

    pub fn set_map(&mut self, map: Option<Arc<dyn HostClockMap>>) {
        self.map = map;
    }

    pub fn latency(&self) -> LatencyModel {
        self.latency
    }

    pub fn set_latency(&mut self, latency: LatencyModel) {
        self.latency = latency;
    }

    /// Records that the stream's bytes up to `end_offset` (exclusive) were read at `host_ns`.
    pub fn chunk(&mut self, end_offset: u64, host_ns: u64) {
        if self.chunks.len() == MAX_CHUNKS {
            self.chunks.pop_front();
        }
        self.chunks.push_back((end_offset, host_ns));
    }

    /// Forgets chunks that end at or before `offset` (every byte before it has been used).
    pub fn consumed(&mut self, offset: u64) {
        while self.chunks.front().is_some_and(|&(end, _)| end <= offset) && self.chunks.len() > 1 {
            self.chunks.pop_front();
        }
    }

    /// Estimated host arrival of the byte at stream offset `last`.
    pub fn arrival(&self, last: u64) -> Stamp {
        let found = self.chunks.iter().find(|&&(end, _)| end > last).or(self.chunks.back());
        let ns = match found {
            Some(&(end, t)) => {
                let after = end.saturating_sub(last.saturating_add(1));
                t.saturating_sub(after.saturating_mul(self.latency.byte_time_ns()))
            }
            None => 0,
        };
        Stamp::new(ns, Clock::Host)
    }

    /// Estimated measurement time of a frame of `len` bytes whose last byte arrived at `arrival`,
    /// on the mapped clock when the map knows it.
    pub fn measured(&self, arrival: Stamp, len: usize) -> Stamp {
        let back = self.latency.transfer_ns(len).saturating_add(self.latency.usb_latency_ns);
        let host = Stamp::new(arrival.ns.saturating_sub(back), Clock::Host);
        self.map.as_ref().and_then(|m| m.map(host)).unwrap_or(host)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn byte_times_follow_the_baud() {
        let m = LatencyModel::new(115_200, 0);
        assert_eq!(m.byte_time_ns(), 86_805);
        assert_eq!(m.transfer_ns(11), 954_855);
        assert_eq!(LatencyModel::new(0, 5).transfer_ns(100), 0);
        assert!((LatencyModel::new(921_600, 0).bytes_per_s() - 92_160.0).abs() < 1e-9);
    }

    #[test]
    fn arrival_counts_back_from_the_end_of_the_read() {
        let mut t = Timestamper::new(LatencyModel::new(100_000, 1_000_000)); // 100 us per byte
        t.chunk(50, 10_000_000);
        t.chunk(100, 20_000_000);
        assert_eq!(t.arrival(99).ns, 20_000_000);
        assert_eq!(t.arrival(89).ns, 19_000_000);
        assert_eq!(t.arrival(49).ns, 10_000_000);
        assert_eq!(t.arrival(10).ns, 10_000_000 - 39 * 100_000);
        // A frame of 10 bytes ending at byte 99: 1 ms transfer + 1 ms USB.
        assert_eq!(t.measured(t.arrival(99), 10), Stamp::new(18_000_000, Clock::Host));
        t.consumed(60);
        assert_eq!(t.chunks.len(), 1);
        // Beyond the last read (cannot happen in a decoder): the last read's time.
        assert_eq!(t.arrival(500).ns, 20_000_000);
    }

    #[test]
    fn linear_map_applies_offset_and_skew() {
        let m = LinearClockMap { target: Clock::Ptp, offset_ns: -1_000, skew_ppb: 1_000.0, reference_host_ns: 0 };
        let t = Timestamper::new(LatencyModel::new(0, 0)).with_map(Arc::new(m));
        // 1 s after the reference: 1000 ppb is 1 us of drift.
        assert_eq!(t.measured(Stamp::new(1_000_000_000, Clock::Host), 0), Stamp::new(1_000_000_000, Clock::Ptp));
        assert_eq!(m.map(Stamp::new(5, Clock::Ptp)), None);
        assert_eq!(m.map(Stamp::new(5, Clock::Host)), None); // before the PTP epoch
    }
}
