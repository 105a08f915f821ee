//! CANopen SDO, expedited transfers only (the objects a drive needs are at most 4 bytes):
//! requests on 0x600 + node, responses on 0x580 + node.
//!
//! Download (write) `2F/2B/27/23 idx sub d0..d3` for 1/2/3/4 bytes, answered `60 idx sub`;
//! upload (read) `40 idx sub`, answered `4F/4B/47/43 idx sub data` (or `42`, size not given);
//! either side may abort with `80 idx sub code(u32)`.

use crate::error::{bytes, need, BaseError, Result};
use starc_can::{CanFrame, CanId};

pub const SDO_REQUEST_BASE: u16 = 0x600;
pub const SDO_RESPONSE_BASE: u16 = 0x580;

/// An object address.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Address {
    pub index: u16,
    pub sub: u8,
}

impl Address {
    pub const fn new(index: u16, sub: u8) -> Self {
        Self { index, sub }
    }
}

impl std::fmt::Display for Address {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{:#06x}:{:02x}", self.index, self.sub)
    }
}

/// A value of 1-4 bytes, little-endian on the wire.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Value {
    pub raw: u32,
    /// 1..=4
    pub size: u8,
}

impl Value {
    pub fn u8(v: u8) -> Self {
        Self { raw: u32::from(v), size: 1 }
    }
    pub fn u16(v: u16) -> Self {
        Self { raw: u32::from(v), size: 2 }
    }
    pub fn u32(v: u32) -> Self {
        Self { raw: v, size: 4 }
    }
    pub fn i8(v: i8) -> Self {
        Self { raw: u32::from(v as u8), size: 1 }
    }
    pub fn i16(v: i16) -> Self {
        Self { raw: u32::from(v as u16), size: 2 }
    }
    pub fn i32(v: i32) -> Self {
        Self { raw: v as u32, size: 4 }
    }
    /// The value sign-extended from its size.
    pub fn as_i32(self) -> i32 {
        match self.size {
            1 => i32::from(self.raw as u8 as i8),
            2 => i32::from(self.raw as u16 as i16),
            _ => self.raw as i32,
        }
    }
}

/// What a client sends.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SdoRequest {
    Download { at: Address, value: Value },
    Upload { at: Address },
    Abort { at: Address, code: u32 },
}

/// What a server answers.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SdoResponse {
    Downloaded { at: Address },
    Uploaded { at: Address, value: Value },
    Abort { at: Address, code: u32 },
}

fn address(d: &[u8]) -> Address {
    Address::new(u16::from_le_bytes(bytes(d, 1)), d.get(3).copied().unwrap_or(0))
}

fn frame(id: u16, cs: u8, at: Address, payload: [u8; 4]) -> Result<CanFrame> {
    let i = at.index.to_le_bytes();
    let p = payload;
    Ok(CanFrame::standard(id, &[cs, i[0], i[1], at.sub, p[0], p[1], p[2], p[3]])?)
}

fn node_of(frame: &CanFrame, base: u16, what: &'static str) -> Result<u8> {
    match frame.id() {
        CanId::Standard(id) if id > base && id <= base + 0x7F => Ok((id - base) as u8),
        other => Err(BaseError::WrongId { what, id: other.raw() }),
    }
}

fn expedited_size(cs: u8, what: &'static str) -> Result<u8> {
    // e = 1 expedited; s = 1 size given in n (bytes without data = n).
    let (e, s, n) = (cs & 0x02 != 0, cs & 0x01 != 0, (cs >> 2) & 0x03);
    if !e {
        return Err(BaseError::malformed(what, "segmented transfer (only expedited is supported)"));
    }
    Ok(if s { 4 - n } else { 4 })
}

impl SdoRequest {
    pub fn to_frame(&self, node: u8) -> Result<CanFrame> {
        let id = SDO_REQUEST_BASE + u16::from(node);
        match *self {
            Self::Download { at, value } => {
                let size = value.size.clamp(1, 4);
                frame(id, 0x23 | ((4 - size) << 2), at, value.raw.to_le_bytes())
            }
            Self::Upload { at } => frame(id, 0x40, at, [0; 4]),
            Self::Abort { at, code } => frame(id, 0x80, at, code.to_le_bytes()),
        }
    }

