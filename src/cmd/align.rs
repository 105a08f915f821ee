//! `starc align --source FILE --target FILE [--init x,y,z,yaw_deg] [--scan-origin x,y,z]
//! [--config FILE] [--json]`:
//! registers a source cloud against a target cloud (NDT, then trimmed point-to-plane ICP) and
//! prints the 4x4 transform mapping source points into the target frame, with its metrics.

use anyhow::Context;
use starc_pipeline::align::{cloud_points, pose_xyz_yaw, AlignConfig, AlignReport, Aligner, Ray, Vec3};
use starc_pipeline::cloud;
use std::io::Write;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    /// Cloud to move (PCD, PLY or KITTI .bin).
    #[arg(long)]
    pub source: PathBuf,
    /// Cloud it is aligned to (the map).
    #[arg(long)]
    pub target: PathBuf,
    /// Initial guess of the source pose in the target frame: x,y,z (m), yaw (deg).
    #[arg(long, value_parser = parse_init, allow_hyphen_values = true)]
    pub init: Option<[f64; 4]>,
    /// The source is one scan taken from this point (its own frame, usually 0,0,0): the result
    /// must also leave the scan's rays clear of the target's surfaces (the free-space check).
    #[arg(long, value_parser = parse_xyz, allow_hyphen_values = true)]
    pub scan_origin: Option<[f64; 3]>,
    /// TOML settings (see config/align.toml); defaults otherwise.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Print the whole report as JSON (stable keys) instead of text.
    #[arg(long)]
    pub json: bool,
}

fn parse_init(s: &str) -> Result<[f64; 4], String> {
    let v: Vec<f64> =
        s.split(',').map(|t| t.trim().parse::<f64>().map_err(|e| format!("{t:?}: {e}"))).collect::<Result<_, _>>()?;
    match v.as_slice() {
        [x, y, z, yaw] if v.iter().all(|a| a.is_finite()) => Ok([*x, *y, *z, *yaw]),
        _ => Err("expected four finite numbers: x,y,z,yaw_deg".into()),
    }
}

fn parse_xyz(s: &str) -> Result<[f64; 3], String> {
    let v: Vec<f64> =
        s.split(',').map(|t| t.trim().parse::<f64>().map_err(|e| format!("{t:?}: {e}"))).collect::<Result<_, _>>()?;
    match v.as_slice() {
        [x, y, z] if v.iter().all(|a| a.is_finite()) => Ok([*x, *y, *z]),
        _ => Err("expected three finite numbers: x,y,z".into()),
    }
}

/// Rays walked by the free-space check come from this many source points at most (it thins
/// them again to `free_space_rays`).
const MAX_RAYS: usize = 20_000;

/// Exit status 0 when the alignment is accepted, 1 when rejected (the report is printed either way).
pub fn run(args: Args) -> anyhow::Result<()> {
    let config = match &args.config {
        Some(p) => {
            let text = std::fs::read_to_string(p).with_context(|| format!("reading {}", p.display()))?;
            AlignConfig::from_toml(&text)?
        }
        None => AlignConfig::default(),
    };
    let source = cloud_points(&cloud::read(&args.source)?);
    let target = cloud_points(&cloud::read(&args.target)?);
    let aligner = Aligner::new(&target, config)?;
    let [x, y, z, yaw] = args.init.unwrap_or([0.0; 4]);
    let rays: Vec<Ray> = match args.scan_origin {
        Some([ox, oy, oz]) => {
            let origin = Vec3::new(ox, oy, oz);
            let stride = source.len().div_ceil(MAX_RAYS).max(1);
            source.iter().step_by(stride).map(|p| Ray { origin, end: *p }).collect()
        }
        None => Vec::new(),
    };
    let report = aligner.align_with_rays(&source, &rays, &pose_xyz_yaw(x, y, z, yaw));
    // Written (not println!) so that a closed pipe (`| head`) is an error, not a panic.
    let mut out = std::io::stdout().lock();
    if args.json {
        serde_json::to_writer_pretty(&mut out, &report)?;
        writeln!(out)?;
    } else {
        print_text(&mut out, &report, aligner.prepare_ms)?;
    }
    anyhow::ensure!(report.accepted, "alignment rejected (the transform above is the best attempt, not a result)");
    Ok(())
}

fn print_text(out: &mut impl Write, report: &AlignReport, prepare_ms: f64) -> std::io::Result<()> {
    writeln!(out, "T_target_source ({}):", if report.accepted { "accepted" } else { "REJECTED" })?;
    for row in &report.transform {
        writeln!(out, "  {:12.6} {:12.6} {:12.6} {:12.6}", row[0], row[1], row[2], row[3])?;
    }
    if let Some(a) = report.best() {
        let m = &a.metrics;
        writeln!(
            out,
            "rms residual {:.4} m, inlier ratio {:.3}, update norm {:.2e}, degeneracy index {:.4}, {} correspondences",
            m.rms_residual_m, m.inlier_ratio, m.update_norm, m.degeneracy_index, m.correspondences
        )?;
        if let Some(f) = &a.free_space {
            writeln!(
                out,
                "free space: {} of {} rays cross a target surface before their end ({:.1} %)",
                f.blocked,
                f.rays,
                f.blocked_ratio * 100.0
            )?;
        }
        if let Some(p) = a.pinned.as_ref().filter(|p| p.pinned) {
            // Accepted below the degeneracy index: say what held it, so nobody is surprised.
            let fewest = p.directions.iter().flat_map(|d| &d.moves).map(|m| p.explained.saturating_sub(m.1)).min();
            writeln!(
                out,
                "pinned by what it explains: {} of {} points; moved along its {} weak direction(s) it loses at least {} of them",
                p.explained,
                p.points,
                p.directions.len(),
                fewest.unwrap_or(0)
            )?;
        }
        if !a.rejected_because.is_empty() {
            writeln!(out, "rejected because: {}", starc_pipeline::align::Reasons(&a.rejected_because))?;
        }
    }
    if let Some(f) = &report.failure {
        writeln!(out, "failure: {f}")?;
    }
    writeln!(
        out,
        "{} seed(s) ranked in {:.1} ms (correlative stage {:.1} ms); {} full attempt(s) (best: seed yaw {:+.0} deg); {} source points; target prepared in {:.1} ms; aligned in {:.1} ms",
        report.seeds.len(),
        report.seed_ms,
        report.correlative_ms,
        report.attempts.len(),
        report.best().map_or(0.0, |a| a.seed_yaw_offset_deg),
        report.source_points,
        prepare_ms,
        report.total_ms
    )?;
    Ok(())
}

/// The rig's first-alignment search settings: `path`'s (an align.toml), else the rig's defaults.
pub fn rig_align_config(path: Option<&std::path::Path>) -> anyhow::Result<AlignConfig> {
    let Some(path) = path else { return Ok(starc_pipeline::mission::RigCoreConfig::default().align) };
    let text = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    AlignConfig::from_toml(&text).with_context(|| format!("parsing {}", path.display()))
}
