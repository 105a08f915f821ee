use thiserror::Error;

/// Everything that can go wrong in the pipeline crate.
#[derive(Debug, Error)]
pub enum PipelineError {
    #[error("{context}: {source}")]
    Io { context: String, source: std::io::Error },
    #[error("{format} file: {reason}")]
    BadFile { format: &'static str, reason: String },
    /// A header line that cannot be understood (`line` counts from 1).
    #[error("{format} header, line {line}: {reason}")]
    BadHeader { format: &'static str, line: usize, reason: String },
    /// A field the reader cannot do without (x, y or z).
    #[error("{format} file: no {field} field")]
    MissingField { format: &'static str, field: &'static str },
    /// The header promises more data than the file holds.
    #[error("{format} file: {what} needs {need} bytes, {have} left")]
    Truncated { format: &'static str, what: &'static str, need: u64, have: u64 },
    /// A value of the data section that does not parse (`index` counts points from 0).
    #[error("{format} file, point {index}: {reason}")]
    BadPoint { format: &'static str, index: u64, reason: String },
    /// A valid file using a feature this reader does not implement.
    #[error("{format} file: {what} is not supported")]
    Unsupported { format: &'static str, what: String },
    /// Neither the first bytes nor the file name tell the point-cloud format.
    #[error("{path}: unknown point-cloud format (expected .pcd, .ply or KITTI .bin)")]
    UnknownFormat { path: String },
    /// A CDR payload (ROS 2 message) that does not decode (`offset` counts from the payload start).
    #[error("CDR {type_name} at byte {offset}: {reason}")]
    BadCdr { type_name: &'static str, offset: usize, reason: String },
    /// The MCAP library refused to write or read a recording.
    #[error("MCAP {context}: {source}")]
    Mcap { context: String, source: mcap::McapError },
    /// A recording call that cannot be honoured (after `finish`, or a value ROS cannot hold).
    #[error("recording: {reason}")]
    Recording { reason: String },
    /// A pose asked for outside the span of a timed pose buffer (or of an empty one).
    #[error("no pose at {t_ns} ns: the buffer spans {first_ns}..={last_ns} ns ({len} poses)")]
    PoseOutOfRange { t_ns: u64, first_ns: u64, last_ns: u64, len: usize },
    /// A pose pushed out of time order (or a non-finite one).
    #[error("pose at {t_ns} ns refused: {reason}")]
    BadPose { t_ns: u64, reason: String },
}

impl PipelineError {
    pub fn io(context: impl Into<String>, source: std::io::Error) -> Self {
        Self::Io { context: context.into(), source }
    }
}
