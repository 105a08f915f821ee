//! `starc gen --seed N --out FILE.toml [--family F|any]`: writes a generated building as an
//! ordinary scenario file that `starc sim` runs. Seeds below 1000 are for development; 1000 and
//! up are the held-out test set (docs/eval.md).

use anyhow::Context;
use starc_hil::gen::{self, Family};
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    /// The building's seed: the same seed and family give the same file.
    #[arg(long)]
    seed: u64,
    /// Where to write the scenario file.
    #[arg(long)]
    out: PathBuf,
    /// flat, office, warehouse, hall, lab, or any (the seed's own family).
    #[arg(long, default_value = "any")]
    family: FamilyChoice,
    /// Also draw the floor plan, people and routes, top down, as SVG.
    #[arg(long)]
    svg: Option<PathBuf>,
}

/// A family, or `any`.
#[derive(Clone, Copy, Debug)]
pub struct FamilyChoice(pub Option<Family>);

impl std::str::FromStr for FamilyChoice {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        if s == "any" {
            return Ok(FamilyChoice(None));
        }
        s.parse().map(|f| FamilyChoice(Some(f)))
    }
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let g = gen::generate(args.seed, args.family.0)?;
    if let Some(dir) = args.out.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    std::fs::write(&args.out, &g.text).with_context(|| format!("writing {}", args.out.display()))?;
    if let Some(svg) = &args.svg {
        let picture = starc_hil::sim::plan_svg::plan_svg(&g.scenario);
        std::fs::write(svg, picture).with_context(|| format!("writing {}", svg.display()))?;
    }
    let set = if gen::is_test_seed(args.seed) { "test" } else { "development" };
    println!(
        "{}: {} seed {} ({set} set), {} people, {:.0} s; wrote {}",
        g.scenario.name,
        g.family,
        args.seed,
        g.people,
        g.scenario.duration_s,
        args.out.display()
    );
    Ok(())
}
