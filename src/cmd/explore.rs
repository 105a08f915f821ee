//! `starc explore --seeds A..B [--duration-s S] [--out FILE.json]`: the explorer on generated
//! buildings, kinematic (the base moves exactly as commanded, at its true pose, scanned by an
//! idealised Avia; `starc_eval::explore_sim`), beside the scenario's scripted route scanned the
//! same way. Prints, per building, the floor each knows at the scripted route's end and at the
//! explorer's, contacts, and the explorer's time per control step. Seeds 1000 and up are the
//! test set: report them, never tune on them.

use super::eval::SeedRange;
use anyhow::Context;
use starc_eval::explore_sim::{area_at, explore_kinematic, scripted_kinematic, KinematicConfig, KinematicRun};
use starc_eval::quantiles::quantiles;
use starc_hil::gen;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    /// Seeds, both ends included. 1000 and up: the test set.
    #[arg(long)]
    seeds: SeedRange,
    /// flat, office, warehouse, hall, lab, or any (each seed's own family).
    #[arg(long, default_value = "any")]
    family: super::gen::FamilyChoice,
    /// The explorer's time limit per building (s).
    #[arg(long, default_value_t = 180.0)]
    duration_s: f64,
    /// Also write every building's runs as JSON.
    #[arg(long)]
    out: Option<PathBuf>,
}

#[derive(serde::Serialize)]
struct Building {
    seed: u64,
    name: String,
    scripted: KinematicRun,
    explorer: KinematicRun,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    anyhow::ensure!(args.duration_s.is_finite() && args.duration_s > 0.0, "--duration-s must be positive");
    let cfg = KinematicConfig { duration_s: args.duration_s, ..KinematicConfig::default() };
    let mut rows = Vec::new();
    let n = args.seeds.last - args.seeds.first + 1;
    for (i, seed) in (args.seeds.first..=args.seeds.last).enumerate() {
        let g = gen::generate(seed, args.family.0)?;
        let (Some(scripted), Some(explorer)) =
            (scripted_kinematic(&g.scenario, &cfg), explore_kinematic(&g.scenario, &cfg))
        else {
            anyhow::bail!("{}: no robot start, or a grid the settings cannot make", g.scenario.name);
        };
        let end = scripted.timeline.last().map_or(0.0, |t| t.0);
        let step = quantiles(&explorer.step_ms);
        eprintln!(
            "[{}/{n}] {}: scripted {:.1} m² in {end:.0} s; explorer {:.1} m² by then, {:.1} m² {} ({:.0} m driven, {} given up); contacts {} / {}; step p50 {:.2} ms, max {:.1} ms",
            i + 1,
            g.scenario.name,
            scripted.final_area_m2,
            area_at(&explorer, end).unwrap_or(f64::NAN),
            explorer.final_area_m2,
            explorer.done_s.map_or(format!("at {:.0} s (time up)", args.duration_s), |t| format!("done at {t:.0} s")),
            explorer.distance_m,
            explorer.blacklisted,
            scripted.contacts,
            explorer.contacts,
            step.p50,
            step.max,
        );
        rows.push(Building { seed, name: g.scenario.name.clone(), scripted, explorer });
    }
    summarise(&rows);
    if let Some(out) = &args.out {
        std::fs::write(out, serde_json::to_string_pretty(&rows)?)
            .with_context(|| format!("writing {}", out.display()))?;
    }
    Ok(())
}

/// Medians over the buildings, and the explorer's time per step over all of them.
fn summarise(rows: &[Building]) {
    let med = |f: &dyn Fn(&Building) -> f64| quantiles(&rows.iter().map(f).collect::<Vec<_>>()).p50;
    let at_scripted_end =
        |b: &Building| area_at(&b.explorer, b.scripted.timeline.last().map_or(0.0, |t| t.0)).unwrap_or(f64::NAN);
    let ratio = |b: &Building| b.explorer.final_area_m2 / b.scripted.final_area_m2.max(1e-9);
    let steps: Vec<f64> = rows.iter().flat_map(|b| b.explorer.step_ms.iter().copied()).collect();
    let q = quantiles(&steps);
    println!(
        "{} buildings: known floor, median: scripted route {:.1} m²; explorer {:.1} m² at the route's end, {:.1} m² at its own ({:.2} x the route's); explorer done in {} ({}); contacts: scripted {}, explorer {}; explorer step p50 {:.2} ms, p99 {:.2} ms, max {:.1} ms",
        rows.len(),
        med(&|b| b.scripted.final_area_m2),
        med(&at_scripted_end),
        med(&|b| b.explorer.final_area_m2),
        med(&ratio),
        rows.iter().filter(|b| b.explorer.done_s.is_some()).count(),
        format_args!("median {:.0} s", med(&|b| b.explorer.done_s.unwrap_or(f64::NAN))),
        rows.iter().map(|b| b.scripted.contacts).sum::<usize>(),
        rows.iter().map(|b| b.explorer.contacts).sum::<usize>(),
        q.p50,
        q.p99,
        q.max,
    );
}

/// What a loop run (`starc sim --explore` or `--measure-route`) came to, in a few lines.
pub fn print_loop(r: &starc_eval::explore_loop::LoopReport) {
    let coverage = r.coverage.last().map_or(0.0, |c| c.1 * 100.0);
    println!(
        "  {}: {:.1} m² of floor known, {coverage:.0} % of the {:.1} m² reachable{}",
        if r.mode == "scripted" { "scripted route" } else { "explorer" },
        r.final_area_m2,
        r.reachable_m2,
        r.coverage_95_s.map_or(String::new(), |t| format!(" (95 % at {t:.0} s)")),
    );
    if r.mode == "scripted" {
        println!("  {:.1} m driven; contacts {} ({} checks of 50 ms)", r.distance_m, r.contacts, r.contact_periods);
        return;
    }
    println!(
        "  {:.1} m driven, {}, {} goal(s) given up; contacts {} ({} checks of 50 ms); control step p50 {:.2} ms, p99 {:.2} ms, max {:.1} ms",
        r.distance_m,
        r.done_s.map_or("still exploring at the end".to_string(), |t| format!("home and done at {t:.1} s")),
        r.blacklisted,
        r.contacts,
        r.contact_periods,
        r.step_ms.p50,
        r.step_ms.p99,
        r.step_ms.max,
    );
    println!(
        "  base over slcan: {} frames sent, {} feedback frames received, {} fault(s) latched",
        r.bus.frames_sent, r.bus.feedback_frames, r.base_faults
    );
}
