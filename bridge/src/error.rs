//! Everything that can go wrong turning device data into pipeline inputs.

use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum BridgeError {
    #[error("{path}: {source}")]
    Io { path: PathBuf, source: std::io::Error },
    #[error("{path}: {source}")]
    Capture { path: PathBuf, source: starc_livox::LivoxError },
    #[error("scan assembler: {0}")]
    Scan(String),
    #[error("{path}: {source}")]
    Recording { path: PathBuf, source: starc_pipeline::PipelineError },
    #[error("{topic} message {sequence}: {source}")]
    Message { topic: String, sequence: u32, source: starc_pipeline::PipelineError },
    #[error("wheel log {path}: {reason}")]
    WheelLog { path: PathBuf, reason: String },
    #[error("external IMU {path}: {reason}")]
    ExternalImu { path: PathBuf, reason: String },
}
