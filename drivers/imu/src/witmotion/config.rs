//! WitMotion configuration writes: `FF AA register value_lo value_hi`, after the unlock write
//! `FF AA 69 88 B5`; `FF AA 00 00 00` saves to flash.
//!
//! The device answers nothing. What STARC does instead: after a rate change the transport
//! measures the output rate over a window and fails when it is not the rate asked for
//! ([`crate::serial::ImuHandle::set_witmotion_rate`]); after a baud change it reopens the port at
//! the new rate and requires good frames (checksums pass) within a timeout.

use crate::error::{ImuError, Result};

pub const CONFIG_HEADER: [u8; 2] = [0xFF, 0xAA];
pub const CONFIG_LEN: usize = 5;

pub const REG_SAVE: u8 = 0x00;
/// Which frames are output: bit k enables type 0x50 + k.
pub const REG_OUTPUT_CONTENT: u8 = 0x02;
pub const REG_RATE: u8 = 0x03;
pub const REG_BAUD: u8 = 0x04;
pub const REG_UNLOCK: u8 = 0x69;
pub const UNLOCK_KEY: u16 = 0xB588;

/// Output rates of register 0x03 (code, Hz); 0x0C is "on request", 0x0D "no output".
pub const RATES: [(u16, f64); 11] = [
    (0x01, 0.2),
    (0x02, 0.5),
    (0x03, 1.0),
    (0x04, 2.0),
    (0x05, 5.0),
    (0x06, 10.0),
    (0x07, 20.0),
    (0x08, 50.0),
    (0x09, 100.0),
    (0x0A, 125.0),
    (0x0B, 200.0),
];
pub const RATE_NO_OUTPUT: u16 = 0x0D;

/// Baud rates of register 0x04 (code, baud).
pub const BAUDS: [(u16, u32); 9] = [
    (0x01, 4800),
    (0x02, 9600),
    (0x03, 19_200),
    (0x04, 38_400),
    (0x05, 57_600),
    (0x06, 115_200),
    (0x07, 230_400),
    (0x08, 460_800),
    (0x09, 921_600),
];

/// The register code of an output rate.
pub fn rate_code(rate_hz: f64) -> Result<u16> {
    RATES
        .iter()
        .find(|&&(_, hz)| (hz - rate_hz).abs() < 1e-9)
        .map(|&(c, _)| c)
        .ok_or(ImuError::UnsupportedRate { rate_hz })
}

/// The output rate of a register code; `None` for no or on-request output and unknown codes.
pub fn rate_hz(code: u16) -> Option<f64> {
    RATES.iter().find(|&&(c, _)| c == code).map(|&(_, hz)| hz)
}

pub fn baud_code(baud: u32) -> Result<u16> {
    BAUDS
        .iter()
        .find(|&&(_, b)| b == baud)
        .map(|&(c, _)| c)
        .ok_or(ImuError::UnsupportedBaud { protocol: "WitMotion", baud })
}

pub fn baud(code: u16) -> Option<u32> {
    BAUDS.iter().find(|&&(c, _)| c == code).map(|&(_, b)| b)
}

/// One register write.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ConfigWrite {
    pub register: u8,
    pub value: u16,
}

impl ConfigWrite {
    pub fn unlock() -> Self {
        Self { register: REG_UNLOCK, value: UNLOCK_KEY }
    }

    pub fn save() -> Self {
        Self { register: REG_SAVE, value: 0 }
    }

    pub fn rate(rate_hz: f64) -> Result<Self> {
        Ok(Self { register: REG_RATE, value: rate_code(rate_hz)? })
    }

    pub fn baud(baud: u32) -> Result<Self> {
        Ok(Self { register: REG_BAUD, value: baud_code(baud)? })
    }

    /// Output only the frame types in `types` (each 0x50..=0x5F).
    pub fn output_content(types: &[u8]) -> Self {
        let mask = types.iter().filter(|&&t| (0x50..=0x5F).contains(&t)).fold(0u16, |m, &t| m | 1 << (t - 0x50));
        Self { register: REG_OUTPUT_CONTENT, value: mask }
    }

    pub fn encode(&self) -> [u8; CONFIG_LEN] {
        let [lo, hi] = self.value.to_le_bytes();
        [CONFIG_HEADER[0], CONFIG_HEADER[1], self.register, lo, hi]
    }

