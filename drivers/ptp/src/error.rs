use thiserror::Error;

/// Everything that can go wrong in the PTP crate.
#[derive(Debug, Error)]
pub enum PtpError {
    #[error("{what}: need {need} bytes, have {have}")]
    TooShort { what: &'static str, need: usize, have: usize },
    #[error("PTP version byte {0:#04x}: only 0x02 (1588-2008) and 0x12 (1588-2019) are spoken")]
    UnsupportedVersion(u8),
    #[error("PTP messageType {0:#x} is reserved")]
    ReservedMessageType(u8),
    #[error("PTP {message}: messageLength {declared} but the message needs at least {need}")]
    LengthTooSmall { message: &'static str, declared: usize, need: usize },
    #[error("PTP messageLength {declared} exceeds the {actual}-byte datagram")]
    LengthExceedsDatagram { declared: usize, actual: usize },
    #[error("PTP timestamp: {0} ns does not fit 48-bit seconds")]
    TimestampRange(i128),
    #[error("PTP: {0} messages are parsed but not encoded")]
    NotEncodable(&'static str),
    #[error("PTP encode: buffer of {have} bytes, message needs {need}")]
    BufferTooSmall { need: usize, have: usize },
    #[error("configuration: {0}")]
    BadConfig(String),
    #[error("interface {iface}: {reason}")]
    Interface { iface: String, reason: String },
    #[error("{context}: {source}")]
    Io { context: String, source: std::io::Error },
}

impl PtpError {
    pub fn io(context: impl Into<String>, source: std::io::Error) -> Self {
        Self::Io { context: context.into(), source }
    }
}

pub type Result<T, E = PtpError> = std::result::Result<T, E>;
