//! `starc robot --config robot.toml`: the robot node (see `starc_node::robot`); stops on SIGINT,
//! SIGTERM or SIGHUP, finishing its recording.

use super::runtime;
use starc_node::config::RobotNodeConfig;
use starc_node::{robot, stop_on_signals};
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    /// The node's config (see config/robot.toml).
    #[arg(long)]
    pub config: PathBuf,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let cfg = RobotNodeConfig::from_file(&args.config)?;
    runtime()?.block_on(async move {
        let (_stop_tx, stop) = stop_on_signals()?;
        let summary = robot::run(cfg, stop, None).await?;
        println!("{}", serde_json::to_string_pretty(&summary)?);
        Ok(())
    })
}
