//! IEEE 1588-2008 (v2) messages over UDP/IPv4: parse untrusted bytes into typed messages and
//! encode them back. Sync, Delay_Req, Follow_Up, Delay_Resp and Announce are decoded in full;
//! the other types (peer delay, signaling, management) are recognised and their bodies skipped.
//!
//! Suffix TLVs inside messageLength are ignored; bytes after messageLength (UDP padding) too.

mod header;
mod timestamp;

pub use header::{ClockIdentity, Flags, Header, MessageType, PortIdentity, PtpVersion};
pub use timestamp::{Correction, PtpTimestamp};

use crate::error::{PtpError, Result};

/// UDP port of event messages (time-stamped: Sync, Delay_Req).
pub const EVENT_PORT: u16 = 319;
/// UDP port of general messages (Follow_Up, Delay_Resp, Announce).
pub const GENERAL_PORT: u16 = 320;
/// The IPv4 multicast group of all PTP messages but peer delay.
pub const PTP_PRIMARY_MULTICAST: std::net::Ipv4Addr = std::net::Ipv4Addr::new(224, 0, 1, 129);

/// Wire length of the messages we decode in full.
pub const SYNC_LEN: usize = 44;
pub const DELAY_RESP_LEN: usize = 54;
pub const ANNOUNCE_LEN: usize = 64;

/// The grandmaster's quality as an Announce carries it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct ClockQuality {
    pub clock_class: u8,
    pub clock_accuracy: u8,
    pub offset_scaled_log_variance: u16,
}

/// timeSource values of 1588-2008 table 7 that a robot meets.
pub mod time_source {
    pub const ATOMIC_CLOCK: u8 = 0x10;
    pub const GPS: u8 = 0x20;
    pub const PTP: u8 = 0x40;
    pub const NTP: u8 = 0x50;
    pub const HAND_SET: u8 = 0x60;
    pub const OTHER: u8 = 0x90;
    pub const INTERNAL_OSCILLATOR: u8 = 0xA0;
}

/// The body of an Announce message.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Announce {
    pub origin: PtpTimestamp,
    /// TAI - UTC in seconds (37 since 2017).
    pub current_utc_offset: i16,
    /// Byte 44, reserved.
    pub reserved: u8,
    pub gm_priority1: u8,
    pub gm_quality: ClockQuality,
    pub gm_priority2: u8,
    pub gm_identity: ClockIdentity,
    pub steps_removed: u16,
    pub time_source: u8,
}

/// What follows the header.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Body {
    Sync {
        origin: PtpTimestamp,
    },
    DelayReq {
        origin: PtpTimestamp,
    },
    FollowUp {
        precise_origin: PtpTimestamp,
    },
    DelayResp {
        receive: PtpTimestamp,
        requesting: PortIdentity,
    },
    Announce(Announce),
    /// Peer delay, signaling or management: recognised, not decoded.
    Other,
}

/// One PTP message.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Message {
    pub header: Header,
    pub body: Body,
}

fn ts_at(b: &[u8], at: usize) -> PtpTimestamp {
    let mut t = [0u8; 10];
    if let Some(s) = b.get(at..at + 10) {
        t.copy_from_slice(s);
    }
    PtpTimestamp::parse(&t)
}

fn byte_at(b: &[u8], at: usize) -> u8 {
    b.get(at).copied().unwrap_or(0)
}

fn u16_at(b: &[u8], at: usize) -> u16 {
    u16::from_be_bytes([byte_at(b, at), byte_at(b, at + 1)])
}

