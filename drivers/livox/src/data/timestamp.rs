//! Packet time stamps (timestamp_type 0, 1, 3, 4) turned into nanoseconds on a named clock.

use crate::error::{LivoxError, Result};
use starc_time::{Clock, Stamp};

pub const NS_PER_US: u64 = 1_000;
pub const NS_PER_HOUR: u64 = 3_600_000_000_000;

/// Decodes the 8 time-stamp bytes of a data packet.
pub fn decode(timestamp_type: u8, raw: [u8; 8]) -> Result<Stamp> {
    match timestamp_type {
        0 => Ok(Stamp::new(u64::from_le_bytes(raw), Clock::Device)),
        1 => Ok(Stamp::new(u64::from_le_bytes(raw), Clock::Ptp)),
        3 => utc_to_unix_ns(raw).map(|ns| Stamp::new(ns, Clock::Gps)),
        4 => Ok(Stamp::new(u64::from_le_bytes(raw), Clock::Pps)),
        other => Err(LivoxError::BadTimestampType(other)),
    }
}

/// Encodes a stamp as (timestamp_type, bytes); the inverse of [`decode`].
pub fn encode(stamp: Stamp) -> Result<(u8, [u8; 8])> {
    match stamp.clock {
        Clock::Device | Clock::Host => Ok((0, stamp.ns.to_le_bytes())),
        Clock::Ptp => Ok((1, stamp.ns.to_le_bytes())),
        Clock::Pps => Ok((4, stamp.ns.to_le_bytes())),
        Clock::Gps => unix_ns_to_utc(stamp.ns).map(|raw| (3, raw)),
    }
}

/// GPS/UTC format: year-2000, month, day, hour, then u32 microseconds within the hour.
fn utc_to_unix_ns(raw: [u8; 8]) -> Result<u64> {
    let (year, month, day, hour) = (2000 + i64::from(raw[0]), raw[1], raw[2], raw[3]);
    let us = u64::from(u32::from_le_bytes([raw[4], raw[5], raw[6], raw[7]]));
    if !(1..=12).contains(&month) {
        return Err(LivoxError::BadUtcTime("month out of range"));
    }
    if day == 0 || day > days_in_month(year, month) {
        return Err(LivoxError::BadUtcTime("day out of range"));
    }
    if hour > 23 {
        return Err(LivoxError::BadUtcTime("hour out of range"));
    }
    if us * NS_PER_US >= NS_PER_HOUR {
        return Err(LivoxError::BadUtcTime("microseconds exceed an hour"));
    }
    let days = days_from_civil(year, month, day) as u64;
    Ok((days * 24 + u64::from(hour)) * NS_PER_HOUR + us * NS_PER_US)
}

fn unix_ns_to_utc(ns: u64) -> Result<[u8; 8]> {
    let hours = ns / NS_PER_HOUR;
    let us = ((ns % NS_PER_HOUR) / NS_PER_US) as u32;
    let (year, month, day) = civil_from_days((hours / 24) as i64);
    if !(2000..=2255).contains(&year) {
        return Err(LivoxError::BadUtcTime("year outside 2000-2255"));
    }
    let u = us.to_le_bytes();
    Ok([(year - 2000) as u8, month, day, (hours % 24) as u8, u[0], u[1], u[2], u[3]])
}

fn is_leap(year: i64) -> bool {
    (year % 4 == 0 && year % 100 != 0) || year % 400 == 0
}

fn days_in_month(year: i64, month: u8) -> u8 {
    match month {
        1 | 3 | 5 | 7 | 8 | 10 | 12 => 31,
        4 | 6 | 9 | 11 => 30,
        2 if is_leap(year) => 29,
        _ => 28,
    }
}

/// Days since 1970-01-01 of a proleptic Gregorian date (H. Hinnant's algorithm).
fn days_from_civil(year: i64, month: u8, day: u8) -> i64 {
    let y = if month <= 2 { year - 1 } else { year };
    let era = y.div_euclid(400);
    let yoe = y - era * 400;
    let m = i64::from(month);
    let doy = (153 * (if m > 2 { m - 3 } else { m + 9 }) + 2) / 5 + i64::from(day) - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    era * 146_097 + doe - 719_468
}

fn civil_from_days(days: i64) -> (i64, u8, u8) {
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = (doy - (153 * mp + 2) / 5 + 1) as u8;
    let month = if mp < 10 { mp + 3 } else { mp - 9 } as u8;
    let year = yoe + era * 400 + i64::from(month <= 2);
    (year, month, day)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn utc_matches_a_known_date() {
        // 2026-11-21 08:00:00 UTC plus 1.5 s is 1795248001.5 s since the epoch.
        let us = 1_500_000u32.to_le_bytes();
        let raw = [26, 11, 21, 8, us[0], us[1], us[2], us[3]];
        let stamp = decode(3, raw).ok();
        assert_eq!(stamp, Some(Stamp::new(1_795_248_001_500_000_000, Clock::Gps)));
        assert_eq!(encode(Stamp::new(1_795_248_001_500_000_000, Clock::Gps)).ok(), Some((3, raw)));
    }

    #[test]
    fn bad_dates_are_refused() {
        assert!(decode(3, [26, 2, 29, 0, 0, 0, 0, 0]).is_err()); // 2026 is not a leap year
        assert!(decode(3, [24, 2, 29, 0, 0, 0, 0, 0]).is_ok());
        assert!(decode(3, [26, 13, 1, 0, 0, 0, 0, 0]).is_err());
        assert!(decode(3, [26, 1, 1, 24, 0, 0, 0, 0]).is_err());
        assert!(decode(3, [26, 1, 1, 0, 0xff, 0xff, 0xff, 0xff]).is_err());
        assert!(decode(2, [0; 8]).is_err());
    }

    #[test]
    fn integer_clocks_round_trip() {
        for clock in [Clock::Device, Clock::Ptp, Clock::Pps] {
            let s = Stamp::new(123_456_789_012, clock);
            let (t, raw) = encode(s).unwrap_or((9, [0; 8]));
            assert_eq!(decode(t, raw).ok(), Some(s));
        }
    }

    #[test]
    fn civil_round_trip_over_centuries() {
        for days in (-1000..200_000).step_by(37) {
            let (y, m, d) = civil_from_days(days);
            assert_eq!(days_from_civil(y, m, d), days);
        }
    }
}
