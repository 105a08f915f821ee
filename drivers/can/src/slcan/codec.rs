//! The Lawicel (slcan) ASCII protocol, both directions, sans-IO.
//!
//! Host to adapter ([`Command`]): `Sn` bitrate while closed, `O` open, `L` listen-only, `C` close,
//! `tIIILDD..`/`TIIIIIIIILDD..` data frames, `rIIIL`/`RIIIIIIIIL` remote frames, `F` status flags,
//! `V` version, `N` serial number, `Z0`/`Z1` time stamps off/on. Every command ends with CR.
//!
//! Adapter to host ([`Reply`]): CR alone = ok, BEL = error, `z`/`Z` = frame queued for transmit,
//! received frames in the same format as transmitted ones (with `Z1`: 4 hex digits of
//! milliseconds appended, wrapping at 60000), `Fxx` flags, `Vhhss`, `Nxxxx`.

use crate::error::{CanError, Result};
use crate::frame::{CanFrame, CanId, MAX_EXTENDED_ID, MAX_STANDARD_ID};
use crate::slcan::lines::Line;

/// What a host asks of an adapter.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Command {
    /// A bare CR (hosts send a few to flush the adapter's input).
    Empty,
    /// `Sn`: bitrate code 0-8 (see [`crate::slcan::bitrate::BITRATES`]).
    Bitrate(u8),
    /// `O`: open the channel.
    Open,
    /// `L`: open in listen-only mode.
    ListenOnly,
    /// `C`: close the channel.
    Close,
    /// `t`/`T`/`r`/`R`: transmit a frame.
    Transmit(CanFrame),
    /// `F`: read the status flags (clears them on a real adapter).
    Status,
    /// `V`: hardware and software version.
    Version,
    /// `N`: serial number.
    SerialNumber,
    /// `Z0`/`Z1`: append a millisecond time stamp to received frames.
    Timestamps(bool),
}

/// What an adapter sends to a host.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Reply {
    /// CR: the last command worked.
    Ok,
    /// BEL: the last command was refused.
    Error,
    /// `z` (standard) or `Z` (extended): a transmit request was queued.
    TxAck { extended: bool },
    /// A frame from the bus, with the adapter's millisecond stamp when `Z1` is on.
    Frame { frame: CanFrame, stamp_ms: Option<u16> },
    /// `Fxx`: the status flags ([`StatusFlags`]).
    Status(StatusFlags),
    /// `Vhhss`: hardware and software version, two hex digits each.
    Version { hardware: u8, software: u8 },
    /// `Nxxxx`: four alphanumeric characters.
    SerialNumber([u8; 4]),
}

/// The bits of the `F` reply, as the Lawicel manual names them.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, serde::Serialize)]
pub struct StatusFlags(pub u8);

impl StatusFlags {
    pub const RX_FIFO_FULL: u8 = 0x01;
    pub const TX_FIFO_FULL: u8 = 0x02;
    pub const ERROR_WARNING: u8 = 0x04;
    pub const DATA_OVERRUN: u8 = 0x08;
    pub const ERROR_PASSIVE: u8 = 0x20;
    pub const ARBITRATION_LOST: u8 = 0x40;
    pub const BUS_ERROR: u8 = 0x80;

    pub fn is_clear(self) -> bool {
        self.0 == 0
    }

    /// Names of the set bits, for logs and status output.
    pub fn names(self) -> Vec<&'static str> {
        [
            (Self::RX_FIFO_FULL, "rx fifo full"),
            (Self::TX_FIFO_FULL, "tx fifo full"),
            (Self::ERROR_WARNING, "error warning"),
            (Self::DATA_OVERRUN, "data overrun"),
            (0x10, "bit 4"),
            (Self::ERROR_PASSIVE, "error passive"),
            (Self::ARBITRATION_LOST, "arbitration lost"),
            (Self::BUS_ERROR, "bus error"),
        ]
        .into_iter()
        .filter(|(bit, _)| self.0 & bit != 0)
        .map(|(_, name)| name)
        .collect()
    }
}

