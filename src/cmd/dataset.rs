//! `starc dataset --seeds A..B --out DIR`: the learned detector's training data from generated
//! buildings (docs/pillars.md): each building simulated (no camera), the robot's core run over
//! it, and every third detection window written with its true people under DIR/<family>-<seed>/
//! (with `--clusters`, also every cluster the geometric detector judges there, for the trees).
//! Seeds from 1000 up are the test set: exported only with `--test-set`, for reporting.

use anyhow::{bail, Context};
use starc_eval::dataset::{export_building, BuildingTruth, ExportOptions, Exported};
use starc_hil::gen;
use starc_hil::sim::run::{run as run_sim, SimOptions, FPV_AVIA_IP, ROBOT_AVIA_IP};
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

#[derive(clap::Args)]
pub struct Args {
    /// Seeds, both ends included (`0..59` is 60 buildings).
    #[arg(long)]
    seeds: super::eval::SeedRange,
    /// flat, office, warehouse, hall, lab, or any (each seed's own family): one family's
    /// buildings only, to give a family the training has seen too little of more examples.
    #[arg(long, default_value = "any")]
    family: super::gen::FamilyChoice,
    #[arg(long)]
    out: PathBuf,
    /// Every Nth detection window (3: windows that share no scan).
    #[arg(long, default_value_t = 3)]
    every: usize,
    /// Allow test seeds (1000 and up): for measuring on them, never for training.
    #[arg(long)]
    test_set: bool,
    /// Buildings at once (default: one per core).
    #[arg(long)]
    jobs: Option<usize>,
    /// Cut each building's run at this many simulated seconds (smoke tests).
    #[arg(long)]
    max_duration: Option<f64>,
    /// Also write clusters.npy: every cluster the geometric detector judges in each window, with
    /// the learned scorer's inputs and the truth (scripts/train/cluster_trees.py trains on it).
    #[arg(long)]
    clusters: bool,
    /// Leave out the windows' points, labels and boxes (the PointPillars data; about 120 MB a
    /// building): with --clusters, only clusters.npy.
    #[arg(long, requires = "clusters")]
    no_points: bool,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let super::eval::SeedRange { first, last } = args.seeds;
    if gen::is_test_seed(last) && !args.test_set {
        bail!("--seeds {first}..{last} reaches the test set (1000 and up): add --test-set to export it for measuring");
    }
    if !gen::is_test_seed(first) && gen::is_test_seed(last) {
        bail!("--seeds {first}..{last} mixes development and test seeds: export them apart");
    }
    std::fs::create_dir_all(&args.out).with_context(|| format!("creating {}", args.out.display()))?;
    let seeds: Vec<u64> = (first..=last).collect();
    let started = Instant::now();
    let (next, done, failed) = (AtomicUsize::new(0), AtomicUsize::new(0), AtomicUsize::new(0));
    let jobs = args.jobs.unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get())).max(1);
    std::thread::scope(|scope| {
        for _ in 0..jobs.min(seeds.len()) {
            scope.spawn(|| {
                while let Some(&seed) = seeds.get(next.fetch_add(1, Ordering::Relaxed)) {
                    let t0 = Instant::now();
                    let what = match one_building(&args, seed) {
                        Ok((name, e)) => format!(
                            "{name}: {} windows, {} points, {} boxes ({} visible), {} clusters",
                            e.windows, e.points, e.boxes, e.visible_boxes, e.clusters
                        ),
                        Err(e) => {
                            failed.fetch_add(1, Ordering::Relaxed);
                            format!("seed {seed} failed: {e:#}")
                        }
                    };
                    let n = done.fetch_add(1, Ordering::Relaxed) + 1;
                    let elapsed = started.elapsed().as_secs_f64();
                    let eta = elapsed / n as f64 * (seeds.len() - n) as f64;
                    eprintln!("[{n}/{}] {:.0} s, eta {eta:.0} s: {what}", seeds.len(), t0.elapsed().as_secs_f64());
                    let _ = std::io::stderr().flush();
                }
            });
        }
    });
    let failed = failed.into_inner();
    println!(
        "{} buildings ({failed} failed) in {:.0} s into {}",
        seeds.len(),
        started.elapsed().as_secs_f64(),
        args.out.display()
    );
    if failed > 0 {
        bail!("{failed} buildings failed");
    }
    Ok(())
}

fn one_building(args: &Args, seed: u64) -> anyhow::Result<(String, Exported)> {
    let g = gen::generate(seed, args.family.0)?;
    let name = format!("{}-{seed}", g.family);
    let sim_dir = args.out.join("sim").join(&name);
    std::fs::create_dir_all(&sim_dir).with_context(|| format!("creating {}", sim_dir.display()))?;
    let duration_s = args.max_duration.map(|m| m.min(g.scenario.duration_s));
    let opts = SimOptions { out: sim_dir.clone(), duration_s, seed, realtime: false, camera: false };
    run_sim(&g.scenario, &g.text, &opts, &mut |_, _| {}).with_context(|| format!("simulating {name}"))?;
    let truth = BuildingTruth::load(&sim_dir)?;
    let mut inputs = starc_bridge::from_capture(&sim_dir.join("avia.pcap"), ROBOT_AVIA_IP, FPV_AVIA_IP)?;
    inputs =
        starc_bridge::wheels::with_wheels(inputs, super::sim::wheel_samples(&sim_dir, g.scenario.robot.get_ref())?);
    let export_opts = ExportOptions {
        every: args.every,
        points: !args.no_points,
        clusters: args.clusters,
        ..ExportOptions::default()
    };
    let out = args.out.join(&name);
    let exported = export_building(inputs, &truth, &export_opts, &out)?;
    write_meta(&out, seed, &g.family.to_string(), args.every, &exported)?;
    std::fs::remove_dir_all(&sim_dir).with_context(|| format!("removing {}", sim_dir.display()))?;
    Ok((name, exported))
}

fn write_meta(out: &Path, seed: u64, family: &str, every: usize, e: &Exported) -> anyhow::Result<()> {
    let set = if gen::is_test_seed(seed) { "test" } else { "development" };
    let meta = serde_json::json!({ "seed": seed, "family": family, "set": set, "counts": e, "every": every });
    let path: PathBuf = out.join("meta.json");
    std::fs::write(&path, serde_json::to_string_pretty(&meta)?).with_context(|| format!("writing {}", path.display()))
}
