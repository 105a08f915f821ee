//! `starc rerun ROBOT.mcap [FPV.mcap] --out DIR [--fpv-config fpv.toml] [--truth SIM_DIR]`:
//! the mission's pipeline rerun on the nodes' recordings (both sides, offline, in time order,
//! through `starc_eval::offline`): trajectories, alignments, detections and AR frames, scored
//! into report.json when the simulator's truth is given. `--no-wall-timing` reads every compute
//! time as 0, so two reruns write the same bytes.

use anyhow::bail;
use starc_eval::offline::{self, Offline, Start};
use starc_node::config::{load, CameraMountConfig, FpvNodeConfig};
use starc_pipeline::mission::RobotCoreConfig;
use std::path::PathBuf;

#[derive(clap::Args, Clone, Debug)]
pub struct Args {
    /// The nodes' MCAP recordings (robot, rig or both), merged by time.
    #[arg(required = true)]
    pub recordings: Vec<PathBuf>,
    /// Where to write (default: `rerun/` next to the first recording).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// The rig node's config (camera, expected start); default: the shipped camera and the
    /// robot's start.
    #[arg(long)]
    pub fpv_config: Option<PathBuf>,
    /// Recordings of a `starc sim` run: its directory, to score the rerun against the truth
    /// (the rig's start is then seeded from the truth too).
    #[arg(long)]
    pub truth: Option<PathBuf>,
    /// Write every Nth AR frame as PNG (0: none).
    #[arg(long, default_value_t = 5)]
    pub frames_every: u64,
    /// Compute times read 0 and peak memory is left out: the outputs depend on the recordings
    /// alone.
    #[arg(long)]
    pub no_wall_timing: bool,
    /// Apply the rig's first alignment once searches have found it again over this long (s; 0:
    /// the first accepted one at once), as `starc sim --confirm-first-s` ran it. Default: the
    /// rig node config's, else 3 s.
    #[arg(long)]
    pub confirm_first_s: Option<f64>,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    for f in &args.recordings {
        if !starc_bridge::is_mcap(f) {
            bail!(
                "{}: not an MCAP recording (a capture is played with `starc replay FILE --to udp://...`)",
                f.display()
            );
        }
    }
    let first = args.recordings.first().cloned().unwrap_or_default();
    let out = args.out.clone().unwrap_or_else(|| first.with_file_name("rerun"));
    let inputs = starc_bridge::from_recordings(&args.recordings)?;
    let mut run = match (&args.truth, &args.fpv_config) {
        (Some(dir), _) => with_truth(dir, out, &args)?,
        (None, config) => without_truth(config.as_deref(), out, &args)?,
    };
    if let Some(s) = args.confirm_first_s {
        if !(s.is_finite() && s >= 0.0) {
            bail!("--confirm-first-s must be a number of seconds, at least 0 (got {s})");
        }
        run.confirm_first_s = s;
    }
    print!("{}", offline::run(inputs, run)?);
    Ok(())
}

fn with_truth(dir: &std::path::Path, out: PathBuf, args: &Args) -> anyhow::Result<Offline> {
    let truth = starc_eval::Truth::load(dir)?;
    Ok(Offline::scored_with_hint(truth, out, args.frames_every, !args.no_wall_timing))
}

fn without_truth(config: Option<&std::path::Path>, out: PathBuf, args: &Args) -> anyhow::Result<Offline> {
    let cfg: Option<FpvNodeConfig> = config.map(load).transpose()?;
    let camera = match &cfg {
        Some(c) => c.camera.clone(),
        None => CameraMountConfig {
            model: starc_pipeline::ar::CameraModel::default(),
            translation_m: [0.0; 3],
            quaternion_xyzw: [-0.5, 0.5, -0.5, 0.5],
        },
    };
    let start = cfg.as_ref().and_then(|c| c.expected_start).map_or(Start::Anywhere, |s| Start::At(s.isometry()));
    Ok(Offline {
        out,
        frames_every: args.frames_every,
        lidar_t_camera: camera.lidar_t_camera()?,
        camera: camera.model,
        start,
        start_gate_m: cfg.as_ref().map_or(2.0, |c| c.start_gate_m),
        confirm_first_s: cfg.as_ref().map_or(starc_pipeline::mission::CONFIRM_FIRST_S, |c| c.confirm_first_s),
        coverage: true,
        robot: RobotCoreConfig::default(),
        rig_align: starc_pipeline::mission::RigCoreConfig::default().align,
        rig_lio: starc_pipeline::mission::RigCoreConfig::default().lio,
        truth: None,
        wall_timing: !args.no_wall_timing,
        align: true,
    })
}
