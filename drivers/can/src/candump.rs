//! `candump -l` log lines, the format SocketCAN's can-utils write and read (`canplayer`):
//! `(SECONDS.MICROS) IFACE ID#DATA`, e.g. `(1767225600.000130) can0 201#0DAC04B0000000` or a
//! remote frame `601#R8`. Sans-IO: one line in, one stamped frame out.

use crate::error::{CanError, Result};
use crate::frame::{CanFrame, CanId};

/// One logged frame: its receive time (the log's clock, nanoseconds), interface and frame.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct LoggedFrame {
    pub t_ns: u64,
    pub interface: String,
    pub frame: CanFrame,
}

/// Parses one `candump -l` line (without its newline).
pub fn parse_line(line: &str) -> Result<LoggedFrame> {
    let bad = |reason: &'static str| CanError::BadLine { reason, line: line.chars().take(80).collect() };
    let rest = line.trim_end().strip_prefix('(').ok_or_else(|| bad("no '(' before the time"))?;
    let (stamp, rest) = rest.split_once(") ").ok_or_else(|| bad("no ') ' after the time"))?;
    let t_ns = stamp_ns(stamp).ok_or_else(|| bad("time is not SECONDS.MICROS"))?;
    let (interface, frame) = rest.split_once(' ').ok_or_else(|| bad("no frame after the interface"))?;
    let (id, data) = frame.split_once('#').ok_or_else(|| bad("no '#' in the frame"))?;
    if !id.bytes().all(|b| b.is_ascii_hexdigit()) {
        return Err(bad("id is not hexadecimal"));
    }
    let raw = u32::from_str_radix(id, 16).map_err(|_| bad("id is not hexadecimal"))?;
    let id = match id.len() {
        3 => CanId::standard(u16::try_from(raw).map_err(|_| bad("standard id too large"))?)?,
        8 => CanId::extended(raw)?,
        _ => return Err(bad("id is neither 3 (standard) nor 8 (extended) hex digits")),
    };
    let frame = match data.strip_prefix('R') {
        Some(dlc) => CanFrame::remote(id, remote_dlc(dlc).ok_or_else(|| bad("remote DLC is not one digit 0-8"))?)?,
        None => CanFrame::new(id, &hex_bytes(data).ok_or_else(|| bad("data is not pairs of hex digits"))?)?,
    };
    Ok(LoggedFrame { t_ns, interface: interface.to_string(), frame })
}

/// `SECONDS.MICROS` (six digits) in nanoseconds.
fn stamp_ns(s: &str) -> Option<u64> {
    let (secs, micros) = s.split_once('.')?;
    if micros.len() != 6 || !micros.bytes().all(|b| b.is_ascii_digit()) || !secs.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    secs.parse::<u64>().ok()?.checked_mul(1_000_000_000)?.checked_add(micros.parse::<u64>().ok()? * 1000)
}

/// `R` alone is DLC 0; otherwise one digit.
fn remote_dlc(s: &str) -> Option<u8> {
    match s.as_bytes() {
        [] => Some(0),
        [d @ b'0'..=b'8'] => Some(d - b'0'),
        _ => None,
    }
}

fn hex_bytes(s: &str) -> Option<Vec<u8>> {
    if !s.len().is_multiple_of(2) || s.len() > 16 || !s.bytes().all(|b| b.is_ascii_hexdigit()) {
        return None;
    }
    (0..s.len() / 2).map(|i| s.get(2 * i..2 * i + 2).and_then(|h| u8::from_str_radix(h, 16).ok())).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lines_round_trip_through_the_frames_display() {
        for (line, ns) in [
            ("(1767225600.000130) can0 201#0DAC04B0000000", 1_767_225_600_000_130_000),
            ("(0.000001) vcan0 12345678#00", 1000),
            ("(5.500000) can1 601#R8", 5_500_000_000),
            ("(5.500000) can1 7FF#", 5_500_000_000),
        ] {
            let f = parse_line(line).unwrap_or_else(|e| panic!("{line}: {e}"));
            assert_eq!(f.t_ns, ns);
            let (_, frame_text) = line.rsplit_once(' ').unwrap_or_default();
            assert_eq!(f.frame.to_string(), frame_text);
        }
    }

    #[test]
    fn bad_lines_are_typed_errors() {
        for line in [
            "",
            "1767225600.000130 can0 201#00",
            "(1767225600.13) can0 201#00",
            "(1.000000) can0 201",
            "(1.000000) can0 2011#00",
            "(1.000000) can0 201#0",
            "(1.000000) can0 201#000102030405060708",
            "(1.000000) can0 800#00",
            "(1.000000) can0 201#R9",
            "(99999999999999999999.000000) can0 201#00",
            "(1.000000) can0 +1F#00",
            "(1.000000) can0 201#+1",
            "(1.000000) can0 201#R08",
        ] {
            assert!(parse_line(line).is_err(), "{line:?} was taken");
        }
    }
}
