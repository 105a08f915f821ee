//! WitMotion output frames: `0x55`, type, 4 x i16 little-endian, checksum = low byte of the sum
//! of the 10 bytes before it.

use crate::error::{ImuError, Result};
use crate::sample::STANDARD_GRAVITY_M_S2;

pub const HEADER: u8 = 0x55;
pub const FRAME_LEN: usize = 11;

pub const TYPE_TIME: u8 = 0x50;
pub const TYPE_ACCEL: u8 = 0x51;
pub const TYPE_GYRO: u8 = 0x52;
pub const TYPE_ANGLE: u8 = 0x53;
pub const TYPE_MAG: u8 = 0x54;
pub const TYPE_QUATERNION: u8 = 0x59;
/// Output frame types run 0x50..=0x5F (0x5F answers a register read).
pub const TYPE_FIRST: u8 = 0x50;
pub const TYPE_LAST: u8 = 0x5F;

/// Full scales: +-16 g, +-2000 deg/s, +-180 deg, quaternion +-1, all over 32768.
pub const ACCEL_FULL_SCALE_G: f64 = 16.0;
pub const GYRO_FULL_SCALE_DEG_S: f64 = 2000.0;
pub const ANGLE_FULL_SCALE_DEG: f64 = 180.0;
const RAW_FULL_SCALE: f64 = 32768.0;

/// Low byte of the sum of `bytes`.
pub fn checksum(bytes: &[u8]) -> u8 {
    bytes.iter().fold(0u8, |s, &b| s.wrapping_add(b))
}

/// Whether `t` is an output frame type.
pub fn is_output_type(t: u8) -> bool {
    (TYPE_FIRST..=TYPE_LAST).contains(&t)
}

/// One checked frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct WitFrame {
    pub frame_type: u8,
    pub data: [u8; 8],
}

impl WitFrame {
    pub fn new(frame_type: u8, data: [u8; 8]) -> Self {
        Self { frame_type, data }
    }

    /// A frame of four i16 values.
    pub fn from_values(frame_type: u8, values: [i16; 4]) -> Self {
        let mut data = [0u8; 8];
        for (chunk, v) in data.chunks_exact_mut(2).zip(values) {
            chunk.copy_from_slice(&v.to_le_bytes());
        }
        Self { frame_type, data }
    }

    /// Parses the frame at the start of `bytes` (11 bytes or more).
    pub fn parse(bytes: &[u8]) -> Result<Self> {
        let frame: [u8; FRAME_LEN] = bytes
            .get(..FRAME_LEN)
            .and_then(|f| f.try_into().ok())
            .ok_or(ImuError::TooShort { what: "WitMotion frame", need: FRAME_LEN, have: bytes.len() })?;
        let [header, frame_type, d0, d1, d2, d3, d4, d5, d6, d7, stored] = frame;
        if header != HEADER {
            return Err(ImuError::WitBadHeader(header));
        }
        if !is_output_type(frame_type) {
            return Err(ImuError::WitBadType(frame_type));
        }
        let computed = checksum(frame.get(..FRAME_LEN - 1).unwrap_or_default());
        if stored != computed {
            return Err(ImuError::WitChecksum { stored, computed });
        }
        Ok(Self { frame_type, data: [d0, d1, d2, d3, d4, d5, d6, d7] })
    }

    pub fn encode(&self) -> [u8; FRAME_LEN] {
        let d = self.data;
        let mut f = [HEADER, self.frame_type, d[0], d[1], d[2], d[3], d[4], d[5], d[6], d[7], 0];
        f[FRAME_LEN - 1] = checksum(&f[..FRAME_LEN - 1]);
        f
    }

    /// The data as four little-endian i16.
    pub fn values(&self) -> [i16; 4] {
        let d = self.data;
        [
            i16::from_le_bytes([d[0], d[1]]),
            i16::from_le_bytes([d[2], d[3]]),
            i16::from_le_bytes([d[4], d[5]]),
            i16::from_le_bytes([d[6], d[7]]),
        ]
    }
}

fn scale3(raw: &[i16; 4], full_scale: f64) -> [f64; 3] {
    [0, 1, 2].map(|i| f64::from(raw[i]) / RAW_FULL_SCALE * full_scale)
}

fn to_raw(v: f64, full_scale: f64) -> i16 {
    let r = (v / full_scale * RAW_FULL_SCALE).round();
    if r.is_nan() {
        0
    } else {
        r.clamp(f64::from(i16::MIN), f64::from(i16::MAX)) as i16
    }
}

