//! PTP time values on the wire: 10-byte timestamps (u48 seconds + u32 nanoseconds) and the
//! correctionField's scaled nanoseconds (ns x 2^16).

use crate::error::{PtpError, Result};

const NS_PER_S: i128 = 1_000_000_000;
const MAX_SECONDS: u64 = (1 << 48) - 1;

/// A PTP timestamp: seconds (48 bits on the wire) and nanoseconds since the PTP epoch.
///
/// The nanoseconds field is kept as received even when it is 1e9 or more (malformed senders
/// exist); [`PtpTimestamp::total_ns`] still gives a well-defined value for it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct PtpTimestamp {
    pub seconds: u64,
    pub nanos: u32,
}

impl PtpTimestamp {
    pub const WIRE_LEN: usize = 10;

    /// From nanoseconds since the epoch; refuses negatives and values past 2^48 seconds.
    pub fn from_ns(ns: i128) -> Result<Self> {
        if ns < 0 {
            return Err(PtpError::TimestampRange(ns));
        }
        let seconds = u64::try_from(ns / NS_PER_S).map_err(|_| PtpError::TimestampRange(ns))?;
        if seconds > MAX_SECONDS {
            return Err(PtpError::TimestampRange(ns));
        }
        Ok(Self { seconds, nanos: (ns % NS_PER_S) as u32 })
    }

    /// Nanoseconds since the epoch (i128: 48-bit seconds in ns overflow u64).
    pub fn total_ns(self) -> i128 {
        self.seconds as i128 * NS_PER_S + self.nanos as i128
    }

    pub fn parse(bytes: &[u8; 10]) -> Self {
        let [s0, s1, s2, s3, s4, s5, n0, n1, n2, n3] = *bytes;
        let seconds = u64::from_be_bytes([0, 0, s0, s1, s2, s3, s4, s5]);
        Self { seconds, nanos: u32::from_be_bytes([n0, n1, n2, n3]) }
    }

    pub fn encode(self) -> [u8; 10] {
        let s = (self.seconds & MAX_SECONDS).to_be_bytes();
        let n = self.nanos.to_be_bytes();
        [s[2], s[3], s[4], s[5], s[6], s[7], n[0], n[1], n[2], n[3]]
    }
}

/// The correctionField: nanoseconds scaled by 2^16 (a signed 64-bit TimeInterval).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct Correction(pub i64);

impl Correction {
    pub fn from_ns(ns: i64) -> Self {
        Self(ns.saturating_mul(1 << 16))
    }

    /// Whole nanoseconds (the fraction below 1 ns is dropped, rounding toward minus infinity).
    pub fn ns(self) -> i64 {
        self.0 >> 16
    }

    /// Nanoseconds with the sub-nanosecond fraction.
    pub fn ns_f64(self) -> f64 {
        self.0 as f64 / 65536.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn timestamp_round_trips_through_wire_and_ns() {
        let t = PtpTimestamp { seconds: 0x0000_1234_5678_9abc, nanos: 999_999_999 };
        assert_eq!(PtpTimestamp::parse(&t.encode()), t);
        assert_eq!(PtpTimestamp::from_ns(t.total_ns()).ok(), Some(t));
    }

    #[test]
    fn timestamp_range_is_checked() {
        assert!(PtpTimestamp::from_ns(-1).is_err());
        assert!(PtpTimestamp::from_ns((MAX_SECONDS as i128 + 1) * NS_PER_S).is_err());
        assert!(PtpTimestamp::from_ns(MAX_SECONDS as i128 * NS_PER_S).is_ok());
    }

    #[test]
    fn correction_is_scaled_by_2_16() {
        assert_eq!(Correction::from_ns(3).0, 3 * 65536);
        assert_eq!(Correction(65536 * 5 + 32768).ns(), 5);
        assert_eq!(Correction(-65536).ns(), -1);
        assert!((Correction(65536 + 32768).ns_f64() - 1.5).abs() < 1e-12);
    }
}
