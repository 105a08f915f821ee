//! Classic pcap: a 24-byte file header, then records of a 16-byte header and the captured bytes.
//!
//! Both byte orders and both time resolutions (microsecond magic 0xa1b2c3d4, nanosecond magic
//! 0xa1b23c4d) are read; the writer emits little-endian files of either resolution.

use super::net::{self, build_udp_frame, MAX_UDP_PAYLOAD};
use super::{Datagram, Endian, FrameRef, Step, MAX_RECORD_LEN};
use crate::error::{LivoxError, Result};
use serde::Serialize;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::net::SocketAddrV4;
use std::path::Path;

pub const MAGIC_MICROS: u32 = 0xa1b2_c3d4;
pub const MAGIC_NANOS: u32 = 0xa1b2_3c4d;
pub const FILE_HEADER_LEN: usize = 24;
pub const RECORD_HEADER_LEN: usize = 16;
const FORMAT: &str = "pcap";

/// Whether 4 bytes are a pcap magic number in either byte order.
pub fn is_magic(b: &[u8]) -> bool {
    let Some(&[a, b, c, d]) = b.get(..4).and_then(|s| <&[u8; 4]>::try_from(s).ok()) else {
        return false;
    };
    let le = u32::from_le_bytes([a, b, c, d]);
    let be = u32::from_be_bytes([a, b, c, d]);
    [le, be].iter().any(|&m| m == MAGIC_MICROS || m == MAGIC_NANOS)
}

/// Time-stamp resolution of a pcap file.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum TsPrecision {
    Micro,
    Nano,
}

/// The file header.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct PcapHeader {
    pub big_endian: bool,
    pub precision: TsPrecision,
    pub version_major: u16,
    pub version_minor: u16,
    pub snaplen: u32,
    pub link_type: u16,
    /// Frame check sequence bytes at the end of each frame, when the header says (in bytes).
    pub fcs_len: Option<u8>,
}

impl PcapHeader {
    pub fn decode(b: &[u8]) -> Result<Self> {
        crate::error::need("pcap file header", b, FILE_HEADER_LEN)?;
        let le_magic = u32::from_le_bytes([b[0], b[1], b[2], b[3]]);
        let (big_endian, magic) = if le_magic == MAGIC_MICROS || le_magic == MAGIC_NANOS {
            (false, le_magic)
        } else {
            (true, u32::from_be_bytes([b[0], b[1], b[2], b[3]]))
        };
        let precision = match magic {
            MAGIC_MICROS => TsPrecision::Micro,
            MAGIC_NANOS => TsPrecision::Nano,
            _ => return Err(LivoxError::UnknownCaptureFormat(b[..4].to_vec())),
        };
        let e = Endian { big: big_endian };
        let (version_major, version_minor) = (e.u16(b, 4), e.u16(b, 6));
        if version_major != 2 {
            return Err(LivoxError::UnsupportedCaptureVersion {
                format: FORMAT,
                major: version_major,
                minor: version_minor,
            });
        }
        let link_field = e.u32(b, 20);
        // Bits 28-31: F flag and FCS length in 16-bit words; bits 0-15: the link type.
        let fcs_len = (link_field & 0x1000_0000 != 0).then(|| ((link_field >> 29) as u8) * 2);
        let link_type = (link_field & 0xffff) as u16;
        if !net::is_supported_link(link_type) {
            return Err(LivoxError::UnsupportedLinkType(u32::from(link_type)));
        }
        Ok(Self { big_endian, precision, version_major, version_minor, snaplen: e.u32(b, 16), link_type, fcs_len })
    }

