use thiserror::Error;

/// Everything that can go wrong in the pipeline crate.
#[derive(Debug, Error)]
pub enum PipelineError {
    #[error("{context}: {source}")]
    Io { context: String, source: std::io::Error },
    #[error("{format} file: {reason}")]
    BadFile { format: &'static str, reason: String },
}
