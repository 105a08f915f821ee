//! The one error type of the eval crate.

use starc_pipeline::PipelineError;
use std::path::PathBuf;
use thiserror::Error;

/// Everything that can go wrong while reading a run's truth or writing its report.
#[derive(Debug, Error)]
pub enum EvalError {
    /// A file could not be read.
    #[error("reading {path}: {source}")]
    Read { path: PathBuf, source: std::io::Error },
    /// A file or directory could not be written.
    #[error("writing {path}: {source}")]
    Write { path: PathBuf, source: std::io::Error },
    /// A line of a text truth file that does not parse (`line` counts from 1).
    #[error("{path} line {line}: expected {expected}")]
    BadLine { path: PathBuf, line: usize, expected: &'static str },
    /// A file that parses but cannot be used (too short, a bad mounting, ...).
    #[error("{path}: {reason}")]
    BadFile { path: PathBuf, reason: String },
    /// A JSON file that does not parse, or a report that does not serialize.
    #[error("{path}: {source}")]
    Json { path: PathBuf, source: serde_json::Error },
    /// The run has no camera frames to score (`starc sim --no-camera`).
    #[error("{path}: no camera frames; the mission scores camera frames: run `starc sim` without --no-camera")]
    NoCameraFrames { path: PathBuf },
    /// A mission input that could not be read (a capture or recording).
    #[error("mission input: {0}")]
    Input(String),
    /// A mission that gave no poses for one side.
    #[error("the LIO produced no poses for {side} (did both devices stand still at the start?)")]
    NoPoses { side: &'static str },
    /// A mask, camera model or AR frame refused by the pipeline.
    #[error("{path}: {source}")]
    Pipeline { path: PathBuf, source: PipelineError },
}

pub type Result<T> = std::result::Result<T, EvalError>;

/// Reads a file, naming it in the error.
pub(crate) fn read(path: &std::path::Path) -> Result<Vec<u8>> {
    std::fs::read(path).map_err(|source| EvalError::Read { path: path.to_path_buf(), source })
}

/// Reads a text file, naming it in the error.
pub(crate) fn read_text(path: &std::path::Path) -> Result<String> {
    std::fs::read_to_string(path).map_err(|source| EvalError::Read { path: path.to_path_buf(), source })
}

/// Writes a file, naming it in the error.
pub(crate) fn write(path: &std::path::Path, bytes: impl AsRef<[u8]>) -> Result<()> {
    std::fs::write(path, bytes).map_err(|source| EvalError::Write { path: path.to_path_buf(), source })
}
