//! The one error type of the IMU crate.

use thiserror::Error;

/// Everything that can go wrong with a serial IMU: bad bytes, refused commands, ports.
#[derive(Debug, Error)]
pub enum ImuError {
    #[error("{what}: need {need} bytes, have {have}")]
    TooShort { what: &'static str, need: usize, have: usize },
    #[error("MIP: sync bytes {0:02x?}, expected [75, 65]")]
    BadSync([u8; 2]),
    #[error("MIP: Fletcher-16 stored {stored:#06x}, computed {computed:#06x}")]
    BadChecksum { stored: u16, computed: u16 },
    #[error("MIP: payload of {len} bytes is over the 255-byte maximum")]
    PayloadTooLong { len: usize },
    #[error("MIP: field at payload byte {offset} of set {set:#04x}: {reason}")]
    BadField { set: u8, offset: usize, reason: &'static str },
    #[error("MIP: field ({set:#04x},{descriptor:#04x}) has {len} data bytes, expected {expected}")]
    FieldLength { set: u8, descriptor: u8, len: usize, expected: &'static str },
    #[error("MIP: unknown command ({set:#04x},{descriptor:#04x})")]
    UnknownCommand { set: u8, descriptor: u8 },
    #[error("MIP: packet in set {set:#04x} holds no command")]
    NoCommand { set: u8 },
    #[error("MIP: command ({set:#04x},{command:#04x}) refused with code {code:#04x} ({name})")]
    Nack { set: u8, command: u8, code: u8, name: &'static str },
    #[error("WitMotion: frame starts with {0:#04x}, expected 0x55")]
    WitBadHeader(u8),
    #[error("WitMotion: frame type {0:#04x} is not an output frame (0x50..=0x5f)")]
    WitBadType(u8),
    #[error("WitMotion: checksum stored {stored:#04x}, computed {computed:#04x}")]
    WitChecksum { stored: u8, computed: u8 },
    #[error("WitMotion: config write starts with {0:02x?}, expected [ff, aa]")]
    WitBadConfigHeader([u8; 2]),
    #[error("invalid value {value} for {field}")]
    BadValue { field: &'static str, value: u64 },
    #[error("{protocol}: baud rate {baud} is not one the device offers")]
    UnsupportedBaud { protocol: &'static str, baud: u32 },
    #[error("WitMotion: output rate {rate_hz} Hz is not one the device offers")]
    UnsupportedRate { rate_hz: f64 },
    #[error("configuration: {field}: {reason}")]
    Config { field: &'static str, reason: String },
    #[error("serial port {port}: {source}")]
    Serial { port: String, source: tokio_serial::Error },
    #[error("{context}: {source}")]
    Io { context: String, source: std::io::Error },
    #[error("{what}: no answer after {tries} tries")]
    Timeout { what: String, tries: u32 },
    #[error("WitMotion: asked for {expected_hz} Hz, observed {observed_hz:.1} Hz")]
    NotVerified { expected_hz: f64, observed_hz: f64 },
    #[error("the IMU driver task has stopped")]
    Closed,
}

impl ImuError {
    pub fn io(context: impl Into<String>, source: std::io::Error) -> Self {
        Self::Io { context: context.into(), source }
    }

    pub fn config(field: &'static str, reason: impl Into<String>) -> Self {
        Self::Config { field, reason: reason.into() }
    }
}

pub type Result<T, E = ImuError> = std::result::Result<T, E>;
