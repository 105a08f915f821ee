//! The process data this driver maps (and configures by SDO when asked to):
//! RPDO1 (0x200 + node) = controlword u16 + target velocity i32;
//! TPDO1 (0x180 + node) = statusword u16 + actual velocity i32. Little-endian.

use crate::error::{bytes, need, BaseError, Result};
use starc_can::{CanFrame, CanId};

pub const RPDO1_BASE: u16 = 0x200;
pub const TPDO1_BASE: u16 = 0x180;

/// Mapping entries (index << 16 | sub << 8 | bits) for the PDO mapping objects.
pub const RPDO1_MAPPING: [u32; 2] = [0x6040_0010, 0x60FF_0020];
pub const TPDO1_MAPPING: [u32; 2] = [0x6041_0010, 0x606C_0020];

/// RPDO1: what the host commands.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct VelocityCommand {
    pub controlword: u16,
    pub target_velocity: i32,
}

impl VelocityCommand {
    pub fn to_frame(&self, node: u8) -> Result<CanFrame> {
        let c = self.controlword.to_le_bytes();
        let v = self.target_velocity.to_le_bytes();
        Ok(CanFrame::standard(RPDO1_BASE + u16::from(node), &[c[0], c[1], v[0], v[1], v[2], v[3]])?)
    }

    pub fn parse(frame: &CanFrame) -> Result<(u8, Self)> {
        let node = node_of(frame, RPDO1_BASE, "RPDO1")?;
        let d = frame.data();
        need("RPDO1", d, 6)?;
        Ok((
            node,
            Self { controlword: u16::from_le_bytes(bytes(d, 0)), target_velocity: i32::from_le_bytes(bytes(d, 2)) },
        ))
    }
}

/// TPDO1: what the drive reports.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct VelocityStatus {
    pub statusword: u16,
    pub actual_velocity: i32,
}

impl VelocityStatus {
    pub fn to_frame(&self, node: u8) -> Result<CanFrame> {
        let s = self.statusword.to_le_bytes();
        let v = self.actual_velocity.to_le_bytes();
        Ok(CanFrame::standard(TPDO1_BASE + u16::from(node), &[s[0], s[1], v[0], v[1], v[2], v[3]])?)
    }

    pub fn parse(frame: &CanFrame) -> Result<(u8, Self)> {
        let node = node_of(frame, TPDO1_BASE, "TPDO1")?;
        let d = frame.data();
        need("TPDO1", d, 6)?;
        Ok((
            node,
            Self { statusword: u16::from_le_bytes(bytes(d, 0)), actual_velocity: i32::from_le_bytes(bytes(d, 2)) },
        ))
    }
}

fn node_of(frame: &CanFrame, base: u16, what: &'static str) -> Result<u8> {
    if frame.is_remote() {
        return Err(BaseError::malformed(what, "remote frame"));
    }
    match frame.id() {
        CanId::Standard(id) if id > base && id <= base + 0x7F => Ok((id - base) as u8),
        other => Err(BaseError::WrongId { what, id: other.raw() }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pdos_round_trip() -> Result<()> {
        let c = VelocityCommand { controlword: 0x0F, target_velocity: -300 };
        assert_eq!(c.to_frame(2)?.to_string(), "202#0F00D4FEFFFF");
        assert_eq!(VelocityCommand::parse(&c.to_frame(2)?)?, (2, c));
        let s = VelocityStatus { statusword: 0x0637, actual_velocity: 1234 };
        assert_eq!(VelocityStatus::parse(&s.to_frame(127)?)?, (127, s));
        assert!(VelocityStatus::parse(&CanFrame::standard(0x181, &[0; 5])?).is_err());
        assert!(VelocityStatus::parse(&CanFrame::standard(0x180, &[0; 6])?).is_err());
        Ok(())
    }
}