    /// Parses a request into (node, request) (the mock drives read these).
    pub fn parse(frame: &CanFrame) -> Result<(u8, Self)> {
        let node = node_of(frame, SDO_REQUEST_BASE, "SDO request")?;
        let d = frame.data();
        need("SDO request", d, 8)?;
        let cs = d.first().copied().unwrap_or(0);
        let at = address(d);
        let req = match cs >> 5 {
            1 => {
                let size = expedited_size(cs, "SDO download")?;
                let raw = u32::from_le_bytes(bytes(d, 4));
                let mask = if size >= 4 { u32::MAX } else { (1u32 << (8 * u32::from(size))) - 1 };
                Self::Download { at, value: Value { raw: raw & mask, size } }
            }
            2 => Self::Upload { at },
            4 => Self::Abort { at, code: u32::from_le_bytes(bytes(d, 4)) },
            _ => return Err(BaseError::malformed("SDO request", format!("command specifier {cs:#04x}"))),
        };
        Ok((node, req))
    }
}

impl SdoResponse {
    pub fn to_frame(&self, node: u8) -> Result<CanFrame> {
        let id = SDO_RESPONSE_BASE + u16::from(node);
        match *self {
            Self::Downloaded { at } => frame(id, 0x60, at, [0; 4]),
            Self::Uploaded { at, value } => {
                let size = value.size.clamp(1, 4);
                frame(id, 0x43 | ((4 - size) << 2), at, value.raw.to_le_bytes())
            }
            Self::Abort { at, code } => frame(id, 0x80, at, code.to_le_bytes()),
        }
    }

    /// Parses a response into (node, response).
    pub fn parse(frame: &CanFrame) -> Result<(u8, Self)> {
        let node = node_of(frame, SDO_RESPONSE_BASE, "SDO response")?;
        let d = frame.data();
        need("SDO response", d, 8)?;
        let cs = d.first().copied().unwrap_or(0);
        let at = address(d);
        let resp = match cs >> 5 {
            3 => Self::Downloaded { at },
            2 => {
                let size = expedited_size(cs, "SDO upload")?;
                let raw = u32::from_le_bytes(bytes(d, 4));
                let mask = if size >= 4 { u32::MAX } else { (1u32 << (8 * u32::from(size))) - 1 };
                Self::Uploaded { at, value: Value { raw: raw & mask, size } }
            }
            4 => Self::Abort { at, code: u32::from_le_bytes(bytes(d, 4)) },
            _ => return Err(BaseError::malformed("SDO response", format!("command specifier {cs:#04x}"))),
        };
        Ok((node, resp))
    }
}

/// SDO abort codes (CiA 301).
pub mod abort {
    pub const TOGGLE_BIT: u32 = 0x0503_0000;
    pub const TIMED_OUT: u32 = 0x0504_0000;
    pub const BAD_COMMAND: u32 = 0x0504_0001;
    pub const UNSUPPORTED_ACCESS: u32 = 0x0601_0000;
    pub const WRITE_ONLY: u32 = 0x0601_0001;
    pub const READ_ONLY: u32 = 0x0601_0002;
    pub const NO_OBJECT: u32 = 0x0602_0000;
    pub const NOT_MAPPABLE: u32 = 0x0604_0041;
    pub const PDO_TOO_LONG: u32 = 0x0604_0042;
    pub const LENGTH_MISMATCH: u32 = 0x0607_0010;
    pub const LENGTH_TOO_HIGH: u32 = 0x0607_0012;
    pub const LENGTH_TOO_LOW: u32 = 0x0607_0013;
    pub const NO_SUBINDEX: u32 = 0x0609_0011;
    pub const INVALID_VALUE: u32 = 0x0609_0030;
    pub const VALUE_TOO_HIGH: u32 = 0x0609_0031;
    pub const VALUE_TOO_LOW: u32 = 0x0609_0032;
    pub const GENERAL: u32 = 0x0800_0000;
    pub const CANNOT_TRANSFER: u32 = 0x0800_0020;
    pub const LOCAL_CONTROL: u32 = 0x0800_0021;
    pub const DEVICE_STATE: u32 = 0x0800_0022;
}

