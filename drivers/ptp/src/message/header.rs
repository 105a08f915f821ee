//! The 34-byte common header every PTP message starts with.

use super::timestamp::Correction;
use crate::error::{PtpError, Result};
use std::fmt;

/// messageType, the low nibble of byte 0.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum MessageType {
    Sync,
    DelayReq,
    PDelayReq,
    PDelayResp,
    FollowUp,
    DelayResp,
    PDelayRespFollowUp,
    Announce,
    Signaling,
    Management,
}

impl MessageType {
    pub fn from_nibble(n: u8) -> Result<Self> {
        Ok(match n {
            0x0 => Self::Sync,
            0x1 => Self::DelayReq,
            0x2 => Self::PDelayReq,
            0x3 => Self::PDelayResp,
            0x8 => Self::FollowUp,
            0x9 => Self::DelayResp,
            0xA => Self::PDelayRespFollowUp,
            0xB => Self::Announce,
            0xC => Self::Signaling,
            0xD => Self::Management,
            other => return Err(PtpError::ReservedMessageType(other)),
        })
    }

    pub fn nibble(self) -> u8 {
        match self {
            Self::Sync => 0x0,
            Self::DelayReq => 0x1,
            Self::PDelayReq => 0x2,
            Self::PDelayResp => 0x3,
            Self::FollowUp => 0x8,
            Self::DelayResp => 0x9,
            Self::PDelayRespFollowUp => 0xA,
            Self::Announce => 0xB,
            Self::Signaling => 0xC,
            Self::Management => 0xD,
        }
    }

    /// Event messages are time-stamped on send and receive and travel on UDP port 319.
    pub fn is_event(self) -> bool {
        matches!(self, Self::Sync | Self::DelayReq | Self::PDelayReq | Self::PDelayResp)
    }

    /// The 1588-2008 controlField value for this type (kept for v1 hardware that reads it).
    pub fn control(self) -> u8 {
        match self {
            Self::Sync => 0,
            Self::DelayReq => 1,
            Self::FollowUp => 2,
            Self::DelayResp => 3,
            Self::Management => 4,
            _ => 5,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Self::Sync => "Sync",
            Self::DelayReq => "Delay_Req",
            Self::PDelayReq => "Pdelay_Req",
            Self::PDelayResp => "Pdelay_Resp",
            Self::FollowUp => "Follow_Up",
            Self::DelayResp => "Delay_Resp",
            Self::PDelayRespFollowUp => "Pdelay_Resp_Follow_Up",
            Self::Announce => "Announce",
            Self::Signaling => "Signaling",
            Self::Management => "Management",
        }
    }
}

/// The version byte: versionPTP (low nibble) must be 2; minorVersionPTP (high nibble) 0 or 1.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum PtpVersion {
    /// 0x02: IEEE 1588-2008. What Livox LiDARs expect; what we send.
    V2_0,
    /// 0x12: IEEE 1588-2019 senders (linuxptp 4.x by default).
    V2_1,
}

impl PtpVersion {
    pub fn from_byte(b: u8) -> Result<Self> {
        match b {
            0x02 => Ok(Self::V2_0),
            0x12 => Ok(Self::V2_1),
            other => Err(PtpError::UnsupportedVersion(other)),
        }
    }

    pub fn byte(self) -> u8 {
        match self {
            Self::V2_0 => 0x02,
            Self::V2_1 => 0x12,
        }
    }
}

/// flagField (bytes 6-7, as one big-endian u16).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct Flags(pub u16);

impl Flags {
    pub const ALTERNATE_MASTER: u16 = 1 << 8;
    pub const TWO_STEP: u16 = 1 << 9;
    pub const UNICAST: u16 = 1 << 10;
    pub const LEAP_61: u16 = 1 << 0;
    pub const LEAP_59: u16 = 1 << 1;
    pub const UTC_OFFSET_VALID: u16 = 1 << 2;
    pub const PTP_TIMESCALE: u16 = 1 << 3;
    pub const TIME_TRACEABLE: u16 = 1 << 4;
    pub const FREQUENCY_TRACEABLE: u16 = 1 << 5;

    pub fn has(self, bit: u16) -> bool {
        self.0 & bit != 0
    }
    pub fn with(self, bit: u16, on: bool) -> Self {
        if on {
            Self(self.0 | bit)
        } else {
            Self(self.0 & !bit)
        }
    }
    pub fn two_step(self) -> bool {
        self.has(Self::TWO_STEP)
    }
    pub fn ptp_timescale(self) -> bool {
        self.has(Self::PTP_TIMESCALE)
    }
    pub fn utc_offset_valid(self) -> bool {
        self.has(Self::UTC_OFFSET_VALID)
    }
}

/// An 8-byte clockIdentity (EUI-64, usually the MAC with ff:fe in the middle).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct ClockIdentity(pub [u8; 8]);

impl ClockIdentity {
    /// The EUI-64 of a MAC address, as ptp4l builds it.
    pub fn from_mac(mac: [u8; 6]) -> Self {
        let [a, b, c, d, e, f] = mac;
        Self([a, b, c, 0xff, 0xfe, d, e, f])
    }
}

