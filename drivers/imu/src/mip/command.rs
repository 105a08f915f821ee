//! MIP commands (base set 0x01, 3DM set 0x0C) and their replies: an ACK/NACK field 0xF1
//! `[echoed command descriptor, error code]`, then any reply data fields.

use crate::error::{ImuError, Result};
use crate::mip::packet::{be_u16, be_u32, Field, Packet, PacketWriter};

pub const BASE_SET: u8 = 0x01;
pub const DM3_SET: u8 = 0x0C;

pub const CMD_PING: u8 = 0x01;
pub const CMD_SET_IDLE: u8 = 0x02;
pub const CMD_RESUME: u8 = 0x06;
pub const CMD_IMU_BASE_RATE: u8 = 0x06;
pub const CMD_IMU_MESSAGE_FORMAT: u8 = 0x08;
pub const CMD_UART_BAUD_RATE: u8 = 0x40;

pub const FIELD_ACK: u8 = 0xF1;
pub const REPLY_IMU_MESSAGE_FORMAT: u8 = 0x80;
pub const REPLY_IMU_BASE_RATE: u8 = 0x83;
pub const REPLY_UART_BAUD_RATE: u8 = 0x86;

/// Error codes of the ACK field (0 is an ACK, anything else a NACK).
pub const ACK_OK: u8 = 0x00;
pub const NACK_UNKNOWN_COMMAND: u8 = 0x01;
pub const NACK_BAD_CHECKSUM: u8 = 0x02;
pub const NACK_BAD_PARAMETER: u8 = 0x03;
pub const NACK_FAILED: u8 = 0x04;
pub const NACK_TIMEOUT: u8 = 0x05;

/// The name of an ACK field's error code.
pub fn ack_code_name(code: u8) -> &'static str {
    match code {
        ACK_OK => "ok",
        NACK_UNKNOWN_COMMAND => "unknown command",
        NACK_BAD_CHECKSUM => "invalid checksum",
        NACK_BAD_PARAMETER => "invalid parameter",
        NACK_FAILED => "command failed",
        NACK_TIMEOUT => "command timed out",
        _ => "unknown error code",
    }
}

/// The most (descriptor, decimation) entries a message format command can carry.
pub const MAX_FORMAT_ENTRIES: usize = (255 - 2 - 2) / 3;

/// The function selector of a settings command: apply a value, or act on the stored one.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Function<T> {
    /// 1: use this value now.
    Apply(T),
    /// 2: read the current value.
    Read,
    /// 3: save the current value as the startup value.
    Save,
    /// 4: load the startup value.
    Load,
    /// 5: reset to the factory default.
    Default,
}

impl<T> Function<T> {
    pub fn selector(&self) -> u8 {
        match self {
            Function::Apply(_) => 1,
            Function::Read => 2,
            Function::Save => 3,
            Function::Load => 4,
            Function::Default => 5,
        }
    }
}

/// One entry of the IMU message format: a 0x80 field and its decimation of the base rate.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FormatEntry {
    pub descriptor: u8,
    pub decimation: u16,
}

/// A command a host sends.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum MipCommand {
    Ping,
    /// Stop streaming and wait for commands.
    SetIdle,
    /// Back to the mode before idle (streaming).
    Resume,
    /// Ask the IMU base rate (Hz); decimations divide it.
    GetImuBaseRate,
    /// Which 0x80 fields stream, at base rate / decimation (all entries of one packet must share
    /// one decimation for them to arrive together).
    ImuMessageFormat(Function<Vec<FormatEntry>>),
    /// The UART baud rate; the device answers at the old rate, then switches.
    UartBaudRate(Function<u32>),
}

impl MipCommand {
    pub fn descriptor_set(&self) -> u8 {
        match self {
            MipCommand::Ping | MipCommand::SetIdle | MipCommand::Resume => BASE_SET,
            _ => DM3_SET,
        }
    }

    pub fn descriptor(&self) -> u8 {
        match self {
            MipCommand::Ping => CMD_PING,
            MipCommand::SetIdle => CMD_SET_IDLE,
            MipCommand::Resume => CMD_RESUME,
            MipCommand::GetImuBaseRate => CMD_IMU_BASE_RATE,
            MipCommand::ImuMessageFormat(_) => CMD_IMU_MESSAGE_FORMAT,
            MipCommand::UartBaudRate(_) => CMD_UART_BAUD_RATE,
        }
    }

