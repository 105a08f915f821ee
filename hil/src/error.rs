//! The one error type of the hil crate.

use std::net::SocketAddrV4;
use std::path::PathBuf;
use thiserror::Error;

/// Everything that can go wrong in a mock device.
#[derive(Debug, Error)]
pub enum HilError {
    /// A configuration value out of range or inconsistent.
    #[error("configuration: {field}: {reason}")]
    Config { field: &'static str, reason: String },
    /// A socket could not be bound.
    #[error("binding {addr}: {source}")]
    Bind { addr: SocketAddrV4, source: std::io::Error },
    /// Another socket operation failed.
    #[error("{context}: {source}")]
    Io { context: String, source: std::io::Error },
    /// A capture file could not be opened or read.
    #[error("capture {path}: {source}")]
    Capture { path: PathBuf, source: starc_livox::LivoxError },
    /// A capture file holds no packet a source can replay.
    #[error("capture {path}: {reason}")]
    EmptyCapture { path: PathBuf, reason: &'static str },
    /// A scenario file that does not parse or does not make sense; `line` is 1-based.
    #[error("scenario {origin}{}: {reason}", line.map(|l| format!(", line {l}")).unwrap_or_default())]
    Scenario { origin: String, line: Option<usize>, reason: String },
    /// A file could not be read.
    #[error("reading {path}: {source}")]
    Read { path: PathBuf, source: std::io::Error },
    /// A line of a TUM trajectory that does not parse; `line` is 1-based.
    #[error("{path} line {line}: expected {expected}")]
    TumLine { path: PathBuf, line: usize, expected: &'static str },
    /// Writing a simulator output failed.
    #[error("writing {path}: {reason}")]
    Output { path: PathBuf, reason: String },
    /// What drives the simulated robot in a closed loop failed.
    #[error("robot driver: {0}")]
    Driver(String),
    /// The mock's task ended abnormally (panicked or was cancelled).
    #[error("mock task: {0}")]
    Task(String),
}

impl HilError {
    pub fn config(field: &'static str, reason: impl Into<String>) -> Self {
        Self::Config { field, reason: reason.into() }
    }
}

pub type Result<T, E = HilError> = std::result::Result<T, E>;
