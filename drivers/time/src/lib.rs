//! Time in STARC is always `u64` nanoseconds tagged with the clock it was read from.
//!
//! Device clocks are only comparable with each other after a clock model has mapped them onto a
//! common clock, so the tag travels with every stamp and arithmetic across clocks is refused.

pub mod error;
pub mod model;

pub use error::TimeError;
pub use model::{ClockFit, ClockModel, ClockModelConfig, TimeAligner};

use serde::{Deserialize, Serialize};
use std::fmt;
use std::time::{SystemTime, UNIX_EPOCH};

/// Where a time stamp came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Clock {
    /// A device's free-running clock (no synchronisation); zero is arbitrary (often power-on).
    Device,
    /// PTP (IEEE 1588) time: nanoseconds since the PTP epoch of the grandmaster.
    Ptp,
    /// GPS/UTC time from a GPS receiver's NMEA + PPS: nanoseconds since the Unix epoch (UTC).
    Gps,
    /// Nanoseconds since the last PPS pulse only; the whole seconds must come from elsewhere.
    Pps,
    /// The host's realtime clock (CLOCK_REALTIME) at the moment of receive or send.
    Host,
}

impl Clock {
    pub fn name(self) -> &'static str {
        match self {
            Clock::Device => "device",
            Clock::Ptp => "ptp",
            Clock::Gps => "gps",
            Clock::Pps => "pps",
            Clock::Host => "host",
        }
    }
}

impl fmt::Display for Clock {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// A time stamp: nanoseconds on a named clock.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct Stamp {
    pub ns: u64,
    pub clock: Clock,
}

impl Stamp {
    pub const fn new(ns: u64, clock: Clock) -> Self {
        Self { ns, clock }
    }

    /// The host realtime clock now.
    pub fn host_now() -> Self {
        let ns = SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .map(|d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX))
            .unwrap_or(0);
        Self::new(ns, Clock::Host)
    }

    /// Signed difference `self - earlier` in nanoseconds, or `None` when the clocks differ.
    pub fn since(self, earlier: Stamp) -> Option<i64> {
        if self.clock != earlier.clock {
            return None;
        }
        Some((self.ns as i128 - earlier.ns as i128).clamp(i64::MIN as i128, i64::MAX as i128) as i64)
    }

    /// This stamp moved by `offset_ns` on the same clock (saturating at the ends of u64).
    pub fn offset_by(self, offset_ns: i64) -> Self {
        let ns = if offset_ns >= 0 {
            self.ns.saturating_add(offset_ns as u64)
        } else {
            self.ns.saturating_sub(offset_ns.unsigned_abs())
        };
        Self::new(ns, self.clock)
    }

    pub fn seconds_f64(self) -> f64 {
        self.ns as f64 * 1e-9
    }
}

impl fmt::Display for Stamp {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}.{:09} ({})", self.ns / 1_000_000_000, self.ns % 1_000_000_000, self.clock)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn since_refuses_mixed_clocks() {
        let a = Stamp::new(10, Clock::Ptp);
        let b = Stamp::new(3, Clock::Host);
        assert_eq!(a.since(b), None);
        assert_eq!(a.since(Stamp::new(3, Clock::Ptp)), Some(7));
        assert_eq!(Stamp::new(3, Clock::Ptp).since(a), Some(-7));
    }

    #[test]
    fn offset_saturates() {
        assert_eq!(Stamp::new(5, Clock::Device).offset_by(-10).ns, 0);
        assert_eq!(Stamp::new(u64::MAX - 1, Clock::Device).offset_by(10).ns, u64::MAX);
        assert_eq!(Stamp::new(5, Clock::Device).offset_by(10).ns, 15);
    }

    #[test]
    fn display_shows_clock() {
        assert_eq!(Stamp::new(1_500_000_000, Clock::Ptp).to_string(), "1.500000000 (ptp)");
    }
}