    fn encode(&self) -> [u8; FILE_HEADER_LEN] {
        let magic = match self.precision {
            TsPrecision::Micro => MAGIC_MICROS,
            TsPrecision::Nano => MAGIC_NANOS,
        };
        let mut h = [0u8; FILE_HEADER_LEN];
        h[..4].copy_from_slice(&magic.to_le_bytes());
        h[4..6].copy_from_slice(&self.version_major.to_le_bytes());
        h[6..8].copy_from_slice(&self.version_minor.to_le_bytes());
        h[16..20].copy_from_slice(&self.snaplen.to_le_bytes());
        h[20..24].copy_from_slice(&u32::from(self.link_type).to_le_bytes());
        h
    }
}

/// Sans-IO pcap decoder.
#[derive(Clone, Debug, Default)]
pub struct PcapDecoder {
    header: Option<PcapHeader>,
    offset: u64,
}

impl PcapDecoder {
    pub fn new() -> Self {
        Self::default()
    }

    pub fn header(&self) -> Option<&PcapHeader> {
        self.header.as_ref()
    }

    /// File offset of the next byte to decode.
    pub fn offset(&self) -> u64 {
        self.offset
    }

    /// Looks at the bytes at the current offset.
    pub fn step(&mut self, input: &[u8]) -> Result<Step> {
        let Some(h) = self.header else {
            if input.len() < FILE_HEADER_LEN {
                return Ok(Step::Need(FILE_HEADER_LEN));
            }
            self.header = Some(PcapHeader::decode(input)?);
            self.offset += FILE_HEADER_LEN as u64;
            return Ok(Step::Skip(FILE_HEADER_LEN));
        };
        if input.len() < RECORD_HEADER_LEN {
            return Ok(Step::Need(RECORD_HEADER_LEN));
        }
        let e = Endian { big: h.big_endian };
        let (sec, frac) = (u64::from(e.u32(input, 0)), u64::from(e.u32(input, 4)));
        let (incl, orig) = (e.u32(input, 8), e.u32(input, 12));
        if incl as usize > MAX_RECORD_LEN {
            return Err(LivoxError::RecordTooLarge {
                format: FORMAT,
                offset: self.offset,
                len: u64::from(incl),
                max: MAX_RECORD_LEN,
            });
        }
        let total = RECORD_HEADER_LEN + incl as usize;
        if input.len() < total {
            return Ok(Step::Need(total));
        }
        let frac_ns = match h.precision {
            TsPrecision::Micro => frac * 1_000,
            TsPrecision::Nano => frac,
        };
        self.offset += total as u64;
        Ok(Step::Frame(FrameRef {
            consumed: total,
            time_ns: sec * 1_000_000_000 + frac_ns,
            link_type: h.link_type,
            data: RECORD_HEADER_LEN..total,
            original_len: u64::from(orig),
        }))
    }
}

/// Writes UDP datagrams as Ethernet/IPv4/UDP frames into a little-endian pcap file.
pub struct PcapWriter<W: Write> {
    out: W,
    precision: TsPrecision,
    ip_id: u16,
    frame: Vec<u8>,
    records: u64,
}

impl PcapWriter<BufWriter<File>> {
    pub fn create(path: &Path, precision: TsPrecision) -> Result<Self> {
        let file = File::create(path).map_err(|e| LivoxError::io(format!("creating {}", path.display()), e))?;
        Self::new(BufWriter::new(file), precision)
    }
}

impl<W: Write> PcapWriter<W> {
    /// Writes the file header (link type Ethernet, snaplen 262144).
    pub fn new(mut out: W, precision: TsPrecision) -> Result<Self> {
        let header = PcapHeader {
            big_endian: false,
            precision,
            version_major: 2,
            version_minor: 4,
            snaplen: MAX_RECORD_LEN as u32,
            link_type: net::LINKTYPE_ETHERNET,
            fcs_len: None,
        };
        out.write_all(&header.encode()).map_err(|e| LivoxError::io("writing pcap header", e))?;
        Ok(Self { out, precision, ip_id: 0, frame: Vec::with_capacity(1600), records: 0 })
    }

