//! CANopen network management: NMT commands on id 0 and heartbeats on 0x700 + node.

use crate::error::{need, BaseError, Result};
use starc_can::{CanFrame, CanId};

pub const NMT_ID: u16 = 0x000;
pub const HEARTBEAT_BASE: u16 = 0x700;
pub const SYNC_ID: u16 = 0x080;

/// NMT command specifiers.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NmtCommand {
    Start = 0x01,
    Stop = 0x02,
    EnterPreOperational = 0x80,
    ResetNode = 0x81,
    ResetCommunication = 0x82,
}

impl NmtCommand {
    pub fn from_byte(b: u8) -> Option<Self> {
        Some(match b {
            0x01 => Self::Start,
            0x02 => Self::Stop,
            0x80 => Self::EnterPreOperational,
            0x81 => Self::ResetNode,
            0x82 => Self::ResetCommunication,
            _ => return None,
        })
    }

    /// The frame `000#cs nn` (`node` 0 = every node).
    pub fn to_frame(self, node: u8) -> Result<CanFrame> {
        Ok(CanFrame::standard(NMT_ID, &[self as u8, node])?)
    }

    /// Parses an NMT frame into (command, target node).
    pub fn parse(frame: &CanFrame) -> Result<(Self, u8)> {
        if frame.id() != CanId::Standard(NMT_ID) {
            return Err(BaseError::WrongId { what: "NMT", id: frame.id().raw() });
        }
        let d = frame.data();
        need("NMT", d, 2)?;
        let cs = d.first().copied().unwrap_or(0);
        let command = Self::from_byte(cs).ok_or_else(|| BaseError::malformed("NMT", format!("command {cs:#04x}")))?;
        Ok((command, d.get(1).copied().unwrap_or(0)))
    }
}

/// The NMT state a heartbeat announces.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum NmtState {
    BootUp,
    Stopped,
    Operational,
    PreOperational,
}

impl NmtState {
    pub fn byte(self) -> u8 {
        match self {
            Self::BootUp => 0x00,
            Self::Stopped => 0x04,
            Self::Operational => 0x05,
            Self::PreOperational => 0x7F,
        }
    }

    pub fn from_byte(b: u8) -> Option<Self> {
        // Bit 7 is the toggle bit of node guarding; heartbeats send it as 0.
        Some(match b & 0x7F {
            0x00 => Self::BootUp,
            0x04 => Self::Stopped,
            0x05 => Self::Operational,
            0x7F => Self::PreOperational,
            _ => return None,
        })
    }
}

/// A heartbeat (or boot-up) message of `node`.
pub fn heartbeat_frame(node: u8, state: NmtState) -> Result<CanFrame> {
    Ok(CanFrame::standard(HEARTBEAT_BASE + u16::from(node), &[state.byte()])?)
}

/// Parses a heartbeat into (node, state).
pub fn parse_heartbeat(frame: &CanFrame) -> Result<(u8, NmtState)> {
    let node = match frame.id() {
        CanId::Standard(id @ 0x701..=0x77F) => (id - HEARTBEAT_BASE) as u8,
        other => return Err(BaseError::WrongId { what: "heartbeat", id: other.raw() }),
    };
    let d = frame.data();
    need("heartbeat", d, 1)?;
    let b = d.first().copied().unwrap_or(0);
    let state = NmtState::from_byte(b).ok_or_else(|| BaseError::malformed("heartbeat", format!("state {b:#04x}")))?;
    Ok((node, state))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nmt_and_heartbeats() -> Result<()> {
        assert_eq!(NmtCommand::Start.to_frame(5)?.to_string(), "000#0105");
        assert_eq!(NmtCommand::parse(&NmtCommand::ResetNode.to_frame(0)?)?, (NmtCommand::ResetNode, 0));
        assert!(NmtCommand::parse(&CanFrame::standard(0, &[0x03, 1])?).is_err());
        assert_eq!(heartbeat_frame(3, NmtState::PreOperational)?.to_string(), "703#7F");
        assert_eq!(parse_heartbeat(&CanFrame::standard(0x77F, &[0x05])?)?, (127, NmtState::Operational));
        assert!(parse_heartbeat(&CanFrame::standard(0x700, &[0x05])?).is_err());
        assert!(parse_heartbeat(&CanFrame::standard(0x701, &[0x06])?).is_err());
        assert!(parse_heartbeat(&CanFrame::standard(0x701, &[])?).is_err());
        Ok(())
    }
}
