//! `starc eval --seeds A..B [--family F] [--offline] --out DIR`: the whole mission on each
//! generated building of a seed range, one row per building in DIR/eval.json with every figure
//! of its report.json, a summary (median, p10, p90) per figure per family and over all, and a
//! plot per figure. Seeds from 1000 up are the held-out test set (docs/eval.md).
//!
//! No truth reaches the pipeline unless `--hint truth` says so: the rig's first alignment is
//! seeded at the world origin with no gate, as a responder who enters anywhere would be.

use anyhow::{bail, Context};
use starc_eval::batch::{alignment_goal, flatten, markdown_table, print_summary, summarize, write_plots, Row};
use starc_eval::offline::{self, Offline, Start};
use starc_hil::gen;
use starc_hil::sim::run::{run as run_sim, SimOptions};
use starc_hil::sim::run::{FPV_AVIA_IP, ROBOT_AVIA_IP};
use starc_pipeline::mission::{RobotCoreConfig, FLOOR_GRID_RAY_STRIDE};
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Mutex, PoisonError};
use std::time::Instant;

#[derive(clap::Args)]
pub struct Args {
    /// Seeds, both ends included (`1000..1023` is 24 buildings). 1000 and up: the test set.
    #[arg(long)]
    seeds: SeedRange,
    /// flat, office, warehouse, hall, lab, or any (each seed's own family).
    #[arg(long, default_value = "any")]
    family: super::gen::FamilyChoice,
    /// Run the mission offline, in this process (fast); without it, live: mock devices, both
    /// nodes and the link, at the real pace.
    #[arg(long)]
    offline: bool,
    #[arg(long)]
    out: PathBuf,
    /// Seed the rig's first alignment from the simulator's truth (`truth`: its true start moved
    /// 1 m and 20 deg, gated at 2 m), as `starc sim` does. `none` (the default) is the scored
    /// setting: no truth in the loop.
    #[arg(long, default_value = "none")]
    hint: Hint,
    /// Keep each building's pcap, point labels and camera masks (about 250 MB per 30 s); by
    /// default only the scenario, the truth's small files, the reports, the trajectories and the
    /// plots stay.
    #[arg(long)]
    keep: bool,
    /// Write every Nth AR frame as PNG (0: none).
    #[arg(long, default_value_t = 0)]
    frames_every: u64,
    /// Draw a walker only from this height above the floor up (the robot core's
    /// `walker_min_height_m`; 0 draws their legs too): to measure what leaving out a walker's
    /// swinging shins costs and gains on every overlay metric. Offline only.
    #[arg(long)]
    walker_min_height_m: Option<f64>,
    /// Leave the base's wheel odometry out of the robot's LIO (offline), to measure what it
    /// brings.
    #[arg(long)]
    no_wheels: bool,
    /// Judge the rig's alignments on its whole window instead of the part the robot's coverage
    /// can judge (to measure what coverage brings).
    #[arg(long)]
    no_coverage: bool,
    /// Buildings run at once (default: one per core offline, one live).
    #[arg(long)]
    jobs: Option<usize>,
    /// Cut each run at this many simulated seconds (smoke tests; such figures are not the
    /// building's: the responder may not have arrived).
    #[arg(long)]
    max_duration: Option<f64>,
    #[command(flatten)]
    detector: super::detector_arg::DetectorArgs,
    /// Offline: leave out the rig's alignment, for the robot's figures alone (detection and
    /// odometry) in a fraction of the time.
    #[arg(long)]
    no_align: bool,
    /// The rig's first-alignment search settings (TOML, as config/align.toml; every key
    /// optional): to measure a setting on the generated buildings.
    #[arg(long)]
    align_config: Option<PathBuf>,
    /// The rig's LIO settings (TOML, as config/lio.toml; every key optional): to measure a
    /// setting on the generated buildings (report.json `rig_lio_error`).
    #[arg(long)]
    rig_lio_config: Option<PathBuf>,
    /// Offline: compute times read 0 and peak memory is left out, so that a building's report
    /// depends on its seed and the settings alone. Without it, the rig's searches take the time
    /// they take on this machine, and its load moves which windows they see (as on the rig).
    #[arg(long)]
    no_wall_timing: bool,
}

/// An inclusive range of seeds.
#[derive(Clone, Copy, Debug)]
pub struct SeedRange {
    pub first: u64,
    pub last: u64,
}