impl Message {
    /// Parses one datagram. Never panics; every length is checked against both messageLength
    /// and the datagram before use.
    pub fn parse(bytes: &[u8]) -> Result<Self> {
        let (header, declared) = Header::parse(bytes)?;
        if declared > bytes.len() {
            return Err(PtpError::LengthExceedsDatagram { declared, actual: bytes.len() });
        }
        let need = match header.message_type {
            MessageType::Sync | MessageType::DelayReq | MessageType::FollowUp => SYNC_LEN,
            MessageType::DelayResp => DELAY_RESP_LEN,
            MessageType::Announce => ANNOUNCE_LEN,
            _ => Header::WIRE_LEN,
        };
        if declared < need {
            return Err(PtpError::LengthTooSmall { message: header.message_type.name(), declared, need });
        }
        // From here on the message is at least `need` bytes long.
        let b = bytes.get(..declared).unwrap_or_default();
        let body = match header.message_type {
            MessageType::Sync => Body::Sync { origin: ts_at(b, 34) },
            MessageType::DelayReq => Body::DelayReq { origin: ts_at(b, 34) },
            MessageType::FollowUp => Body::FollowUp { precise_origin: ts_at(b, 34) },
            MessageType::DelayResp => {
                let mut p = [0u8; 10];
                if let Some(s) = b.get(44..54) {
                    p.copy_from_slice(s);
                }
                Body::DelayResp { receive: ts_at(b, 34), requesting: PortIdentity::parse(&p) }
            }
            MessageType::Announce => {
                let mut gm = [0u8; 8];
                if let Some(s) = b.get(53..61) {
                    gm.copy_from_slice(s);
                }
                Body::Announce(Announce {
                    origin: ts_at(b, 34),
                    current_utc_offset: u16_at(b, 44) as i16,
                    reserved: byte_at(b, 46),
                    gm_priority1: byte_at(b, 47),
                    gm_quality: ClockQuality {
                        clock_class: byte_at(b, 48),
                        clock_accuracy: byte_at(b, 49),
                        offset_scaled_log_variance: u16_at(b, 50),
                    },
                    gm_priority2: byte_at(b, 52),
                    gm_identity: ClockIdentity(gm),
                    steps_removed: u16_at(b, 61),
                    time_source: byte_at(b, 63),
                })
            }
            _ => Body::Other,
        };
        Ok(Self { header, body })
    }

    /// The canonical wire length of this message.
    pub fn wire_len(&self) -> Result<usize> {
        Ok(match self.body {
            Body::Sync { .. } | Body::DelayReq { .. } | Body::FollowUp { .. } => SYNC_LEN,
            Body::DelayResp { .. } => DELAY_RESP_LEN,
            Body::Announce(_) => ANNOUNCE_LEN,
            Body::Other => return Err(PtpError::NotEncodable(self.header.message_type.name())),
        })
    }

    /// Writes the message into `out` and returns its length.
    pub fn encode_into(&self, out: &mut [u8]) -> Result<usize> {
        let len = self.wire_len()?;
        let have = out.len();
        let dst = out.get_mut(..len).ok_or(PtpError::BufferTooSmall { need: len, have })?;
        dst.fill(0);
        dst[..34].copy_from_slice(&self.header.encode(len as u16));
        match self.body {
            Body::Sync { origin } | Body::DelayReq { origin } | Body::FollowUp { precise_origin: origin } => {
                dst[34..44].copy_from_slice(&origin.encode());
            }
            Body::DelayResp { receive, requesting } => {
                dst[34..44].copy_from_slice(&receive.encode());
                dst[44..54].copy_from_slice(&requesting.encode());
            }
            Body::Announce(a) => {
                dst[34..44].copy_from_slice(&a.origin.encode());
                dst[44..46].copy_from_slice(&a.current_utc_offset.to_be_bytes());
                dst[46] = a.reserved;
                dst[47] = a.gm_priority1;
                dst[48] = a.gm_quality.clock_class;
                dst[49] = a.gm_quality.clock_accuracy;
                dst[50..52].copy_from_slice(&a.gm_quality.offset_scaled_log_variance.to_be_bytes());
                dst[52] = a.gm_priority2;
                dst[53..61].copy_from_slice(&a.gm_identity.0);
                dst[61..63].copy_from_slice(&a.steps_removed.to_be_bytes());
                dst[63] = a.time_source;
            }
            Body::Other => return Err(PtpError::NotEncodable(self.header.message_type.name())),
        }
        Ok(len)
    }

    pub fn encode(&self) -> Result<Vec<u8>> {
        let mut out = vec![0u8; self.wire_len()?];
        self.encode_into(&mut out)?;
        Ok(out)
    }
}

#[cfg(test)]
mod tests;