const HEX: &[u8; 16] = b"0123456789ABCDEF";

fn push_hex(out: &mut Vec<u8>, value: u32, digits: u32) {
    for k in (0..digits).rev() {
        let nibble = (value >> (4 * k)) & 0xF;
        out.push(HEX.get(nibble as usize).copied().unwrap_or(b'0'));
    }
}

fn hex_value(line: &[u8], range: std::ops::Range<usize>) -> Result<u32> {
    let digits = line.get(range).ok_or_else(|| CanError::bad_line("line too short", line))?;
    let mut v: u32 = 0;
    for &d in digits {
        let n = (d as char).to_digit(16).ok_or_else(|| CanError::bad_line("not a hex digit", line))?;
        v = (v << 4) | n;
    }
    Ok(v)
}

/// Appends `frame` in slcan form (without CR).
fn push_frame(out: &mut Vec<u8>, frame: &CanFrame) {
    let (letter, id_digits) = match (frame.id().is_extended(), frame.is_remote()) {
        (false, false) => (b't', 3),
        (true, false) => (b'T', 8),
        (false, true) => (b'r', 3),
        (true, true) => (b'R', 8),
    };
    out.push(letter);
    push_hex(out, frame.id().raw(), id_digits);
    out.push(b'0' + frame.dlc());
    for &b in frame.data() {
        push_hex(out, u32::from(b), 2);
    }
}

/// Parses a frame line (`t`, `T`, `r`, `R`); a trailing 4-digit stamp is returned when
/// `allow_stamp`.
pub fn decode_frame(line: &[u8], allow_stamp: bool) -> Result<(CanFrame, Option<u16>)> {
    let letter = *line.first().ok_or_else(|| CanError::bad_line("empty line", line))?;
    let (extended, remote) = match letter {
        b't' => (false, false),
        b'T' => (true, false),
        b'r' => (false, true),
        b'R' => (true, true),
        _ => return Err(CanError::bad_line("not a frame", line)),
    };
    let id_digits = if extended { 8 } else { 3 };
    let raw_id = hex_value(line, 1..1 + id_digits)?;
    let id = if extended {
        if raw_id > MAX_EXTENDED_ID {
            return Err(CanError::bad_line("29-bit id out of range", line));
        }
        CanId::Extended(raw_id)
    } else {
        if raw_id > u32::from(MAX_STANDARD_ID) {
            return Err(CanError::bad_line("11-bit id out of range", line));
        }
        CanId::Standard(raw_id as u16)
    };
    let dlc_at = 1 + id_digits;
    let dlc = match line.get(dlc_at) {
        Some(d @ b'0'..=b'8') => d - b'0',
        Some(_) => return Err(CanError::bad_line("DLC is not 0-8", line)),
        None => return Err(CanError::bad_line("line too short", line)),
    };
    let body = dlc_at + 1 + if remote { 0 } else { 2 * usize::from(dlc) };
    let stamp_ms = match line.len().checked_sub(body) {
        Some(0) => None,
        Some(4) if allow_stamp => Some(hex_value(line, body..body + 4)? as u16),
        Some(_) | None => return Err(CanError::bad_line("length does not match the DLC", line)),
    };
    let frame = if remote {
        CanFrame::remote(id, dlc)?
    } else {
        let mut data = [0u8; 8];
        for (k, slot) in data.iter_mut().take(usize::from(dlc)).enumerate() {
            let at = dlc_at + 1 + 2 * k;
            *slot = hex_value(line, at..at + 2)? as u8;
        }
        CanFrame::new(id, data.get(..usize::from(dlc)).unwrap_or(&[]))?
    };
    Ok((frame, stamp_ms))
}

