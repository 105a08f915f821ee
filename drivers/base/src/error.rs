//! The one error type of the base crate.

use starc_can::CanError;
use thiserror::Error;

/// Everything that can go wrong in the base driver.
#[derive(Debug, Error)]
pub enum BaseError {
    #[error("{what}: need {need} bytes, frame has {have}")]
    TooShort { what: &'static str, need: usize, have: usize },
    #[error("{what}: frame id {id:#x} is not one of ours")]
    WrongId { what: &'static str, id: u32 },
    #[error("{what}: {reason}")]
    Malformed { what: &'static str, reason: String },
    #[error("configuration: {field}: {reason}")]
    Config { field: &'static str, reason: String },
    #[error("CAN: {0}")]
    Can(#[from] CanError),
    #[error("{context}: {source}")]
    Io { context: String, source: std::io::Error },
    #[error("the base controller has stopped")]
    Stopped,
}

impl BaseError {
    pub fn config(field: &'static str, reason: impl Into<String>) -> Self {
        Self::Config { field, reason: reason.into() }
    }

    pub(crate) fn malformed(what: &'static str, reason: impl Into<String>) -> Self {
        Self::Malformed { what, reason: reason.into() }
    }
}

pub type Result<T, E = BaseError> = std::result::Result<T, E>;

/// Checks that `data` holds at least `need` bytes before anyone indexes it.
pub(crate) fn need(what: &'static str, data: &[u8], need: usize) -> Result<()> {
    if data.len() < need {
        return Err(BaseError::TooShort { what, need, have: data.len() });
    }
    Ok(())
}

/// Bytes `at..at+N` as an array, after [`need`] said they exist.
pub(crate) fn bytes<const N: usize>(data: &[u8], at: usize) -> [u8; N] {
    let mut out = [0u8; N];
    if let Some(src) = data.get(at..at + N) {
        out.copy_from_slice(src);
    }
    out
}
