use thiserror::Error;

/// Everything that can go wrong in the Livox driver crate.
#[derive(Debug, Error)]
pub enum LivoxError {
    #[error("{what}: need {need} bytes, have {have}")]
    TooShort { what: &'static str, need: usize, have: usize },
    #[error("control frame: start byte is {0:#04x}, expected 0xaa")]
    BadStartOfFrame(u8),
    #[error("control frame: protocol version {0}, expected 1")]
    BadControlVersion(u8),
    #[error("control frame: length field says {declared} bytes, datagram has {actual}")]
    LengthMismatch { declared: usize, actual: usize },
    #[error("control frame: header CRC16 stored {stored:#06x}, computed {computed:#06x}")]
    BadHeaderCrc { stored: u16, computed: u16 },
    #[error("control frame: CRC32 stored {stored:#010x}, computed {computed:#010x}")]
    BadFrameCrc { stored: u32, computed: u32 },
    #[error("control frame: unknown cmd_type {0}")]
    BadCmdType(u8),
    #[error("control frame: command ({set},{id}) payload of {len} bytes is malformed")]
    BadPayload { set: u8, id: u8, len: usize },
    #[error("control frame: unknown command ({set},{id})")]
    UnknownCommand { set: u8, id: u8 },
    #[error("control frame: invalid value {value} for {field}")]
    BadValue { field: &'static str, value: u32 },
    #[error("data packet: version {0}, expected 5")]
    BadDataVersion(u8),
    #[error("data packet: unknown data_type {0}")]
    BadDataType(u8),
    #[error("data packet: unknown timestamp_type {0}")]
    BadTimestampType(u8),
    #[error("data packet: GPS/UTC time stamp is not a valid date ({0})")]
    BadUtcTime(&'static str),
    #[error("data packet: data_type {data_type} needs {need} bytes, datagram has {have}")]
    PacketLength { data_type: u8, need: usize, have: usize },
    #[error("capture: {0}")]
    Capture(String),
    #[error("capture: unsupported link type {0}")]
    UnsupportedLinkType(u32),
    #[error("lvx: {0}")]
    Lvx(String),
    #[error("capture: first bytes {0:02x?} are not pcap, pcapng or .lvx")]
    UnknownCaptureFormat(Vec<u8>),
    #[error("{format}: file ends inside a record at byte {offset}: need {need} bytes, have {have}")]
    CaptureTruncated { format: &'static str, offset: u64, need: usize, have: usize },
    #[error("{format}: record at byte {offset} claims {len} bytes, more than the {max}-byte limit")]
    RecordTooLarge { format: &'static str, offset: u64, len: u64, max: usize },
    #[error("{format}: unsupported version {major}.{minor}")]
    UnsupportedCaptureVersion { format: &'static str, major: u16, minor: u16 },
    #[error("pcapng: block {block_type:#010x} at byte {offset}: {reason}")]
    BadBlock { offset: u64, block_type: u32, reason: &'static str },
    #[error("pcapng: packet at byte {offset} names interface {interface}, the section has {known}")]
    UnknownInterface { offset: u64, interface: u32, known: usize },
    #[error("{format}: malformed at byte {offset}: {reason}")]
    MalformedCapture { format: &'static str, offset: u64, reason: &'static str },
    #[error("lvx: package at byte {offset} has unknown data_type {data_type}")]
    LvxDataType { offset: u64, data_type: u8 },
    #[error("lvx: frame at byte {offset}: {reason} (header says current {current}, next {next})")]
    LvxFrame { offset: u64, current: u64, next: u64, reason: &'static str },
    #[error("lvx: device index {0} is not in the file's device list")]
    LvxUnknownDevice(u8),
    #[error("capture writer: {what} of {len} bytes exceeds {max}")]
    TooLarge { what: &'static str, len: usize, max: usize },
    #[error("capture writer: datagram without {0} address")]
    MissingAddress(&'static str),
    #[error("{context}: {source}")]
    Io { context: String, source: std::io::Error },
    #[error("device {0} did not answer")]
    Timeout(String),
    #[error("configuration: {0}")]
    BadConfig(String),
    #[error("device refused {command}: return code {ret}")]
    Refused { command: &'static str, ret: u8 },
}

impl LivoxError {
    pub fn io(context: impl Into<String>, source: std::io::Error) -> Self {
        Self::Io { context: context.into(), source }
    }
}

pub type Result<T, E = LivoxError> = std::result::Result<T, E>;

/// Checks that `bytes` holds at least `need` bytes before anyone indexes it.
pub(crate) fn need(what: &'static str, bytes: &[u8], need: usize) -> Result<()> {
    if bytes.len() < need {
        return Err(LivoxError::TooShort { what, need, have: bytes.len() });
    }
    Ok(())
}