/// Acceleration frame (0x51) values in m/s^2.
pub fn accel_m_s2(raw: &[i16; 4]) -> [f64; 3] {
    scale3(raw, ACCEL_FULL_SCALE_G).map(|g| g * STANDARD_GRAVITY_M_S2)
}

/// Angular rate frame (0x52) values in rad/s.
pub fn gyro_rad_s(raw: &[i16; 4]) -> [f64; 3] {
    scale3(raw, GYRO_FULL_SCALE_DEG_S).map(f64::to_radians)
}

/// Angle frame (0x53) values (roll, pitch, yaw) in rad.
pub fn angle_rad(raw: &[i16; 4]) -> [f64; 3] {
    scale3(raw, ANGLE_FULL_SCALE_DEG).map(f64::to_radians)
}

/// Quaternion frame (0x59) values (w, x, y, z).
pub fn quaternion_wxyz(raw: &[i16; 4]) -> [f64; 4] {
    raw.map(|q| f64::from(q) / RAW_FULL_SCALE)
}

/// The temperature word of acceleration/gyro/mag frames, in degrees Celsius.
pub fn temperature_c(raw: &[i16; 4]) -> f64 {
    f64::from(raw[3]) / 100.0
}

/// Raw words of an acceleration frame (clamped to +-16 g) with a temperature.
pub fn accel_raw(m_s2: [f64; 3], temperature_c: f64) -> [i16; 4] {
    let [x, y, z] = m_s2.map(|a| to_raw(a / STANDARD_GRAVITY_M_S2, ACCEL_FULL_SCALE_G));
    [x, y, z, to_raw(temperature_c * 100.0, RAW_FULL_SCALE)]
}

/// Raw words of an angular rate frame (clamped to +-2000 deg/s).
pub fn gyro_raw(rad_s: [f64; 3], temperature_c: f64) -> [i16; 4] {
    let [x, y, z] = rad_s.map(|w| to_raw(w.to_degrees(), GYRO_FULL_SCALE_DEG_S));
    [x, y, z, to_raw(temperature_c * 100.0, RAW_FULL_SCALE)]
}

/// Raw words of an angle frame; the fourth word is the firmware version.
pub fn angle_raw(rad: [f64; 3], version: i16) -> [i16; 4] {
    let [r, p, y] = rad.map(|a| to_raw(a.to_degrees(), ANGLE_FULL_SCALE_DEG));
    [r, p, y, version]
}

/// Raw words of a quaternion frame.
pub fn quaternion_raw(wxyz: [f64; 4]) -> [i16; 4] {
    wxyz.map(|q| to_raw(q, 1.0))
}

/// The time frame (0x50): year since 2000, month, day, hour, minute, second, millisecond.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct WitTime {
    pub year: u8,
    pub month: u8,
    pub day: u8,
    pub hour: u8,
    pub minute: u8,
    pub second: u8,
    pub millisecond: u16,
}

impl WitTime {
    pub fn from_data(d: [u8; 8]) -> Self {
        Self {
            year: d[0],
            month: d[1],
            day: d[2],
            hour: d[3],
            minute: d[4],
            second: d[5],
            millisecond: u16::from_le_bytes([d[6], d[7]]),
        }
    }

    pub fn to_data(self) -> [u8; 8] {
        let [lo, hi] = self.millisecond.to_le_bytes();
        [self.year, self.month, self.day, self.hour, self.minute, self.second, lo, hi]
    }

    /// Nanoseconds since 1970-01-01 of this calendar time, or `None` when a field is out of
    /// range (an unset RTC sends zeros).
    pub fn unix_ns(self) -> Option<u64> {
        let valid = (1..=12).contains(&self.month)
            && (1..=31).contains(&self.day)
            && self.hour < 24
            && self.minute < 60
            && self.second < 60
            && self.millisecond < 1000;
        if !valid {
            return None;
        }
        let days = days_from_civil(2000 + i64::from(self.year), i64::from(self.month), i64::from(self.day));
        let s = days * 86_400 + i64::from(self.hour) * 3600 + i64::from(self.minute) * 60 + i64::from(self.second);
        u64::try_from(s).ok().map(|s| s * 1_000_000_000 + u64::from(self.millisecond) * 1_000_000)
    }