    /// A short name for logs and errors.
    pub fn name(&self) -> &'static str {
        match self {
            MipCommand::Ping => "ping",
            MipCommand::SetIdle => "set idle",
            MipCommand::Resume => "resume",
            MipCommand::GetImuBaseRate => "get IMU base rate",
            MipCommand::ImuMessageFormat(_) => "IMU message format",
            MipCommand::UartBaudRate(_) => "UART baud rate",
        }
    }

    /// The command packet appended to `out`.
    pub fn encode(&self, out: &mut Vec<u8>) -> Result<()> {
        let mut data = Vec::with_capacity(8);
        match self {
            MipCommand::ImuMessageFormat(f) => {
                data.push(f.selector());
                if let Function::Apply(entries) = f {
                    if entries.len() > MAX_FORMAT_ENTRIES {
                        return Err(ImuError::PayloadTooLong { len: 4 + 3 * entries.len() });
                    }
                    data.push(entries.len() as u8);
                    for e in entries {
                        data.push(e.descriptor);
                        data.extend_from_slice(&e.decimation.to_be_bytes());
                    }
                }
            }
            MipCommand::UartBaudRate(f) => {
                data.push(f.selector());
                if let Function::Apply(baud) = f {
                    data.extend_from_slice(&baud.to_be_bytes());
                }
            }
            _ => {}
        }
        let mut w = PacketWriter::new(self.descriptor_set());
        w.field(self.descriptor(), &data)?;
        w.finish(out);
        Ok(())
    }

    pub fn to_bytes(&self) -> Result<Vec<u8>> {
        let mut out = Vec::with_capacity(16);
        self.encode(&mut out)?;
        Ok(out)
    }

    /// The command in a packet (its first field); what a device does.
    pub fn decode(packet: &Packet<'_>) -> Result<Self> {
        let set = packet.descriptor_set;
        let field = packet.fields().next().ok_or(ImuError::NoCommand { set })??;
        Self::from_field(set, &field)
    }

    fn from_field(set: u8, field: &Field<'_>) -> Result<Self> {
        let (d, data) = (field.descriptor, field.data);
        let bad_len = |expected| ImuError::FieldLength { set, descriptor: d, len: data.len(), expected };
        let no_data = |cmd: MipCommand| if data.is_empty() { Ok(cmd) } else { Err(bad_len("0")) };
        match (set, d) {
            (BASE_SET, CMD_PING) => no_data(MipCommand::Ping),
            (BASE_SET, CMD_SET_IDLE) => no_data(MipCommand::SetIdle),
            (BASE_SET, CMD_RESUME) => no_data(MipCommand::Resume),
            (DM3_SET, CMD_IMU_BASE_RATE) => no_data(MipCommand::GetImuBaseRate),
            (DM3_SET, CMD_IMU_MESSAGE_FORMAT) => {
                let f = function(set, d, data, |rest| {
                    let (&count, entries) = rest.split_first().ok_or(bad_len("2 + 3 per entry"))?;
                    if entries.len() != 3 * usize::from(count) {
                        return Err(bad_len("2 + 3 per entry"));
                    }
                    Ok(entries
                        .chunks_exact(3)
                        .map(|c| FormatEntry { descriptor: c.first().copied().unwrap_or(0), decimation: be_u16(c, 1) })
                        .collect())
                })?;
                Ok(MipCommand::ImuMessageFormat(f))
            }
            (DM3_SET, CMD_UART_BAUD_RATE) => {
                let f = function(set, d, data, |rest| {
                    if rest.len() != 4 {
                        return Err(bad_len("5"));
                    }
                    Ok(be_u32(rest, 0))
                })?;
                Ok(MipCommand::UartBaudRate(f))
            }
            _ => Err(ImuError::UnknownCommand { set, descriptor: d }),
        }
    }
}

