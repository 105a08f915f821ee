//! Everything that stops a node from starting or finishing cleanly.

use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum NodeError {
    #[error("reading {path}: {source}")]
    Read { path: PathBuf, source: std::io::Error },
    #[error("{path}: {source}")]
    Toml { path: PathBuf, source: toml::de::Error },
    /// A setting the types let through but the node cannot use.
    #[error("{0}")]
    Config(String),
    #[error("{path}: {source}")]
    File { path: PathBuf, source: starc_pipeline::PipelineError },
    #[error("{0}")]
    Pipeline(#[from] starc_pipeline::PipelineError),
    /// A node config's `[link]` table the link refuses (names the file).
    #[error("{path}: [link]: {source}")]
    LinkConfig { path: PathBuf, source: starc_link::LinkError },
    #[error("the link: {0}")]
    Link(#[from] starc_link::LinkError),
    #[error("the Livox driver: {0}")]
    Livox(#[from] starc_livox::LivoxError),
    #[error("the views: {0}")]
    View(#[from] starc_view::ViewError),
    #[error("{what}: {source}")]
    Io { what: &'static str, source: std::io::Error },
    #[error("{0}")]
    Thread(&'static str),
    /// The disk did not take the recording's last entries and index in time (a stalled disk);
    /// every chunk it took is readable in recover mode.
    #[error(
        "the recording was not finished within {waited_s:.0} s (the disk is stalled); its closed chunks are readable"
    )]
    RecordingStalled { waited_s: f64 },
}

pub type Result<T> = std::result::Result<T, NodeError>;
