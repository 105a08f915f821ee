//! `--detector` and `--detect-config`, shared by the commands that run the robot's detector.

use anyhow::Context;
use starc_pipeline::detect::{DetectConfig, DetectorKind};
use std::path::PathBuf;

#[derive(clap::Args, Clone, Debug, Default)]
pub struct DetectorArgs {
    /// The person detector: trees (clusters scored by learned trees), geometric (clusters scored
    /// by hand-set rules) or pointpillars (a learned network; docs/pillars.md). Default: the
    /// detect config's `kind`, else trees (docs/detect.md).
    #[arg(long)]
    pub detector: Option<DetectorKind>,
    /// A detector config file (like config/detect.toml); fields left out keep their defaults.
    #[arg(long)]
    pub detect_config: Option<PathBuf>,
}

impl DetectorArgs {
    pub fn config(&self) -> anyhow::Result<DetectConfig> {
        let mut cfg = match &self.detect_config {
            Some(path) => {
                let text = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
                DetectConfig::from_toml(&text).with_context(|| format!("in {}", path.display()))?
            }
            None => DetectConfig::default(),
        };
        if let Some(kind) = self.detector {
            cfg.kind = kind;
        }
        Ok(cfg)
    }
}