impl std::str::FromStr for SeedRange {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        let parse = |v: &str| v.trim().parse::<u64>().map_err(|e| format!("{v:?}: {e}"));
        let (first, last) = match s.split_once("..") {
            Some((a, b)) => (parse(a)?, parse(b.trim_start_matches('='))?),
            None => (parse(s)?, parse(s)?),
        };
        if last < first || last - first >= 10_000 {
            return Err(format!("{s}: want A..B with A <= B and at most 10000 seeds"));
        }
        Ok(SeedRange { first, last })
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Hint {
    None,
    Truth,
}

#[derive(serde::Serialize)]
struct EvalFile<'a> {
    seeds: [u64; 2],
    max_duration_s: Option<f64>,
    walker_min_height_m: f64,
    detector: starc_pipeline::detect::DetectorKind,
    aligned: bool,
    test_set: bool,
    family: String,
    mode: &'static str,
    hint: Hint,
    /// Whether compute times were read from the wall clock (`--no-wall-timing`: not).
    wall_timing: bool,
    wall_s: f64,
    jobs: usize,
    buildings: usize,
    failed: usize,
    rows: &'a [Row],
    summary: serde_json::Value,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let SeedRange { first, last } = args.seeds;
    if args.no_align && !args.offline {
        bail!("--no-align is for offline runs");
    }
    if args.no_wall_timing && !args.offline {
        bail!("--no-wall-timing is for offline runs (the live nodes run on the wall clock)");
    }
    if args.walker_min_height_m.is_some() && !args.offline {
        bail!("--walker-min-height-m is for offline runs (the live robot node takes its core's defaults)");
    }
    if first < gen::TEST_SEEDS_FROM && last >= gen::TEST_SEEDS_FROM {
        bail!("--seeds {first}..{last} mixes development seeds (below 1000) with test seeds: run them apart");
    }
    std::fs::create_dir_all(&args.out).with_context(|| format!("creating {}", args.out.display()))?;
    let started = Instant::now();
    let seeds: Vec<u64> = (first..=last).collect();
    let rows = run_all(&args, &seeds, started);
    let summary = summarize(&rows);
    let file = EvalFile {
        seeds: [first, last],
        max_duration_s: args.max_duration,
        walker_min_height_m: robot_config(&args)?.walker_min_height_m,
        detector: robot_config(&args)?.detect.kind,
        aligned: !args.no_align,
        test_set: gen::is_test_seed(first) && args.hint == Hint::None && args.max_duration.is_none(),
        family: args.family.0.map_or_else(|| "any".to_string(), |f| f.to_string()),
        mode: if args.offline { "offline" } else { "live" },
        hint: args.hint,
        wall_timing: !args.no_wall_timing,
        wall_s: started.elapsed().as_secs_f64(),
        jobs: jobs(&args),
        buildings: rows.len(),
        failed: rows.iter().filter(|r| r.error.is_some()).count(),
        rows: &rows,
        summary,
    };
    let path = args.out.join("eval.json");
    std::fs::write(&path, serde_json::to_string_pretty(&file)?)
        .with_context(|| format!("writing {}", path.display()))?;
    let plots = write_plots(&rows, &args.out.join("plots"))?;
    let table = args.out.join("summary.md");
    let goal = alignment_goal(&rows);
    std::fs::write(&table, markdown_table(&file.summary) + "\n" + &goal + "\n")
        .with_context(|| format!("writing {}", table.display()))?;
    println!(
        "{} buildings ({} failed) in {:.0} s; wrote {}, summary.md and {plots} plots",
        file.buildings,
        file.failed,
        file.wall_s,
        path.display()
    );
    print_summary(&file.summary);
    if !args.no_align {
        println!("  {goal}");
    }
    Ok(())
}

/// Each building on one of `--jobs` threads (the simulator and the mission each keep one core
/// busy); rows in seed order.
fn run_all(args: &Args, seeds: &[u64], started: Instant) -> Vec<Row> {
    let next = AtomicUsize::new(0);
    let done = AtomicUsize::new(0);
    let rows = Mutex::new(Vec::with_capacity(seeds.len()));
    std::thread::scope(|scope| {
        for _ in 0..jobs(args).min(seeds.len()) {
            scope.spawn(|| {
                while let Some(&seed) = seeds.get(next.fetch_add(1, Ordering::Relaxed)) {
                    let t0 = Instant::now();
                    let row = guarded(args, seed);
                    let n = done.fetch_add(1, Ordering::Relaxed) + 1;
                    progress(n, seeds.len(), &row, t0.elapsed().as_secs_f64(), started.elapsed().as_secs_f64());
                    rows.lock().unwrap_or_else(PoisonError::into_inner).push(row);
                }
            });
        }
    });
    let mut rows = rows.into_inner().unwrap_or_else(PoisonError::into_inner);
    rows.sort_by_key(|r| r.seed);
    rows
}

/// One building, its failure or panic a failed row rather than the end of the batch.
fn guarded(args: &Args, seed: u64) -> Row {
    let failed = |why: String| Row::failed(seed, args.family.0, &why);
    match std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| one_building(args, seed))) {
        Ok(Ok(row)) => row,
        Ok(Err(e)) => failed(format!("{e:#}")),
        Err(panic) => {
            let what =
                panic.downcast_ref::<&str>().map(|s| s.to_string()).or_else(|| panic.downcast_ref::<String>().cloned());
            failed(format!("panicked: {}", what.unwrap_or_default()))
        }
    }
}

/// Buildings at once: `--jobs`, else one per core offline and one live (a live run keeps both
/// nodes busy at the real pace, and its latencies are figures).
fn jobs(args: &Args) -> usize {
    let default = if args.offline { std::thread::available_parallelism().map_or(1, |n| n.get()) } else { 1 };
    args.jobs.unwrap_or(default).max(1)
}

