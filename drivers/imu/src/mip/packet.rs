//! MIP packet framing: `0x75 0x65`, descriptor set, payload length, fields
//! `[length incl. its 2 header bytes, descriptor, data...]`, Fletcher-16 over everything before
//! it (MSB = first sum). Multi-byte values are big-endian.

use crate::error::{ImuError, Result};

pub const SYNC1: u8 = 0x75;
pub const SYNC2: u8 = 0x65;
pub const HEADER_LEN: usize = 4;
pub const CHECKSUM_LEN: usize = 2;
pub const MAX_PAYLOAD_LEN: usize = 255;
/// The longest packet the length byte allows.
pub const MAX_PACKET_LEN: usize = HEADER_LEN + MAX_PAYLOAD_LEN + CHECKSUM_LEN;
/// A field's own header: length and descriptor.
pub const FIELD_HEADER_LEN: usize = 2;
/// The most data one field can hold (its length byte counts its header too).
pub const MAX_FIELD_DATA_LEN: usize = 255 - FIELD_HEADER_LEN;

/// The MIP Fletcher-16: `s1 += b; s2 += s1` (mod 256) over `bytes`, as `s1 << 8 | s2`.
pub fn fletcher16(bytes: &[u8]) -> u16 {
    let (mut s1, mut s2) = (0u8, 0u8);
    for &b in bytes {
        s1 = s1.wrapping_add(b);
        s2 = s2.wrapping_add(s1);
    }
    u16::from_be_bytes([s1, s2])
}

/// One field of a packet.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Field<'a> {
    pub descriptor: u8,
    pub data: &'a [u8],
}

/// A checked packet borrowed from a byte buffer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Packet<'a> {
    pub descriptor_set: u8,
    pub payload: &'a [u8],
}

impl<'a> Packet<'a> {
    /// Parses the packet at the start of `bytes`; returns it and its length on the wire.
    /// Checks sync bytes, length and checksum (not the field layout: see [`Packet::fields`]).
    pub fn parse(bytes: &'a [u8]) -> Result<(Self, usize)> {
        let header: [u8; HEADER_LEN] = bytes
            .get(..HEADER_LEN)
            .and_then(|h| h.try_into().ok())
            .ok_or(ImuError::TooShort { what: "MIP header", need: HEADER_LEN, have: bytes.len() })?;
        let [s1, s2, descriptor_set, payload_len] = header;
        if (s1, s2) != (SYNC1, SYNC2) {
            return Err(ImuError::BadSync([s1, s2]));
        }
        let total = HEADER_LEN + usize::from(payload_len) + CHECKSUM_LEN;
        let packet =
            bytes.get(..total).ok_or(ImuError::TooShort { what: "MIP packet", need: total, have: bytes.len() })?;
        let (body, sum) = packet.split_at(total - CHECKSUM_LEN);
        let stored = u16::from_be_bytes([sum.first().copied().unwrap_or(0), sum.get(1).copied().unwrap_or(0)]);
        let computed = fletcher16(body);
        if stored != computed {
            return Err(ImuError::BadChecksum { stored, computed });
        }
        let payload = body.get(HEADER_LEN..).unwrap_or_default();
        Ok((Self { descriptor_set, payload }, total))
    }

    /// The fields of the payload, each checked to fit.
    pub fn fields(&self) -> Fields<'a> {
        Fields { set: self.descriptor_set, payload: self.payload, offset: 0 }
    }
}

/// Iterator over a payload's fields; yields an error (once, then stops) on a bad layout.
#[derive(Clone, Debug)]
pub struct Fields<'a> {
    set: u8,
    payload: &'a [u8],
    offset: usize,
}

impl<'a> Iterator for Fields<'a> {
    type Item = Result<Field<'a>>;

    fn next(&mut self) -> Option<Self::Item> {
        let rest = self.payload.get(self.offset..)?;
        let (&len, &descriptor) = match rest {
            [] => return None,
            [len, descriptor, ..] => (len, descriptor),
            [_] => {
                let offset = self.offset;
                self.offset = self.payload.len();
                return Some(Err(ImuError::BadField {
                    set: self.set,
                    offset,
                    reason: "one byte left: no room for a field",
                }));
            }
        };
        let offset = self.offset;
        let len = usize::from(len);
        if len < FIELD_HEADER_LEN {
            self.offset = self.payload.len();
            return Some(Err(ImuError::BadField { set: self.set, offset, reason: "field length under 2" }));
        }
        let Some(data) = rest.get(FIELD_HEADER_LEN..len) else {
            self.offset = self.payload.len();
            return Some(Err(ImuError::BadField { set: self.set, offset, reason: "field runs past the payload" }));
        };
        self.offset += len;
        Some(Ok(Field { descriptor, data }))
    }
}

/// Builds one packet field by field.
#[derive(Clone, Debug)]
pub struct PacketWriter {
    descriptor_set: u8,
    payload: Vec<u8>,
}

impl PacketWriter {
    pub fn new(descriptor_set: u8) -> Self {
        Self { descriptor_set, payload: Vec::with_capacity(64) }
    }

