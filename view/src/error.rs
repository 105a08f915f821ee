//! The one error type of the live views.

use std::path::PathBuf;
use thiserror::Error;

#[derive(Debug, Error)]
pub enum ViewError {
    #[error("{context}: {source}")]
    Io {
        context: String,
        #[source]
        source: std::io::Error,
    },
    #[error("encoding the frame as PNG: {0}")]
    Png(#[from] starc_pipeline::PipelineError),
    #[error("frame is {width}x{height} but holds {bytes} bytes of RGB (expected {expected})")]
    BadFrame { width: u32, height: u32, bytes: usize, expected: usize },
    #[error("framebuffer {path}: {reason}")]
    Framebuffer { path: PathBuf, reason: String },
    #[error("framebuffer {path}: {bits_per_pixel} bits per pixel is not supported (16, 24 or 32)")]
    UnsupportedFormat { path: PathBuf, bits_per_pixel: u32 },
    #[error("Foxglove channel {topic}: {reason}")]
    Channel { topic: String, reason: String },
    #[error("view config: {0}")]
    Config(String),
}

impl ViewError {
    pub fn io(context: impl Into<String>, source: std::io::Error) -> Self {
        Self::Io { context: context.into(), source }
    }
}
