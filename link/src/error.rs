use std::path::PathBuf;

use starc_pipeline::PipelineError;
use thiserror::Error;

/// Everything that can go wrong in the link crate.
#[derive(Debug, Error)]
pub enum LinkError {
    /// A configuration value that cannot work (names the field).
    #[error("link config: {field}: {reason}")]
    Config { field: &'static str, reason: String },
    #[error("link config {path}: {reason}")]
    ConfigFile { path: PathBuf, reason: String },
    /// Making the CA or a certificate (`starc link certs`).
    #[error("link certificates: {context}: {reason}")]
    Certs { context: &'static str, reason: String },
    /// Writing a certificate or key file (the I/O error's text: kept out of the error chain so
    /// that `{:#}` does not print it twice).
    #[error("{path}: {reason}")]
    File { path: PathBuf, reason: String },
    /// zenoh refused (opening the session, declaring, sending, querying).
    #[error("zenoh {context}: {reason}")]
    Zenoh { context: &'static str, reason: String },
    /// A message that does not encode or decode.
    #[error("link message: {0}")]
    Codec(#[from] PipelineError),
    /// A ROS 2 type whose RIHS01 hash cannot be computed from the schema we ship.
    #[error("ROS 2 type hash of {type_name}: {reason}")]
    TypeHash { type_name: String, reason: String },
    /// The node was closed.
    #[error("link node closed")]
    Closed,
}

impl LinkError {
    pub(crate) fn zenoh(context: &'static str, e: impl std::fmt::Display) -> Self {
        Self::Zenoh { context, reason: e.to_string() }
    }
}
