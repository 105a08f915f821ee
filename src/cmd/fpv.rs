//! `starc fpv --config fpv.toml`: the responder's rig node (see `starc_node::fpv`); stops on SIGINT,
//! SIGTERM or SIGHUP, finishing its recording.

use super::runtime;
use starc_node::config::FpvNodeConfig;
use starc_node::{fpv, stop_on_signals};
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    /// The node's config (see config/fpv.toml).
    #[arg(long)]
    pub config: PathBuf,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let cfg = FpvNodeConfig::from_file(&args.config)?;
    runtime()?.block_on(async move {
        let (_stop_tx, stop) = stop_on_signals()?;
        let summary = fpv::run(cfg, stop, Vec::new(), None).await?;
        println!("{}", serde_json::to_string_pretty(&summary)?);
        Ok(())
    })
}
