//! The one error type of the CAN crate.

use thiserror::Error;

/// Everything that can go wrong with CAN frames and transports.
#[derive(Debug, Error)]
pub enum CanError {
    #[error("CAN id {id:#x} does not fit in {bits} bits")]
    IdOutOfRange { id: u32, bits: u8 },
    #[error("CAN frame: {len} data bytes, at most 8")]
    TooMuchData { len: usize },
    #[error("CAN remote frame: DLC {dlc}, at most 8")]
    BadDlc { dlc: u8 },
    #[error("slcan: {reason} in {line:?}")]
    BadLine { reason: &'static str, line: String },
    #[error("slcan: line longer than {max} bytes without a CR")]
    LineTooLong { max: usize },
    #[error("slcan: unknown bitrate {0} bit/s (S0-S8 cover 10k..1M)")]
    UnsupportedBitrate(u32),
    #[error("slcan: the adapter refused {command:?} (BEL)")]
    Refused { command: String },
    #[error("slcan: no reply to {command:?} within {timeout_ms} ms")]
    NoReply { command: String, timeout_ms: u64 },
    #[error("{context}: {source}")]
    Io { context: String, source: std::io::Error },
    #[error("the CAN transport is closed")]
    Closed,
}

impl CanError {
    pub fn io(context: impl Into<String>, source: std::io::Error) -> Self {
        Self::Io { context: context.into(), source }
    }

    pub(crate) fn bad_line(reason: &'static str, line: &[u8]) -> Self {
        Self::BadLine { reason, line: String::from_utf8_lossy(line).into_owned() }
    }
}

pub type Result<T, E = CanError> = std::result::Result<T, E>;