impl fmt::Display for ClockIdentity {
    /// ptp4l's spelling: `aabbcc.fffe.ddeeff`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let [a, b, c, d, e, g, h, i] = self.0;
        write!(f, "{a:02x}{b:02x}{c:02x}.{d:02x}{e:02x}.{g:02x}{h:02x}{i:02x}")
    }
}

/// sourcePortIdentity / requestingPortIdentity: clock identity + port number.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct PortIdentity {
    pub clock: ClockIdentity,
    pub port: u16,
}

impl PortIdentity {
    pub const WIRE_LEN: usize = 10;

    pub fn parse(b: &[u8; 10]) -> Self {
        let [c0, c1, c2, c3, c4, c5, c6, c7, p0, p1] = *b;
        Self { clock: ClockIdentity([c0, c1, c2, c3, c4, c5, c6, c7]), port: u16::from_be_bytes([p0, p1]) }
    }

    pub fn encode(self) -> [u8; 10] {
        let [c0, c1, c2, c3, c4, c5, c6, c7] = self.clock.0;
        let [p0, p1] = self.port.to_be_bytes();
        [c0, c1, c2, c3, c4, c5, c6, c7, p0, p1]
    }
}

impl fmt::Display for PortIdentity {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}-{}", self.clock, self.port)
    }
}

/// The common header, without messageLength (the encoder writes the canonical length and the
/// parser checks the received one).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Header {
    /// transportSpecific / majorSdoId: the high nibble of byte 0.
    pub sdo_id_major: u8,
    pub message_type: MessageType,
    pub version: PtpVersion,
    pub domain: u8,
    /// Byte 5: reserved in 1588-2008, minorSdoId in 1588-2019.
    pub sdo_id_minor: u8,
    pub flags: Flags,
    pub correction: Correction,
    /// Bytes 16-19: reserved in 1588-2008, messageTypeSpecific in 1588-2019.
    pub type_specific: u32,
    pub source: PortIdentity,
    pub sequence_id: u16,
    pub control: u8,
    pub log_interval: i8,
}

impl Header {
    pub const WIRE_LEN: usize = 34;

    /// A 1588-2008 header with the controlField that goes with `message_type`.
    pub fn new(message_type: MessageType, domain: u8, source: PortIdentity, sequence_id: u16) -> Self {
        Self {
            sdo_id_major: 0,
            message_type,
            version: PtpVersion::V2_0,
            domain,
            sdo_id_minor: 0,
            flags: Flags::default(),
            correction: Correction::default(),
            type_specific: 0,
            source,
            sequence_id,
            control: message_type.control(),
            log_interval: 0x7f,
        }
    }

    /// Parses the header and returns it with the declared messageLength.
    pub fn parse(bytes: &[u8]) -> Result<(Self, usize)> {
        let b: &[u8; 34] = bytes.get(..Self::WIRE_LEN).and_then(|s| s.try_into().ok()).ok_or(PtpError::TooShort {
            what: "PTP header",
            need: Self::WIRE_LEN,
            have: bytes.len(),
        })?;
        let version = PtpVersion::from_byte(b[1])?;
        let message_type = MessageType::from_nibble(b[0] & 0x0f)?;
        let length = u16::from_be_bytes([b[2], b[3]]) as usize;
        let mut correction = [0u8; 8];
        correction.copy_from_slice(&b[8..16]);
        let mut source = [0u8; 10];
        source.copy_from_slice(&b[20..30]);
        let header = Self {
            sdo_id_major: b[0] >> 4,
            message_type,
            version,
            domain: b[4],
            sdo_id_minor: b[5],
            flags: Flags(u16::from_be_bytes([b[6], b[7]])),
            correction: Correction(i64::from_be_bytes(correction)),
            type_specific: u32::from_be_bytes([b[16], b[17], b[18], b[19]]),
            source: PortIdentity::parse(&source),
            sequence_id: u16::from_be_bytes([b[30], b[31]]),
            control: b[32],
            log_interval: b[33] as i8,
        };
        Ok((header, length))
    }

    /// Writes the header with `length` as messageLength.
    pub fn encode(&self, length: u16) -> [u8; 34] {
        let mut b = [0u8; 34];
        b[0] = ((self.sdo_id_major & 0x0f) << 4) | self.message_type.nibble();
        b[1] = self.version.byte();
        b[2..4].copy_from_slice(&length.to_be_bytes());
        b[4] = self.domain;
        b[5] = self.sdo_id_minor;
        b[6..8].copy_from_slice(&self.flags.0.to_be_bytes());
        b[8..16].copy_from_slice(&self.correction.0.to_be_bytes());
        b[16..20].copy_from_slice(&self.type_specific.to_be_bytes());
        b[20..30].copy_from_slice(&self.source.encode());
        b[30..32].copy_from_slice(&self.sequence_id.to_be_bytes());
        b[32] = self.control;
        b[33] = self.log_interval as u8;
        b
    }
}
