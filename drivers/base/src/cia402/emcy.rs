//! CANopen emergency messages: 0x80 + node, error code u16, error register u8, 5 bytes of
//! manufacturer data.

use crate::error::{bytes, need, BaseError, Result};
use starc_can::{CanFrame, CanId};

pub const EMCY_BASE: u16 = 0x080;

/// One EMCY message.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Emergency {
    pub node: u8,
    /// 0x0000 = error reset (the node says its errors are gone).
    pub code: u16,
    /// Object 0x1001: bit 0 generic, 1 current, 2 voltage, 3 temperature, 4 communication,
    /// 5 device profile, 7 manufacturer.
    pub register: u8,
    pub vendor: [u8; 5],
}

impl Emergency {
    pub fn parse(frame: &CanFrame) -> Result<Self> {
        let node = match frame.id() {
            // 0x080 itself is SYNC.
            CanId::Standard(id @ 0x081..=0x0FF) => (id - EMCY_BASE) as u8,
            other => return Err(BaseError::WrongId { what: "EMCY", id: other.raw() }),
        };
        let d = frame.data();
        need("EMCY", d, 8)?;
        Ok(Self {
            node,
            code: u16::from_le_bytes(bytes(d, 0)),
            register: d.get(2).copied().unwrap_or(0),
            vendor: bytes(d, 3),
        })
    }

    pub fn to_frame(&self) -> Result<CanFrame> {
        let c = self.code.to_le_bytes();
        let v = self.vendor;
        Ok(CanFrame::standard(
            EMCY_BASE + u16::from(self.node),
            &[c[0], c[1], self.register, v[0], v[1], v[2], v[3], v[4]],
        )?)
    }

    pub fn is_reset(&self) -> bool {
        self.code == 0
    }

    pub fn meaning(&self) -> &'static str {
        code_meaning(self.code)
    }
}

/// The CiA 301/402 meaning of an error code, most specific first.
pub fn code_meaning(code: u16) -> &'static str {
    match code {
        0x0000 => "error reset or no error",
        0x2310 => "continuous over-current",
        0x2320 => "short circuit at outputs",
        0x3210 => "DC link over-voltage",
        0x3220 => "DC link under-voltage",
        0x4210 => "excess temperature device",
        0x4310 => "excess temperature drive",
        0x5530 => "EEPROM error",
        0x7121 => "motor blocked",
        0x7305 => "incremental sensor 1 fault",
        0x8110 => "CAN overrun (objects lost)",
        0x8120 => "CAN in error passive mode",
        0x8130 => "life guard or heartbeat error",
        0x8140 => "recovered from bus off",
        0x8250 => "RPDO timeout",
        0x8400 => "velocity speed controller error",
        0x8611 => "following error",
        _ => match code & 0xFF00 {
            0x1000 => "generic error",
            0x2000..=0x2F00 => "current",
            0x3000..=0x3F00 => "voltage",
            0x4000..=0x4F00 => "temperature",
            0x5000 => "device hardware",
            0x6000..=0x6F00 => "device software",
            0x7000..=0x7F00 => "additional modules",
            0x8000..=0x8F00 => "monitoring",
            0x9000 => "external error",
            0xF000 => "additional functions",
            0xFF00 => "device specific",
            _ => "unknown",
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn emcy_round_trip_and_meaning() -> Result<()> {
        let f = CanFrame::standard(0x081, &[0x10, 0x23, 0x03, 1, 2, 3, 4, 5])?;
        let e = Emergency::parse(&f)?;
        assert_eq!((e.node, e.code, e.register, e.vendor), (1, 0x2310, 0x03, [1, 2, 3, 4, 5]));
        assert_eq!(e.meaning(), "continuous over-current");
        assert_eq!(e.to_frame()?, f);
        assert_eq!(code_meaning(0x2399), "current");
        assert!(Emergency::parse(&CanFrame::standard(0x080, &[0; 8])?).is_err(), "SYNC");
        assert!(Emergency::parse(&CanFrame::standard(0x081, &[0; 7])?).is_err());
        Ok(())
    }
}
