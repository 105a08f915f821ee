//! pcapng: blocks of `type u32, total length u32, body, total length u32`, in sections that each
//! start with a Section Header Block fixing the byte order.
//!
//! Read: SHB (either byte order; a new SHB starts a new section and forgets its interfaces),
//! IDB (link type, snaplen, `if_tsresol` in both its power-of-10 and power-of-2 forms, default
//! microseconds, and `if_tsoffset`), EPB, SPB (no time stamp: the previous packet's time is used)
//! and the obsolete OPB. Other blocks are skipped. Every block's two length fields must agree and
//! be a multiple of 4.

use super::{Endian, FrameRef, ReadStats, Step, MAX_BLOCK_LEN};
use crate::error::{LivoxError, Result};
use serde::Serialize;

pub const SHB_TYPE: u32 = 0x0a0d_0d0a;
pub const IDB_TYPE: u32 = 0x0000_0001;
pub const OPB_TYPE: u32 = 0x0000_0002;
pub const SPB_TYPE: u32 = 0x0000_0003;
pub const EPB_TYPE: u32 = 0x0000_0006;
pub const BYTE_ORDER_MAGIC: u32 = 0x1a2b_3c4d;
/// Option codes of the IDB.
pub const OPT_END: u16 = 0;
pub const IF_TSRESOL: u16 = 9;
pub const IF_TSOFFSET: u16 = 14;
/// A section with more interfaces than this is refused (each costs memory for the whole section).
pub const MAX_INTERFACES: usize = 65_536;
const FORMAT: &str = "pcapng";
const MIN_BLOCK_LEN: usize = 12;

/// Time-stamp units of an interface: 10^-exp or 2^-exp seconds.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum TsResolution {
    Decimal(u8),
    Binary(u8),
}

impl TsResolution {
    /// The `if_tsresol` byte: most significant bit set means a power of two.
    pub fn from_byte(b: u8) -> Self {
        if b & 0x80 != 0 {
            Self::Binary(b & 0x7f)
        } else {
            Self::Decimal(b)
        }
    }

    /// Converts a count of units to nanoseconds (saturating).
    pub fn to_ns(self, ticks: u64) -> u64 {
        let t = u128::from(ticks);
        let ns = match self {
            Self::Decimal(e) if e <= 9 => t * 10u128.pow(u32::from(9 - e)),
            Self::Decimal(e) => 10u128.checked_pow(u32::from(e - 9)).map_or(0, |d| t / d),
            // e < 128, and t * 10^9 < 2^94: neither the product nor the shift overflows.
            Self::Binary(e) => (t * 1_000_000_000) >> e,
        };
        u64::try_from(ns).unwrap_or(u64::MAX)
    }
}

/// One Interface Description Block.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct Interface {
    pub link_type: u16,
    pub snaplen: u32,
    pub ts_resolution: TsResolution,
    /// Seconds to add to every time stamp (`if_tsoffset`).
    pub ts_offset_s: i64,
}

impl Interface {
    fn time_ns(&self, ticks: u64) -> u64 {
        let ns = i128::from(self.ts_resolution.to_ns(ticks)) + i128::from(self.ts_offset_s) * 1_000_000_000;
        ns.clamp(0, i128::from(u64::MAX)) as u64
    }
}

#[derive(Clone, Debug)]
struct Section {
    endian: Endian,
    interfaces: Vec<Interface>,
}

/// Sans-IO pcapng decoder.
#[derive(Clone, Debug, Default)]
pub struct PcapngDecoder {
    section: Option<Section>,
    offset: u64,
    last_time_ns: u64,
}

impl PcapngDecoder {
    pub fn new() -> Self {
        Self::default()
    }

    /// File offset of the next block.
    pub fn offset(&self) -> u64 {
        self.offset
    }

    pub fn section_started(&self) -> bool {
        self.section.is_some()
    }

    pub fn interfaces(&self) -> &[Interface] {
        self.section.as_ref().map_or(&[], |s| s.interfaces.as_slice())
    }

    fn bad(&self, block_type: u32, reason: &'static str) -> LivoxError {
        LivoxError::BadBlock { offset: self.offset, block_type, reason }
    }

