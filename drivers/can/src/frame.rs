//! Classic CAN frames (no CAN FD): an 11- or 29-bit id, 0-8 data bytes or a remote request.

use crate::error::{CanError, Result};
use std::fmt;

/// Largest 11-bit (standard) id.
pub const MAX_STANDARD_ID: u16 = 0x7FF;
/// Largest 29-bit (extended) id.
pub const MAX_EXTENDED_ID: u32 = 0x1FFF_FFFF;

/// A CAN identifier; the constructors refuse ids that do not fit their width.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum CanId {
    Standard(u16),
    Extended(u32),
}

impl CanId {
    pub fn standard(id: u16) -> Result<Self> {
        if id > MAX_STANDARD_ID {
            return Err(CanError::IdOutOfRange { id: u32::from(id), bits: 11 });
        }
        Ok(Self::Standard(id))
    }

    pub fn extended(id: u32) -> Result<Self> {
        if id > MAX_EXTENDED_ID {
            return Err(CanError::IdOutOfRange { id, bits: 29 });
        }
        Ok(Self::Extended(id))
    }

    /// The numeric id, whatever its width.
    pub fn raw(self) -> u32 {
        match self {
            Self::Standard(id) => u32::from(id),
            Self::Extended(id) => id,
        }
    }

    pub fn is_extended(self) -> bool {
        matches!(self, Self::Extended(_))
    }
}

impl fmt::Display for CanId {
    /// candump style: three hex digits for standard ids, eight for extended ones.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Standard(id) => write!(f, "{id:03X}"),
            Self::Extended(id) => write!(f, "{id:08X}"),
        }
    }
}

/// One classic CAN frame. Fields are private so that every frame is valid by construction.
#[derive(Clone, Copy, PartialEq, Eq, Hash)]
pub struct CanFrame {
    id: CanId,
    len: u8,
    data: [u8; 8],
    remote: bool,
}

impl CanFrame {
    /// A data frame; at most 8 bytes.
    pub fn new(id: CanId, data: &[u8]) -> Result<Self> {
        let mut buf = [0u8; 8];
        let slot = buf.get_mut(..data.len()).ok_or(CanError::TooMuchData { len: data.len() })?;
        slot.copy_from_slice(data);
        Ok(Self { id, len: data.len() as u8, data: buf, remote: false })
    }

    /// A data frame with an 11-bit id, the common case for motor controllers.
    pub fn standard(id: u16, data: &[u8]) -> Result<Self> {
        Self::new(CanId::standard(id)?, data)
    }

    /// A remote transmission request asking for `dlc` bytes.
    pub fn remote(id: CanId, dlc: u8) -> Result<Self> {
        if dlc > 8 {
            return Err(CanError::BadDlc { dlc });
        }
        Ok(Self { id, len: dlc, data: [0; 8], remote: true })
    }

    pub fn id(&self) -> CanId {
        self.id
    }

    /// The data bytes (empty for a remote frame).
    pub fn data(&self) -> &[u8] {
        if self.remote {
            return &[];
        }
        self.data.get(..usize::from(self.len)).unwrap_or(&[])
    }

    /// Data length code: the number of data bytes, or the length a remote frame asks for.
    pub fn dlc(&self) -> u8 {
        self.len
    }

    pub fn is_remote(&self) -> bool {
        self.remote
    }
}

impl fmt::Debug for CanFrame {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        fmt::Display::fmt(self, f)
    }
}

impl fmt::Display for CanFrame {
    /// candump's compact form: `201#0102030405060708`, `601#R`, `12345678#00`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}#", self.id)?;
        if self.remote {
            return write!(f, "R{}", self.len);
        }
        for b in self.data() {
            write!(f, "{b:02X}")?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn constructors_refuse_what_does_not_fit() {
        assert!(CanId::standard(0x7FF).is_ok());
        assert!(CanId::standard(0x800).is_err());
        assert!(CanId::extended(0x1FFF_FFFF).is_ok());
        assert!(CanId::extended(0x2000_0000).is_err());
        assert!(CanFrame::standard(0x200, &[0; 9]).is_err());
        assert!(CanFrame::remote(CanId::Standard(1), 9).is_err());
    }

    #[test]
    fn data_and_display() -> Result<()> {
        let f = CanFrame::standard(0x201, &[1, 2, 0xAB])?;
        assert_eq!(f.data(), &[1, 2, 0xAB]);
        assert_eq!(f.dlc(), 3);
        assert_eq!(f.to_string(), "201#0102AB");
        let r = CanFrame::remote(CanId::extended(0x1234)?, 4)?;
        assert!(r.data().is_empty());
        assert_eq!(r.to_string(), "00001234#R4");
        Ok(())
    }
}