fn progress(done: usize, total: usize, row: &Row, took_s: f64, elapsed_s: f64) {
    let eta = elapsed_s / done as f64 * (total - done) as f64;
    let what = match &row.error {
        Some(e) => format!("failed: {}", e.lines().next().unwrap_or("")),
        None => row.headline(),
    };
    eprintln!("[{done}/{total}] {}-{} {took_s:.0} s, eta {eta:.0} s: {what}", row.family, row.seed);
    let _ = std::io::stderr().flush();
}

fn one_building(args: &Args, seed: u64) -> anyhow::Result<Row> {
    let g = gen::generate(seed, args.family.0)?;
    let dir = args.out.join(format!("{}-{seed}", g.family));
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    std::fs::write(dir.join("plan.svg"), starc_hil::sim::plan_svg::plan_svg(&g.scenario))?;
    let duration_s = args.max_duration.map(|m| m.min(g.scenario.duration_s));
    let opts = SimOptions { out: dir.clone(), duration_s, seed, realtime: false, camera: true };
    run_sim(&g.scenario, &g.text, &opts, &mut |_, _| {}).with_context(|| format!("simulating {}", dir.display()))?;
    let mission_dir = dir.join("mission");
    if args.offline {
        mission_offline(&dir, g.scenario.robot.get_ref(), &mission_dir, args)?;
    } else {
        mission_live(&dir, &mission_dir, args)?;
    }
    if !args.keep {
        remove_bulk(&dir);
    }
    let report: serde_json::Value = serde_json::from_slice(
        &std::fs::read(mission_dir.join("report.json"))
            .with_context(|| format!("reading {}", mission_dir.display()))?,
    )?;
    Ok(Row::new(seed, g.family, g.people, duration_s.unwrap_or(g.scenario.duration_s), flatten(&report)))
}

fn mission_offline(dir: &Path, robot: &starc_hil::sim::scenario::Robot, out: &Path, args: &Args) -> anyhow::Result<()> {
    let truth = starc_eval::Truth::load(dir)?;
    let mut inputs = starc_bridge::from_capture(&dir.join("avia.pcap"), ROBOT_AVIA_IP, FPV_AVIA_IP)?;
    if !args.no_wheels {
        inputs = starc_bridge::wheels::with_wheels(inputs, super::sim::wheel_samples(dir, robot)?);
    }
    let (start, start_gate_m) = match args.hint {
        Hint::None => (Start::Anywhere, f64::INFINITY),
        Hint::Truth => (Start::FromTruth { hint_m: 1.0, hint_deg: 20.0 }, 2.0),
    };
    offline::run(
        inputs,
        Offline {
            out: out.to_path_buf(),
            frames_every: args.frames_every,
            camera: truth.mount.camera.clone(),
            lidar_t_camera: truth.mount.lidar_t_camera,
            start,
            start_gate_m,
            confirm_first_s: starc_pipeline::mission::CONFIRM_FIRST_S,
            coverage: !args.no_coverage,
            robot: robot_config(args)?,
            rig_align: super::align::rig_align_config(args.align_config.as_deref())?,
            rig_lio: super::lio::rig_lio_config(args.rig_lio_config.as_deref())?,
            truth: Some(truth),
            wall_timing: !args.no_wall_timing,
            align: !args.no_align,
        },
    )?;
    Ok(())
}

fn robot_config(args: &Args) -> anyhow::Result<RobotCoreConfig> {
    let mut cfg = RobotCoreConfig {
        detect: args.detector.config()?,
        floor_grid_ray_stride: FLOOR_GRID_RAY_STRIDE,
        ..RobotCoreConfig::default()
    };
    if let Some(h) = args.walker_min_height_m {
        cfg.walker_min_height_m = h;
    }
    Ok(cfg)
}

fn mission_live(dir: &Path, out: &Path, args: &Args) -> anyhow::Result<()> {
    let opts = super::sim_live::LiveOptions {
        out: out.to_path_buf(),
        frames_every: args.frames_every,
        start_hint: match args.hint {
            Hint::None => None,
            Hint::Truth => Some((1.0, 20.0)),
        },
        start_gate_m: 2.0,
        confirm_first_s: starc_pipeline::mission::CONFIRM_FIRST_S,
        view: starc_view::ViewConfig::default(),
        wheels: !args.no_wheels,
        detect: args.detector.config()?,
        ros2: None,
    };
    super::sim_live::run(dir, &opts)
}

/// The pcap, the point labels and the camera masks: the bulk of a run (about 250 MB for 30 s),
/// not needed once it is scored.
fn remove_bulk(dir: &Path) {
    for name in ["avia.pcap", "camera", "labels_robot.bin", "labels_fpv.bin"] {
        let p: PathBuf = dir.join(name);
        let _ = if p.is_dir() { std::fs::remove_dir_all(&p) } else { std::fs::remove_file(&p) };
    }
}