fn function<T>(set: u8, descriptor: u8, data: &[u8], apply: impl FnOnce(&[u8]) -> Result<T>) -> Result<Function<T>> {
    let (&selector, rest) =
        data.split_first().ok_or(ImuError::FieldLength { set, descriptor, len: 0, expected: "at least 1" })?;
    let only_selector = |f: Function<T>| {
        if rest.is_empty() {
            Ok(f)
        } else {
            Err(ImuError::FieldLength { set, descriptor, len: data.len(), expected: "1" })
        }
    };
    match selector {
        1 => Ok(Function::Apply(apply(rest)?)),
        2 => only_selector(Function::Read),
        3 => only_selector(Function::Save),
        4 => only_selector(Function::Load),
        5 => only_selector(Function::Default),
        other => Err(ImuError::BadValue { field: "MIP function selector", value: u64::from(other) }),
    }
}

/// Data that comes with an ACK.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum ReplyData {
    ImuBaseRate(u16),
    ImuMessageFormat(Vec<FormatEntry>),
    UartBaudRate(u32),
}

impl ReplyData {
    fn descriptor(&self) -> u8 {
        match self {
            ReplyData::ImuBaseRate(_) => REPLY_IMU_BASE_RATE,
            ReplyData::ImuMessageFormat(_) => REPLY_IMU_MESSAGE_FORMAT,
            ReplyData::UartBaudRate(_) => REPLY_UART_BAUD_RATE,
        }
    }

    fn encode(&self) -> Vec<u8> {
        match self {
            ReplyData::ImuBaseRate(r) => r.to_be_bytes().to_vec(),
            ReplyData::UartBaudRate(b) => b.to_be_bytes().to_vec(),
            ReplyData::ImuMessageFormat(entries) => {
                let n = entries.len().min(MAX_FORMAT_ENTRIES);
                let mut v = Vec::with_capacity(1 + 3 * n);
                v.push(n as u8);
                for e in entries.iter().take(n) {
                    v.push(e.descriptor);
                    v.extend_from_slice(&e.decimation.to_be_bytes());
                }
                v
            }
        }
    }

    fn decode(set: u8, field: &Field<'_>) -> Result<Option<Self>> {
        let (d, data) = (field.descriptor, field.data);
        let bad_len = |expected| ImuError::FieldLength { set, descriptor: d, len: data.len(), expected };
        Ok(Some(match (set, d) {
            (DM3_SET, REPLY_IMU_BASE_RATE) if data.len() == 2 => ReplyData::ImuBaseRate(be_u16(data, 0)),
            (DM3_SET, REPLY_IMU_BASE_RATE) => return Err(bad_len("2")),
            (DM3_SET, REPLY_UART_BAUD_RATE) if data.len() == 4 => ReplyData::UartBaudRate(be_u32(data, 0)),
            (DM3_SET, REPLY_UART_BAUD_RATE) => return Err(bad_len("4")),
            (DM3_SET, REPLY_IMU_MESSAGE_FORMAT) => {
                let (&count, entries) = data.split_first().ok_or(bad_len("1 + 3 per entry"))?;
                if entries.len() != 3 * usize::from(count) {
                    return Err(bad_len("1 + 3 per entry"));
                }
                ReplyData::ImuMessageFormat(
                    entries
                        .chunks_exact(3)
                        .map(|c| FormatEntry { descriptor: c.first().copied().unwrap_or(0), decimation: be_u16(c, 1) })
                        .collect(),
                )
            }
            _ => return Ok(None),
        }))
    }
}

/// A device's answer to one command.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct MipReply {
    pub descriptor_set: u8,
    /// The command's field descriptor, echoed.
    pub command: u8,
    /// [`ACK_OK`] or a NACK code.
    pub code: u8,
    pub data: Option<ReplyData>,
}

impl MipReply {
    pub fn ack(descriptor_set: u8, command: u8, data: Option<ReplyData>) -> Self {
        Self { descriptor_set, command, code: ACK_OK, data }
    }

    pub fn nack(descriptor_set: u8, command: u8, code: u8) -> Self {
        Self { descriptor_set, command, code, data: None }
    }

    pub fn is_ack(&self) -> bool {
        self.code == ACK_OK
    }

