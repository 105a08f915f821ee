//! CANopen network management: NMT commands on id 0 and heartbeats on 0x700 + node.

use crate::error::{need, BaseError, Result};
use starc_can::{CanFrame, CanId};
use starc_time::Stamp;

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

/// A consumer heartbeat time entry (0x1016 sub 1..): watch `node`'s heartbeat, `time_ms` at
/// most between two (bits 23-16 node id, bits 15-0 time; bits 31-24 reserved, 0).
pub fn consumer_heartbeat_entry(node: u8, time_ms: u16) -> u32 {
    u32::from(node) << 16 | u32::from(time_ms)
}

/// The (node, time in ms) of a consumer heartbeat entry; time 0 or node 0 means unused.
pub fn parse_consumer_heartbeat_entry(entry: u32) -> (u8, u16) {
    ((entry >> 16) as u8, entry as u16)
}

/// The host's own heartbeat (CiA 301 producer), which the drives' consumer heartbeat watches: if
/// it stops (the host process died, the adapter was unplugged), each drive takes its abort
/// connection option (0x6007) by itself, without anything from the host.
#[derive(Clone, Debug)]
pub struct HeartbeatProducer {
    node: u8,
    period_ns: i64,
    last_sent: Option<Stamp>,
    /// Heartbeats produced.
    pub sent: u64,
}

impl HeartbeatProducer {
    /// `node`: the host's node id (1-127); `period_ms`: the producer time.
    pub fn new(node: u8, period_ms: u16) -> Self {
        Self { node, period_ns: i64::from(period_ms) * 1_000_000, last_sent: None, sent: 0 }
    }

    pub fn node(&self) -> u8 {
        self.node
    }

    /// Appends the host's heartbeat (state operational) when one is due at `now`. Called once
    /// per control period, so the period is kept to within one control period.
    pub fn poll(&mut self, now: Stamp, out: &mut Vec<CanFrame>) {
        let due = match self.last_sent {
            None => true,
            // A clock that went back (or another clock) sends at once rather than never.
            Some(t) => now.since(t).is_none_or(|dt| dt < 0 || dt >= self.period_ns),
        };
        if !due {
            return;
        }
        match heartbeat_frame(self.node, NmtState::Operational) {
            Ok(f) => {
                out.push(f);
                self.last_sent = Some(now);
                self.sent += 1;
            }
            Err(e) => tracing::warn!(node = self.node, "cannot build the host heartbeat: {e}"),
        }
    }
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

    #[test]
    fn consumer_entries_put_the_node_above_the_time() {
        assert_eq!(consumer_heartbeat_entry(0x7F, 150), 0x007F_0096);
        assert_eq!(parse_consumer_heartbeat_entry(0x007F_0096), (0x7F, 150));
        assert_eq!(parse_consumer_heartbeat_entry(0xFF01_0002), (1, 2), "reserved bits ignored");
    }

    #[test]
    fn the_host_heartbeat_goes_out_every_period_and_not_more_often() {
        let at_ms = |ms: u64| Stamp::new(ms * 1_000_000, starc_time::Clock::Host);
        let mut p = HeartbeatProducer::new(127, 50);
        let mut out = Vec::new();
        // One poll per 10 ms control period for one second.
        let mut sent_at = Vec::new();
        for t in (0..1000).step_by(10) {
            let before = out.len();
            p.poll(at_ms(t), &mut out);
            if out.len() > before {
                sent_at.push(t);
            }
        }
        assert_eq!(sent_at, (0..1000).step_by(50).collect::<Vec<u64>>());
        assert_eq!(p.sent, 20);
        assert!(out.iter().all(|f| f.to_string() == "77F#05"), "{out:?}");
        // A late poll sends at once, and the next one a period after it.
        let mut out = Vec::new();
        p.poll(at_ms(1_173), &mut out);
        p.poll(at_ms(1_200), &mut out);
        p.poll(at_ms(1_223), &mut out);
        assert_eq!(out.len(), 2);
    }
}