    /// Appends a field; refuses one that would overflow the field or the payload.
    pub fn field(&mut self, descriptor: u8, data: &[u8]) -> Result<&mut Self> {
        let len = data.len() + FIELD_HEADER_LEN;
        if data.len() > MAX_FIELD_DATA_LEN || self.payload.len() + len > MAX_PAYLOAD_LEN {
            return Err(ImuError::PayloadTooLong { len: self.payload.len() + len });
        }
        self.payload.push(len as u8);
        self.payload.push(descriptor);
        self.payload.extend_from_slice(data);
        Ok(self)
    }

    /// Appends the whole packet to `out`.
    pub fn finish(&self, out: &mut Vec<u8>) {
        let start = out.len();
        out.extend_from_slice(&[SYNC1, SYNC2, self.descriptor_set, self.payload.len() as u8]);
        out.extend_from_slice(&self.payload);
        let sum = fletcher16(out.get(start..).unwrap_or_default());
        out.extend_from_slice(&sum.to_be_bytes());
    }

    /// The packet as a new buffer.
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(HEADER_LEN + self.payload.len() + CHECKSUM_LEN);
        self.finish(&mut out);
        out
    }
}

/// Big-endian readers over a field's data at fixed offsets (the caller checked the length).
pub(crate) fn be_f32(data: &[u8], at: usize) -> f32 {
    let b: [u8; 4] = data.get(at..at + 4).and_then(|s| s.try_into().ok()).unwrap_or([0; 4]);
    f32::from_be_bytes(b)
}

pub(crate) fn be_f64(data: &[u8], at: usize) -> f64 {
    let b: [u8; 8] = data.get(at..at + 8).and_then(|s| s.try_into().ok()).unwrap_or([0; 8]);
    f64::from_be_bytes(b)
}

pub(crate) fn be_u16(data: &[u8], at: usize) -> u16 {
    u16::from_be_bytes([data.get(at).copied().unwrap_or(0), data.get(at + 1).copied().unwrap_or(0)])
}

pub(crate) fn be_u32(data: &[u8], at: usize) -> u32 {
    let b: [u8; 4] = data.get(at..at + 4).and_then(|s| s.try_into().ok()).unwrap_or([0; 4]);
    u32::from_be_bytes(b)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ping_matches_the_published_bytes() {
        // The MIP ping command as printed in MicroStrain's protocol manuals.
        let mut w = PacketWriter::new(0x01);
        w.field(0x01, &[]).map(|_| ()).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(w.to_bytes(), [0x75, 0x65, 0x01, 0x02, 0x02, 0x01, 0xE0, 0xC6]);
    }

    #[test]
    fn parse_checks_everything() {
        let good = [0x75, 0x65, 0x01, 0x02, 0x02, 0x01, 0xE0, 0xC6];
        let (p, n) = Packet::parse(&good).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!((p.descriptor_set, p.payload, n), (0x01, &good[4..6], 8));
        assert!(matches!(Packet::parse(&good[..3]), Err(ImuError::TooShort { need: 4, .. })));
        assert!(matches!(Packet::parse(&good[..7]), Err(ImuError::TooShort { need: 8, have: 7, .. })));
        let mut bad = good;
        bad[0] = 0x74;
        assert!(matches!(Packet::parse(&bad), Err(ImuError::BadSync([0x74, 0x65]))));
        let mut bad = good;
        bad[7] ^= 1;
        assert!(matches!(Packet::parse(&bad), Err(ImuError::BadChecksum { stored: 0xE0C7, computed: 0xE0C6 })));
    }

    fn packet_with_payload(payload: &[u8]) -> Vec<u8> {
        let mut v = vec![SYNC1, SYNC2, 0x80, payload.len() as u8];
        v.extend_from_slice(payload);
        let s = fletcher16(&v);
        v.extend_from_slice(&s.to_be_bytes());
        v
    }

    #[test]
    fn bad_field_layouts_are_errors() {
        for (payload, reason) in [
            (&[0x02, 0x04, 0x05][..], "one byte left: no room for a field"),
            (&[0x01, 0x04][..], "field length under 2"),
            (&[0x05, 0x04, 0x00][..], "field runs past the payload"),
        ] {
            let bytes = packet_with_payload(payload);
            let (p, _) = Packet::parse(&bytes).unwrap_or_else(|e| panic!("{e}"));
            let results: Vec<_> = p.fields().collect();
            let last = results.last().unwrap_or_else(|| panic!("no fields"));
            assert!(matches!(last, Err(ImuError::BadField { reason: r, .. }) if *r == reason), "{results:?}");
        }
    }

    #[test]
    fn writer_refuses_overflow() {
        let mut w = PacketWriter::new(0x80);
        assert!(w.field(0x01, &[0; 254]).is_err());
        assert!(w.field(0x01, &[0; 253]).is_ok());
        assert!(w.field(0x02, &[]).is_err()); // 255 + 2 > 255
        assert_eq!(w.to_bytes().len(), MAX_PACKET_LEN);
    }
}