    /// `Ok(self)` for an ACK, [`ImuError::Nack`] for a NACK.
    pub fn into_result(self) -> Result<Self> {
        if self.is_ack() {
            Ok(self)
        } else {
            Err(ImuError::Nack {
                set: self.descriptor_set,
                command: self.command,
                code: self.code,
                name: ack_code_name(self.code),
            })
        }
    }

    /// Whether this answers `command`.
    pub fn answers(&self, command: &MipCommand) -> bool {
        self.descriptor_set == command.descriptor_set() && self.command == command.descriptor()
    }

    /// The reply packet appended to `out`.
    pub fn encode(&self, out: &mut Vec<u8>) -> Result<()> {
        let mut w = PacketWriter::new(self.descriptor_set);
        w.field(FIELD_ACK, &[self.command, self.code])?;
        if let Some(d) = &self.data {
            w.field(d.descriptor(), &d.encode())?;
        }
        w.finish(out);
        Ok(())
    }

    /// Every reply in a packet of set 0x01 or 0x0C (one per ACK field, with the data fields
    /// after it), appended to `out`.
    pub fn decode_all(packet: &Packet<'_>, out: &mut Vec<MipReply>) -> Result<()> {
        let set = packet.descriptor_set;
        let start = out.len();
        for field in packet.fields() {
            let f = field?;
            if f.descriptor == FIELD_ACK {
                let [command, code] = <[u8; 2]>::try_from(f.data).map_err(|_| ImuError::FieldLength {
                    set,
                    descriptor: FIELD_ACK,
                    len: f.data.len(),
                    expected: "2",
                })?;
                out.push(MipReply { descriptor_set: set, command, code, data: None });
            } else if let Some(data) = ReplyData::decode(set, &f)? {
                // Data belongs to the ACK before it.
                if let Some(last) = out.get_mut(start..).and_then(|s| s.last_mut()) {
                    last.data = Some(data);
                }
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn all_commands() -> Vec<MipCommand> {
        let entries =
            vec![FormatEntry { descriptor: 0x04, decimation: 5 }, FormatEntry { descriptor: 0x05, decimation: 5 }];
        let mut v = vec![MipCommand::Ping, MipCommand::SetIdle, MipCommand::Resume, MipCommand::GetImuBaseRate];
        for f in [Function::Apply(entries), Function::Read, Function::Save, Function::Load, Function::Default] {
            v.push(MipCommand::ImuMessageFormat(f));
        }
        for f in [Function::Apply(921_600), Function::Read, Function::Save, Function::Load, Function::Default] {
            v.push(MipCommand::UartBaudRate(f));
        }
        v
    }

    #[test]
    fn every_command_round_trips() {
        for c in all_commands() {
            let bytes = c.to_bytes().unwrap_or_else(|e| panic!("{e}"));
            let (p, n) = Packet::parse(&bytes).unwrap_or_else(|e| panic!("{c:?}: {e}"));
            assert_eq!(n, bytes.len());
            assert_eq!(MipCommand::decode(&p).unwrap_or_else(|e| panic!("{c:?}: {e}")), c);
        }
    }

    #[test]
    fn known_command_bytes() {
        assert_eq!(
            MipCommand::SetIdle.to_bytes().unwrap_or_default(),
            [0x75, 0x65, 0x01, 0x02, 0x02, 0x02, 0xE1, 0xC7]
        );
        // Set baud 115200: 0x0C, field [07 40 01 00 01 C2 00].
        let b = MipCommand::UartBaudRate(Function::Apply(115_200)).to_bytes().unwrap_or_default();
        assert_eq!(&b[..11], &[0x75, 0x65, 0x0C, 0x07, 0x07, 0x40, 0x01, 0x00, 0x01, 0xC2, 0x00]);
    }

    #[test]
    fn bad_commands_are_errors() {
        let packet = |set: u8, desc: u8, data: &[u8]| {
            let mut w = PacketWriter::new(set);
            w.field(desc, data).map(|_| ()).unwrap_or_else(|e| panic!("{e}"));
            w.to_bytes()
        };
        let decode = |b: &[u8]| Packet::parse(b).and_then(|(p, _)| MipCommand::decode(&p));
        assert!(matches!(decode(&packet(0x01, 0x03, &[])), Err(ImuError::UnknownCommand { set: 1, descriptor: 3 })));
        assert!(matches!(decode(&packet(0x01, 0x01, &[0])), Err(ImuError::FieldLength { .. })));
        assert!(matches!(decode(&packet(0x0C, 0x40, &[])), Err(ImuError::FieldLength { .. })));
        assert!(matches!(decode(&packet(0x0C, 0x40, &[1, 0, 0])), Err(ImuError::FieldLength { .. })));
        assert!(matches!(decode(&packet(0x0C, 0x40, &[2, 0])), Err(ImuError::FieldLength { .. })));
        assert!(matches!(decode(&packet(0x0C, 0x40, &[9])), Err(ImuError::BadValue { value: 9, .. })));
        assert!(matches!(decode(&packet(0x0C, 0x08, &[1, 2, 4, 0, 1])), Err(ImuError::FieldLength { .. })));
        assert!(matches!(decode(&packet(0x0C, 0x08, &[1])), Err(ImuError::FieldLength { .. })));
        let empty = PacketWriter::new(0x01).to_bytes();
        assert!(matches!(decode(&empty), Err(ImuError::NoCommand { set: 1 })));
        let too_many = MipCommand::ImuMessageFormat(Function::Apply(vec![
            FormatEntry { descriptor: 4, decimation: 1 };
            MAX_FORMAT_ENTRIES + 1
        ]));
        assert!(too_many.to_bytes().is_err());
        let most = MipCommand::ImuMessageFormat(Function::Apply(vec![
            FormatEntry { descriptor: 4, decimation: 1 };
            MAX_FORMAT_ENTRIES
        ]));
        assert!(most.to_bytes().is_ok());
    }

    #[test]
    fn replies_round_trip_and_nacks_are_errors() {
        let replies = [
            MipReply::ack(BASE_SET, CMD_PING, None),
            MipReply::nack(BASE_SET, 0x03, NACK_UNKNOWN_COMMAND),
            MipReply::ack(DM3_SET, CMD_IMU_BASE_RATE, Some(ReplyData::ImuBaseRate(1000))),
            MipReply::ack(DM3_SET, CMD_UART_BAUD_RATE, Some(ReplyData::UartBaudRate(921_600))),
            MipReply::ack(
                DM3_SET,
                CMD_IMU_MESSAGE_FORMAT,
                Some(ReplyData::ImuMessageFormat(vec![FormatEntry { descriptor: 4, decimation: 10 }])),
            ),
        ];
        for r in replies {
            let mut b = Vec::new();
            r.encode(&mut b).unwrap_or_else(|e| panic!("{e}"));
            let (p, _) = Packet::parse(&b).unwrap_or_else(|e| panic!("{e}"));
            let mut out = Vec::new();
            MipReply::decode_all(&p, &mut out).unwrap_or_else(|e| panic!("{e}"));
            assert_eq!(out, vec![r.clone()]);
            assert_eq!(r.clone().into_result().is_ok(), r.code == ACK_OK);
        }
        let ping_ack = [0x75, 0x65, 0x01, 0x04, 0x04, 0xF1, 0x01, 0x00, 0xD5, 0x6A];
        let (p, _) = Packet::parse(&ping_ack).unwrap_or_else(|e| panic!("{e}"));
        let mut out = Vec::new();
        MipReply::decode_all(&p, &mut out).unwrap_or_else(|e| panic!("{e}"));
        assert!(out.first().is_some_and(|r| r.answers(&MipCommand::Ping) && r.is_ack()));
        let nack = MipReply::nack(DM3_SET, CMD_UART_BAUD_RATE, NACK_BAD_PARAMETER).into_result();
        assert!(matches!(nack, Err(ImuError::Nack { code: 3, name: "invalid parameter", .. })));

        let mut w = PacketWriter::new(BASE_SET);
        w.field(FIELD_ACK, &[1]).map(|_| ()).unwrap_or_else(|e| panic!("{e}"));
        let b = w.to_bytes();
        let (p, _) = Packet::parse(&b).unwrap_or_else(|e| panic!("{e}"));
        assert!(MipReply::decode_all(&p, &mut out).is_err());
    }
}