/// What an abort code means.
pub fn abort_meaning(code: u32) -> &'static str {
    match code {
        abort::TOGGLE_BIT => "toggle bit not alternated",
        abort::TIMED_OUT => "SDO protocol timed out",
        abort::BAD_COMMAND => "command specifier not valid or unknown",
        abort::UNSUPPORTED_ACCESS => "unsupported access to an object",
        abort::WRITE_ONLY => "attempt to read a write-only object",
        abort::READ_ONLY => "attempt to write a read-only object",
        abort::NO_OBJECT => "object does not exist in the object dictionary",
        abort::NOT_MAPPABLE => "object cannot be mapped to the PDO",
        abort::PDO_TOO_LONG => "mapped objects exceed the PDO length",
        abort::LENGTH_MISMATCH => "data type does not match, length of service parameter does not match",
        abort::LENGTH_TOO_HIGH => "data type does not match, length too high",
        abort::LENGTH_TOO_LOW => "data type does not match, length too low",
        abort::NO_SUBINDEX => "sub-index does not exist",
        abort::INVALID_VALUE => "invalid value for parameter",
        abort::VALUE_TOO_HIGH => "value of parameter written too high",
        abort::VALUE_TOO_LOW => "value of parameter written too low",
        abort::GENERAL => "general error",
        abort::CANNOT_TRANSFER => "data cannot be transferred or stored to the application",
        abort::LOCAL_CONTROL => "data cannot be transferred because of local control",
        abort::DEVICE_STATE => "data cannot be transferred because of the present device state",
        _ => "unknown abort code",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn expedited_frames_match_cia301() -> Result<()> {
        let w = SdoRequest::Download { at: Address::new(0x6040, 0), value: Value::u16(0x0F) };
        assert_eq!(w.to_frame(1)?.to_string(), "601#2B4060000F000000");
        assert_eq!(SdoRequest::parse(&w.to_frame(1)?)?, (1, w));
        let r = SdoRequest::Upload { at: Address::new(0x6041, 0) };
        assert_eq!(r.to_frame(127)?.to_string(), "67F#4041600000000000");
        let resp = SdoResponse::Uploaded { at: Address::new(0x6061, 0), value: Value::i8(3) };
        assert_eq!(resp.to_frame(2)?.to_string(), "582#4F61600003000000");
        assert_eq!(SdoResponse::parse(&resp.to_frame(2)?)?, (2, resp));
        let abort = SdoResponse::Abort { at: Address::new(0x2000, 1), code: abort::NO_OBJECT };
        assert_eq!(abort.to_frame(3)?.to_string(), "583#8000200100000206");
        assert_eq!(SdoResponse::parse(&abort.to_frame(3)?)?, (3, abort));
        assert_eq!(abort_meaning(abort::NO_OBJECT), "object does not exist in the object dictionary");
        Ok(())
    }

    #[test]
    fn sizes_and_signs() -> Result<()> {
        let neg = SdoResponse::Uploaded { at: Address::new(0x606C, 0), value: Value::i32(-1500) };
        let (_, back) = SdoResponse::parse(&neg.to_frame(1)?)?;
        assert!(matches!(back, SdoResponse::Uploaded { value, .. } if value.as_i32() == -1500));
        // 0x42: expedited, size not indicated: four bytes.
        let f = CanFrame::standard(0x581, &[0x42, 0x00, 0x10, 0x00, 0x92, 0x01, 0x02, 0x00])?;
        assert!(
            matches!(SdoResponse::parse(&f)?.1, SdoResponse::Uploaded { value, .. } if value == Value::u32(0x0002_0192))
        );
        // Bytes beyond the indicated size are masked off.
        let f = CanFrame::standard(0x601, &[0x2F, 0x60, 0x60, 0x00, 0x03, 0xAA, 0xBB, 0xCC])?;
        assert!(matches!(SdoRequest::parse(&f)?.1, SdoRequest::Download { value, .. } if value == Value::u8(3)));
        Ok(())
    }

    #[test]
    fn junk_is_refused() -> Result<()> {
        assert!(SdoResponse::parse(&CanFrame::standard(0x581, &[0x60, 0, 0])?).is_err());
        assert!(SdoResponse::parse(&CanFrame::standard(0x580, &[0x60, 0, 0, 0, 0, 0, 0, 0])?).is_err());
        assert!(SdoResponse::parse(&CanFrame::standard(0x581, &[0x41, 0, 0x10, 0, 4, 0, 0, 0])?).is_err(), "segmented");
        assert!(SdoRequest::parse(&CanFrame::standard(0x601, &[0xE0, 0, 0, 0, 0, 0, 0, 0])?).is_err());
        Ok(())
    }
}