    pub fn parse(bytes: &[u8]) -> Result<Self> {
        let [a, b, register, lo, hi]: [u8; CONFIG_LEN] = bytes
            .get(..CONFIG_LEN)
            .and_then(|s| s.try_into().ok())
            .ok_or(ImuError::TooShort { what: "WitMotion config write", need: CONFIG_LEN, have: bytes.len() })?;
        if [a, b] != CONFIG_HEADER {
            return Err(ImuError::WitBadConfigHeader([a, b]));
        }
        Ok(Self { register, value: u16::from_le_bytes([lo, hi]) })
    }

    /// The writes that set a register: unlock, then the write.
    pub fn unlocked(self) -> [[u8; CONFIG_LEN]; 2] {
        [Self::unlock().encode(), self.encode()]
    }
}

/// Finds config writes in a byte stream (what a device does with its input): resynchronises on
/// `FF AA`, never holds more than one write.
#[derive(Clone, Debug, Default)]
pub struct ConfigDecoder {
    buf: [u8; CONFIG_LEN],
    len: usize,
    /// Bytes that were not part of a write.
    pub skipped_bytes: u64,
}

impl ConfigDecoder {
    pub fn new() -> Self {
        Self::default()
    }

    pub fn push(&mut self, bytes: &[u8], out: &mut Vec<ConfigWrite>) {
        for &b in bytes {
            let ok = match self.len {
                0 => b == CONFIG_HEADER[0],
                1 => b == CONFIG_HEADER[1],
                _ => true,
            };
            if !ok {
                // `FF FF AA`: the second FF may start the write.
                self.skipped_bytes += self.len as u64;
                self.len = 0;
                if b == CONFIG_HEADER[0] {
                    self.len = 1;
                } else {
                    self.skipped_bytes += 1;
                }
                continue;
            }
            if let Some(slot) = self.buf.get_mut(self.len) {
                *slot = b;
            }
            self.len += 1;
            if self.len == CONFIG_LEN {
                self.len = 0;
                if let Ok(w) = ConfigWrite::parse(&self.buf) {
                    out.push(w);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn known_writes() {
        assert_eq!(ConfigWrite::unlock().encode(), [0xFF, 0xAA, 0x69, 0x88, 0xB5]);
        assert_eq!(ConfigWrite::save().encode(), [0xFF, 0xAA, 0x00, 0x00, 0x00]);
        assert_eq!(ConfigWrite::rate(200.0).map(|w| w.encode()).ok(), Some([0xFF, 0xAA, 0x03, 0x0B, 0x00]));
        assert_eq!(ConfigWrite::baud(115_200).map(|w| w.encode()).ok(), Some([0xFF, 0xAA, 0x04, 0x06, 0x00]));
        assert_eq!(ConfigWrite::output_content(&[0x51, 0x52, 0x53, 0x59, 0x70]).value, 0b10_0000_1110);
        assert!(matches!(ConfigWrite::rate(300.0), Err(ImuError::UnsupportedRate { .. })));
        assert!(matches!(ConfigWrite::baud(12345), Err(ImuError::UnsupportedBaud { .. })));
        assert_eq!(rate_hz(0x08), Some(50.0));
        assert_eq!(rate_hz(RATE_NO_OUTPUT), None);
        assert_eq!(baud(0x09), Some(921_600));
        assert_eq!(baud(0x0A), None);
    }

    #[test]
    fn parse_errors_and_round_trip() {
        let w = ConfigWrite { register: 0x23, value: 0x0102 };
        assert_eq!(ConfigWrite::parse(&w.encode()).ok(), Some(w));
        assert!(matches!(ConfigWrite::parse(&[0xFF, 0xAA]), Err(ImuError::TooShort { .. })));
        assert!(matches!(ConfigWrite::parse(&[0xFF, 0xAB, 0, 0, 0]), Err(ImuError::WitBadConfigHeader(_))));
    }

    #[test]
    fn stream_resyncs_on_the_header() {
        let mut d = ConfigDecoder::new();
        let mut out = Vec::new();
        let mut bytes = vec![0x00, 0xFF, 0x12, 0xFF, 0xFF];
        bytes.extend_from_slice(&[0xAA, 0x03, 0x08, 0x00]); // the second FF starts a write
        bytes.extend_from_slice(&ConfigWrite::unlock().encode());
        for chunk in bytes.chunks(2) {
            d.push(chunk, &mut out);
        }
        assert_eq!(out, vec![ConfigWrite { register: 0x03, value: 0x08 }, ConfigWrite::unlock()]);
        assert_eq!(d.skipped_bytes, 4);
    }
}