    /// Looks at the block at the current offset.
    pub fn step(&mut self, input: &[u8], stats: &mut ReadStats) -> Result<Step> {
        if input.len() < MIN_BLOCK_LEN {
            return Ok(Step::Need(MIN_BLOCK_LEN));
        }
        let raw_type = u32::from_le_bytes([input[0], input[1], input[2], input[3]]);
        let endian = if raw_type == SHB_TYPE {
            // The type reads the same both ways; the byte-order magic decides.
            match u32::from_le_bytes([input[8], input[9], input[10], input[11]]) {
                BYTE_ORDER_MAGIC => Endian { big: false },
                m if m.swap_bytes() == BYTE_ORDER_MAGIC => Endian { big: true },
                _ => return Err(self.bad(SHB_TYPE, "byte-order magic is neither 0x1a2b3c4d nor swapped")),
            }
        } else {
            match &self.section {
                Some(s) => s.endian,
                None => return Err(self.bad(raw_type, "block before the first section header")),
            }
        };
        let block_type = endian.u32(input, 0);
        let len = endian.u32(input, 4) as usize;
        if len < MIN_BLOCK_LEN {
            return Err(self.bad(block_type, "total length below 12"));
        }
        if len & 3 != 0 {
            return Err(self.bad(block_type, "total length not a multiple of 4"));
        }
        if len > MAX_BLOCK_LEN {
            return Err(LivoxError::RecordTooLarge {
                format: FORMAT,
                offset: self.offset,
                len: len as u64,
                max: MAX_BLOCK_LEN,
            });
        }
        if input.len() < len {
            return Ok(Step::Need(len));
        }
        if endian.u32(input, len - 4) as usize != len {
            return Err(self.bad(block_type, "trailing total length differs from the leading one"));
        }
        let body = input.get(8..len - 4).unwrap_or(&[]);
        let step = match block_type {
            SHB_TYPE => {
                if body.len() < 16 {
                    return Err(self.bad(block_type, "section header shorter than 28 bytes"));
                }
                let (major, minor) = (endian.u16(body, 4), endian.u16(body, 6));
                if major != 1 {
                    return Err(LivoxError::UnsupportedCaptureVersion { format: FORMAT, major, minor });
                }
                self.section = Some(Section { endian, interfaces: Vec::new() });
                Step::Skip(len)
            }
            IDB_TYPE => {
                let interface = self.interface(body, endian)?;
                let Some(section) = self.section.as_mut() else {
                    return Err(self.bad(block_type, "block before the first section header"));
                };
                if section.interfaces.len() >= MAX_INTERFACES {
                    return Err(LivoxError::BadBlock {
                        offset: self.offset,
                        block_type,
                        reason: "more than 65536 interfaces",
                    });
                }
                section.interfaces.push(interface);
                Step::Skip(len)
            }
            EPB_TYPE | OPB_TYPE => {
                if body.len() < 20 {
                    return Err(self.bad(block_type, "packet block shorter than its fixed fields"));
                }
                let interface_id =
                    if block_type == EPB_TYPE { endian.u32(body, 0) } else { u32::from(endian.u16(body, 0)) };
                let ticks = (u64::from(endian.u32(body, 4)) << 32) | u64::from(endian.u32(body, 8));
                let captured = endian.u32(body, 12) as usize;
                let original = u64::from(endian.u32(body, 16));
                if captured > body.len() - 20 {
                    return Err(self.bad(block_type, "captured length runs past the block"));
                }
                let interface = self.find_interface(interface_id)?;
                self.last_time_ns = interface.time_ns(ticks);
                Step::Frame(FrameRef {
                    consumed: len,
                    time_ns: self.last_time_ns,
                    link_type: interface.link_type,
                    data: 28..28 + captured,
                    original_len: original,
                })
            }
            SPB_TYPE => {
                if body.len() < 4 {
                    return Err(self.bad(block_type, "simple packet block shorter than 16 bytes"));
                }
                let original = endian.u32(body, 0);
                let interface = self.find_interface(0)?;
                let mut captured = (original as usize).min(body.len() - 4);
                if interface.snaplen != 0 {
                    captured = captured.min(interface.snaplen as usize);
                }
                Step::Frame(FrameRef {
                    consumed: len,
                    time_ns: self.last_time_ns,
                    link_type: interface.link_type,
                    data: 12..12 + captured,
                    original_len: u64::from(original),
                })
            }
            _ => {
                stats.skipped_blocks += 1;
                Step::Skip(len)
            }
        };
        self.offset += len as u64;
        Ok(step)
    }

    fn find_interface(&self, id: u32) -> Result<Interface> {
        let interfaces = self.interfaces();
        interfaces.get(id as usize).copied().ok_or(LivoxError::UnknownInterface {
            offset: self.offset,
            interface: id,
            known: interfaces.len(),
        })
    }

    fn interface(&self, body: &[u8], endian: Endian) -> Result<Interface> {
        if body.len() < 8 {
            return Err(self.bad(IDB_TYPE, "interface block shorter than 20 bytes"));
        }
        let mut interface = Interface {
            link_type: endian.u16(body, 0),
            snaplen: endian.u32(body, 4),
            ts_resolution: TsResolution::Decimal(6),
            ts_offset_s: 0,
        };
        let mut rest = body.get(8..).unwrap_or(&[]);
        while rest.len() >= 4 {
            let code = endian.u16(rest, 0);
            let len = usize::from(endian.u16(rest, 2));
            if code == OPT_END {
                break;
            }
            let padded = (len + 3) & !3;
            let Some(value) = rest.get(4..4 + len) else {
                return Err(self.bad(IDB_TYPE, "option runs past the block"));
            };
            match (code, value) {
                (IF_TSRESOL, &[b]) => interface.ts_resolution = TsResolution::from_byte(b),
                (IF_TSRESOL, _) => return Err(self.bad(IDB_TYPE, "if_tsresol is not 1 byte")),
                (IF_TSOFFSET, v) if v.len() == 8 => interface.ts_offset_s = endian.u64(v, 0) as i64,
                (IF_TSOFFSET, _) => return Err(self.bad(IDB_TYPE, "if_tsoffset is not 8 bytes")),
                _ => {}
            }
            rest = rest.get(4 + padded..).unwrap_or(&[]);
        }
        Ok(interface)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn resolutions() {
        assert_eq!(TsResolution::Decimal(6).to_ns(1_500_000), 1_500_000_000);
        assert_eq!(TsResolution::Decimal(9).to_ns(7), 7);
        assert_eq!(TsResolution::Decimal(12).to_ns(7_000), 7);
        assert_eq!(TsResolution::Decimal(0).to_ns(3), 3_000_000_000);
        assert_eq!(TsResolution::Decimal(100).to_ns(u64::MAX), 0);
        assert_eq!(TsResolution::from_byte(0x80 | 10), TsResolution::Binary(10));
        assert_eq!(TsResolution::Binary(10).to_ns(1024), 1_000_000_000);
        assert_eq!(TsResolution::Binary(127).to_ns(u64::MAX), 0);
        assert_eq!(TsResolution::Binary(0).to_ns(u64::MAX), u64::MAX);
    }
}