    /// Appends one datagram captured at `time_ns` (nanoseconds since the Unix epoch; the
    /// microsecond format rounds down).
    pub fn write_udp(&mut self, time_ns: u64, src: SocketAddrV4, dst: SocketAddrV4, payload: &[u8]) -> Result<()> {
        if payload.len() > MAX_UDP_PAYLOAD {
            return Err(LivoxError::TooLarge { what: "UDP payload", len: payload.len(), max: MAX_UDP_PAYLOAD });
        }
        let sec = time_ns / 1_000_000_000;
        let sec = u32::try_from(sec).map_err(|_| LivoxError::BadValue {
            field: "pcap time stamp seconds",
            value: u32::try_from(sec >> 32).unwrap_or(u32::MAX),
        })?;
        let frac = match self.precision {
            TsPrecision::Micro => (time_ns % 1_000_000_000) / 1_000,
            TsPrecision::Nano => time_ns % 1_000_000_000,
        } as u32;
        self.frame.clear();
        build_udp_frame(src, dst, self.ip_id, payload, &mut self.frame);
        self.ip_id = self.ip_id.wrapping_add(1);
        let len = self.frame.len() as u32;
        let mut record = [0u8; RECORD_HEADER_LEN];
        record[..4].copy_from_slice(&sec.to_le_bytes());
        record[4..8].copy_from_slice(&frac.to_le_bytes());
        record[8..12].copy_from_slice(&len.to_le_bytes());
        record[12..16].copy_from_slice(&len.to_le_bytes());
        self.out.write_all(&record).map_err(|e| LivoxError::io("writing pcap record", e))?;
        self.out.write_all(&self.frame).map_err(|e| LivoxError::io("writing pcap record", e))?;
        self.records += 1;
        Ok(())
    }

    /// Appends a datagram read from a capture; it must carry both addresses.
    pub fn write_datagram(&mut self, d: &Datagram) -> Result<()> {
        let src = d.src.ok_or(LivoxError::MissingAddress("source"))?;
        let dst = d.dst.ok_or(LivoxError::MissingAddress("destination"))?;
        self.write_udp(d.time.ns, src, dst, &d.payload)
    }

    /// Records written so far.
    pub fn records(&self) -> u64 {
        self.records
    }

    /// Flushes and hands back the writer.
    pub fn finish(mut self) -> Result<W> {
        self.out.flush().map_err(|e| LivoxError::io("flushing pcap", e))?;
        Ok(self.out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn magics_in_both_orders() {
        for m in [MAGIC_MICROS, MAGIC_NANOS] {
            assert!(is_magic(&m.to_le_bytes()));
            assert!(is_magic(&m.to_be_bytes()));
        }
        assert!(!is_magic(&[0xa1, 0xb2]));
        assert!(!is_magic(&0x0a0d_0d0au32.to_le_bytes()));
    }

    #[test]
    fn header_fields_and_refusals() {
        let mut h = PcapHeader {
            big_endian: false,
            precision: TsPrecision::Nano,
            version_major: 2,
            version_minor: 4,
            snaplen: 65535,
            link_type: 113,
            fcs_len: None,
        }
        .encode();
        assert_eq!(
            PcapHeader::decode(&h).map(|h| (h.link_type, h.snaplen, h.precision)).ok(),
            Some((113, 65535, TsPrecision::Nano))
        );
        h[20..24].copy_from_slice(&(1u32 | 0x1000_0000 | (2 << 29)).to_le_bytes());
        assert_eq!(PcapHeader::decode(&h).map(|h| (h.link_type, h.fcs_len)).ok(), Some((1, Some(4))));
        h[20..24].copy_from_slice(&105u32.to_le_bytes());
        assert!(matches!(PcapHeader::decode(&h), Err(LivoxError::UnsupportedLinkType(105))));
        h[4] = 3;
        assert!(matches!(PcapHeader::decode(&h), Err(LivoxError::UnsupportedCaptureVersion { major: 3, .. })));
    }
}