    /// The calendar time of `unix_ns` (years 2000..=2255).
    pub fn from_unix_ns(unix_ns: u64) -> Self {
        let s = unix_ns / 1_000_000_000;
        let (days, rem) = ((s / 86_400) as i64, s % 86_400);
        let (y, m, d) = civil_from_days(days);
        Self {
            year: (y - 2000).clamp(0, 255) as u8,
            month: m as u8,
            day: d as u8,
            hour: (rem / 3600) as u8,
            minute: (rem % 3600 / 60) as u8,
            second: (rem % 60) as u8,
            millisecond: (unix_ns / 1_000_000 % 1000) as u16,
        }
    }
}

/// Days since 1970-01-01 of a proleptic Gregorian date (Howard Hinnant's algorithm).
fn days_from_civil(y: i64, m: i64, d: i64) -> i64 {
    let y = if m <= 2 { y - 1 } else { y };
    let era = y.div_euclid(400);
    let yoe = y - era * 400;
    let mp = (m + 9) % 12;
    let doy = (153 * mp + 2) / 5 + d - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    era * 146_097 + doe - 719_468
}

fn civil_from_days(z: i64) -> (i64, i64, i64) {
    let z = z + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    (if m <= 2 { yoe + era * 400 + 1 } else { yoe + era * 400 }, m, d)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_round_trip_and_known_bytes() {
        // 1 g on z at 25.00 C: 2048 = 0x0800, 2500 = 0x09C4.
        let f = WitFrame::from_values(TYPE_ACCEL, [0, 0, 2048, 2500]);
        let b = f.encode();
        assert_eq!(b, [0x55, 0x51, 0, 0, 0, 0, 0x00, 0x08, 0xC4, 0x09, 0x7B]);
        assert_eq!(WitFrame::parse(&b).ok(), Some(f));
        assert_eq!(f.values(), [0, 0, 2048, 2500]);
        let a = accel_m_s2(&f.values());
        assert!((a[2] - STANDARD_GRAVITY_M_S2).abs() < 1e-12);
        assert!((temperature_c(&f.values()) - 25.0).abs() < 1e-12);
    }

    #[test]
    fn every_parse_error() {
        let good = WitFrame::from_values(TYPE_GYRO, [1, -2, 3, 0]).encode();
        assert!(matches!(WitFrame::parse(&good[..10]), Err(ImuError::TooShort { need: 11, have: 10, .. })));
        let mut b = good;
        b[0] = 0x54;
        assert!(matches!(WitFrame::parse(&b), Err(ImuError::WitBadHeader(0x54))));
        let mut b = good;
        b[1] = 0x60;
        assert!(matches!(WitFrame::parse(&b), Err(ImuError::WitBadType(0x60))));
        let mut b = good;
        b[10] = b[10].wrapping_add(1);
        assert!(matches!(WitFrame::parse(&b), Err(ImuError::WitChecksum { .. })));
    }

    #[test]
    fn unit_conversions_round_trip_within_a_count() {
        let g = gyro_raw([0.5, -1.0, 40.0], 21.5);
        let w = gyro_rad_s(&g);
        assert!((w[0] - 0.5).abs() < 2000f64.to_radians() / 32768.0);
        assert!((w[1] + 1.0).abs() < 2000f64.to_radians() / 32768.0);
        assert!((w[2] - 2000f64.to_radians()).abs() < 0.01, "clamped to full scale: {w:?}");
        assert_eq!(g[3], 2150);
        let a = accel_raw([0.0, 9.80665, -1000.0], 0.0);
        assert_eq!(a, [0, 2048, i16::MIN, 0]);
        let r = angle_rad(&angle_raw([0.1, -0.2, 3.0], 7));
        assert!((r[0] - 0.1).abs() < 1e-4 && (r[1] + 0.2).abs() < 1e-4 && (r[2] - 3.0).abs() < 1e-4);
        let q = quaternion_wxyz(&quaternion_raw([1.0, 0.0, -0.5, f64::NAN]));
        assert_eq!(q, [32767.0 / 32768.0, 0.0, -0.5, 0.0]);
    }

    #[test]
    fn time_frames() {
        let t = WitTime { year: 24, month: 2, day: 29, hour: 23, minute: 59, second: 58, millisecond: 999 };
        let ns = t.unix_ns().unwrap_or(0);
        // 2024-02-29T23:59:58.999Z
        assert_eq!(ns, 1_709_251_198_999_000_000);
        assert_eq!(WitTime::from_unix_ns(ns), t);
        assert_eq!(WitTime::from_data(t.to_data()), t);
        assert_eq!(WitTime { month: 0, ..t }.unix_ns(), None);
        assert_eq!(WitTime { millisecond: 1000, ..t }.unix_ns(), None);
    }
}