impl Command {
    /// Appends the command and its CR.
    pub fn encode(&self, out: &mut Vec<u8>) {
        match self {
            Self::Empty => {}
            Self::Bitrate(code) => out.extend_from_slice(&[b'S', b'0' + code.min(&9)]),
            Self::Open => out.push(b'O'),
            Self::ListenOnly => out.push(b'L'),
            Self::Close => out.push(b'C'),
            Self::Transmit(frame) => push_frame(out, frame),
            Self::Status => out.push(b'F'),
            Self::Version => out.push(b'V'),
            Self::SerialNumber => out.push(b'N'),
            Self::Timestamps(on) => out.extend_from_slice(if *on { b"Z1" } else { b"Z0" }),
        }
        out.push(b'\r');
    }

    pub fn to_bytes(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(32);
        self.encode(&mut out);
        out
    }

    /// Parses one line (without its CR).
    pub fn decode(line: &[u8]) -> Result<Self> {
        let Some(&first) = line.first() else {
            return Ok(Self::Empty);
        };
        let alone = |cmd: Self| if line.len() == 1 { Ok(cmd) } else { Err(CanError::bad_line("trailing bytes", line)) };
        match first {
            b'S' => match line {
                [_, d @ b'0'..=b'8'] => Ok(Self::Bitrate(d - b'0')),
                _ => Err(CanError::bad_line("bitrate is not S0-S8", line)),
            },
            b'O' => alone(Self::Open),
            b'L' => alone(Self::ListenOnly),
            b'C' => alone(Self::Close),
            b'F' => alone(Self::Status),
            b'V' => alone(Self::Version),
            b'N' => alone(Self::SerialNumber),
            b'Z' => match line {
                [_, b'0'] => Ok(Self::Timestamps(false)),
                [_, b'1'] => Ok(Self::Timestamps(true)),
                _ => Err(CanError::bad_line("time stamps are Z0 or Z1", line)),
            },
            b't' | b'T' | b'r' | b'R' => Ok(Self::Transmit(decode_frame(line, false)?.0)),
            _ => Err(CanError::bad_line("unknown command", line)),
        }
    }
}

impl Reply {
    /// Appends the reply and its end (CR, or nothing after a BEL).
    pub fn encode(&self, out: &mut Vec<u8>) {
        match self {
            Self::Ok => {}
            Self::Error => {
                out.push(0x07);
                return;
            }
            Self::TxAck { extended } => out.push(if *extended { b'Z' } else { b'z' }),
            Self::Frame { frame, stamp_ms } => {
                push_frame(out, frame);
                if let Some(ms) = stamp_ms {
                    push_hex(out, u32::from(*ms), 4);
                }
            }
            Self::Status(flags) => {
                out.push(b'F');
                push_hex(out, u32::from(flags.0), 2);
            }
            Self::Version { hardware, software } => {
                out.push(b'V');
                push_hex(out, u32::from(*hardware), 2);
                push_hex(out, u32::from(*software), 2);
            }
            Self::SerialNumber(sn) => {
                out.push(b'N');
                out.extend_from_slice(sn);
            }
        }
        out.push(b'\r');
    }

    pub fn to_bytes(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(32);
        self.encode(&mut out);
        out
    }

