//! The control-frame envelope: start byte, version, length, type, sequence, two CRCs.

use crate::crc::{crc16, crc32};
use crate::error::{need, LivoxError, Result};

pub const START_OF_FRAME: u8 = 0xAA;
pub const CONTROL_VERSION: u8 = 1;
/// sof, version, length u16, cmd_type, seq u16, crc16 u16, cmd_set, cmd_id.
pub const HEADER_LEN: usize = 11;
pub const CRC32_LEN: usize = 4;
/// The smallest possible frame: a header with an empty payload.
pub const MIN_FRAME_LEN: usize = HEADER_LEN + CRC32_LEN;
/// Largest frame we build or accept; real frames are well under 1400 bytes.
pub const MAX_FRAME_LEN: usize = 1400;

/// CMD, ACK or MSG.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum CmdType {
    Cmd = 0,
    Ack = 1,
    Msg = 2,
}

impl CmdType {
    pub fn from_u8(value: u8) -> Result<Self> {
        match value {
            0 => Ok(Self::Cmd),
            1 => Ok(Self::Ack),
            2 => Ok(Self::Msg),
            other => Err(LivoxError::BadCmdType(other)),
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Self::Cmd => "cmd",
            Self::Ack => "ack",
            Self::Msg => "msg",
        }
    }
}

/// A checked control frame borrowing its payload from the datagram.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RawFrame<'a> {
    pub cmd_type: CmdType,
    pub seq: u16,
    pub cmd_set: u8,
    pub cmd_id: u8,
    pub payload: &'a [u8],
}

impl<'a> RawFrame<'a> {
    /// Parses and verifies one frame (length and both CRCs). Trailing bytes are an error: a
    /// datagram carries exactly one frame.
    pub fn decode(bytes: &'a [u8]) -> Result<Self> {
        need("control frame", bytes, MIN_FRAME_LEN)?;
        if bytes[0] != START_OF_FRAME {
            return Err(LivoxError::BadStartOfFrame(bytes[0]));
        }
        if bytes[1] != CONTROL_VERSION {
            return Err(LivoxError::BadControlVersion(bytes[1]));
        }
        let declared = usize::from(u16::from_le_bytes([bytes[2], bytes[3]]));
        if declared != bytes.len() {
            return Err(LivoxError::LengthMismatch { declared, actual: bytes.len() });
        }
        let stored16 = u16::from_le_bytes([bytes[7], bytes[8]]);
        let computed16 = crc16(&bytes[..7]);
        if stored16 != computed16 {
            return Err(LivoxError::BadHeaderCrc { stored: stored16, computed: computed16 });
        }
        let body_end = bytes.len() - CRC32_LEN;
        let stored32 =
            u32::from_le_bytes([bytes[body_end], bytes[body_end + 1], bytes[body_end + 2], bytes[body_end + 3]]);
        let computed32 = crc32(&bytes[..body_end]);
        if stored32 != computed32 {
            return Err(LivoxError::BadFrameCrc { stored: stored32, computed: computed32 });
        }
        Ok(Self {
            cmd_type: CmdType::from_u8(bytes[4])?,
            seq: u16::from_le_bytes([bytes[5], bytes[6]]),
            cmd_set: bytes[9],
            cmd_id: bytes[10],
            payload: &bytes[HEADER_LEN..body_end],
        })
    }

    /// Appends the encoded frame to `out`.
    pub fn encode_into(&self, out: &mut Vec<u8>) -> Result<()> {
        let total = MIN_FRAME_LEN + self.payload.len();
        if total > MAX_FRAME_LEN {
            return Err(LivoxError::BadValue { field: "frame length", value: total as u32 });
        }
        let start = out.len();
        out.push(START_OF_FRAME);
        out.push(CONTROL_VERSION);
        out.extend_from_slice(&(total as u16).to_le_bytes());
        out.push(self.cmd_type as u8);
        out.extend_from_slice(&self.seq.to_le_bytes());
        let header_crc = crc16(&out[start..start + 7]);
        out.extend_from_slice(&header_crc.to_le_bytes());
        out.push(self.cmd_set);
        out.push(self.cmd_id);
        out.extend_from_slice(self.payload);
        let frame_crc = crc32(&out[start..]);
        out.extend_from_slice(&frame_crc.to_le_bytes());
        Ok(())
    }

    pub fn encode(&self) -> Result<Vec<u8>> {
        let mut out = Vec::with_capacity(MIN_FRAME_LEN + self.payload.len());
        self.encode_into(&mut out)?;
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(payload: &[u8]) -> Vec<u8> {
        RawFrame { cmd_type: CmdType::Cmd, seq: 7, cmd_set: 0, cmd_id: 3, payload }.encode().unwrap_or_default()
    }

    #[test]
    fn round_trip() {
        let bytes = frame(&[1, 2, 3]);
        assert_eq!(bytes.len(), 18);
        let back = RawFrame::decode(&bytes).ok();
        assert_eq!(back.map(|f| (f.seq, f.cmd_id, f.payload.to_vec())), Some((7, 3, vec![1, 2, 3])));
    }

    #[test]
    fn every_corrupted_byte_is_caught() {
        let bytes = frame(&[9, 8, 7, 6]);
        for i in 0..bytes.len() {
            let mut bad = bytes.clone();
            bad[i] ^= 0x40;
            assert!(RawFrame::decode(&bad).is_err(), "flip at byte {i} went unnoticed");
        }
    }

    #[test]
    fn truncation_is_a_typed_error() {
        let bytes = frame(&[]);
        for len in 0..bytes.len() {
            assert!(RawFrame::decode(&bytes[..len]).is_err());
        }
        assert!(matches!(RawFrame::decode(&[]), Err(LivoxError::TooShort { .. })));
    }
}