    /// Parses one item of the adapter's stream.
    pub fn decode(line: &Line) -> Result<Self> {
        let text = match line {
            Line::Bell => return Ok(Self::Error),
            Line::Overlong => return Err(CanError::LineTooLong { max: crate::slcan::lines::MAX_LINE }),
            Line::Text(t) => t.as_slice(),
        };
        match text {
            [] => Ok(Self::Ok),
            [b'z'] => Ok(Self::TxAck { extended: false }),
            [b'Z'] => Ok(Self::TxAck { extended: true }),
            [b'F', ..] if text.len() == 3 => Ok(Self::Status(StatusFlags(hex_value(text, 1..3)? as u8))),
            [b'V', ..] if text.len() == 5 => {
                Ok(Self::Version { hardware: hex_value(text, 1..3)? as u8, software: hex_value(text, 3..5)? as u8 })
            }
            [b'N', a, b, c, d] if [a, b, c, d].iter().all(|x| x.is_ascii_alphanumeric()) => {
                Ok(Self::SerialNumber([*a, *b, *c, *d]))
            }
            [b't' | b'T' | b'r' | b'R', ..] => {
                let (frame, stamp_ms) = decode_frame(text, true)?;
                Ok(Self::Frame { frame, stamp_ms })
            }
            _ => Err(CanError::bad_line("unknown reply", text)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::slcan::lines::LineSplitter;

    fn frame(id: u16, data: &[u8]) -> CanFrame {
        CanFrame::standard(id, data).unwrap_or_else(|e| panic!("{e}"))
    }

    #[test]
    fn commands_encode_as_the_manual_says() -> Result<()> {
        assert_eq!(Command::Bitrate(8).to_bytes(), b"S8\r");
        assert_eq!(Command::Open.to_bytes(), b"O\r");
        assert_eq!(
            Command::Transmit(frame(0x200, &[0x01, 0xF4, 0, 0, 0, 0, 0xFE, 0x0C])).to_bytes(),
            b"t200801F400000000FE0C\r"
        );
        let ext = CanFrame::new(CanId::extended(0x1ABCDEF)?, &[0xAA])?;
        assert_eq!(Command::Transmit(ext).to_bytes(), b"T01ABCDEF1AA\r");
        let rtr = CanFrame::remote(CanId::Standard(0x701), 1)?;
        assert_eq!(Command::Transmit(rtr).to_bytes(), b"r7011\r");
        assert_eq!(Command::Timestamps(true).to_bytes(), b"Z1\r");
        Ok(())
    }

    #[test]
    fn commands_round_trip_and_refuse_junk() -> Result<()> {
        for cmd in [
            Command::Empty,
            Command::Bitrate(0),
            Command::Bitrate(8),
            Command::Open,
            Command::ListenOnly,
            Command::Close,
            Command::Status,
            Command::Version,
            Command::SerialNumber,
            Command::Timestamps(false),
            Command::Transmit(frame(0x7FF, &[1, 2, 3, 4, 5, 6, 7, 8])),
            Command::Transmit(frame(0, &[])),
        ] {
            let bytes = cmd.to_bytes();
            let line = bytes.strip_suffix(b"\r").unwrap_or(&bytes);
            assert_eq!(Command::decode(line)?, cmd, "{bytes:?}");
        }
        for junk in
            [&b"S9"[..], b"t8000", b"t2019", b"t20120", b"t201201", b"T2000000000", b"OO", b"t20G0", b"x", b"Z2"]
        {
            assert!(Command::decode(junk).is_err(), "{junk:?}");
        }
        // Lower-case hex is read too.
        assert_eq!(Command::decode(b"t1ab1ff")?, Command::Transmit(frame(0x1AB, &[0xFF])));
        Ok(())
    }

    #[test]
    fn replies_round_trip_through_the_splitter() -> Result<()> {
        let replies = [
            Reply::Ok,
            Reply::Error,
            Reply::TxAck { extended: false },
            Reply::TxAck { extended: true },
            Reply::Frame {
                frame: frame(0x201, &[0x1F, 0xFF, 0x01, 0x2C, 0x00, 0x10, 0x24, 0x00]),
                stamp_ms: Some(0xEA5F),
            },
            Reply::Frame { frame: frame(0x581, &[0x4B, 0x41, 0x60, 0, 0x27, 0x06, 0, 0]), stamp_ms: None },
            Reply::Status(StatusFlags(0x84)),
            Reply::Version { hardware: 0x10, software: 0x13 },
            Reply::SerialNumber(*b"A123"),
        ];
        let mut bytes = Vec::new();
        for r in &replies {
            r.encode(&mut bytes);
        }
        let mut lines = Vec::new();
        LineSplitter::new().push(&bytes, &mut lines);
        let decoded: Vec<Reply> = lines.iter().map(Reply::decode).collect::<Result<_>>()?;
        assert_eq!(decoded, replies);
        assert_eq!(StatusFlags(0x84).names(), vec!["error warning", "bus error"]);
        Ok(())
    }
}
