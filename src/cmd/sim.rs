//! `starc sim SCENARIO --out DIR`: runs a scenario's simulated sensors through the mock devices
//! and writes the Avia pcap and the ground truth; with `--mission`, runs the see-through mission
//! on it (see `mission.rs`).

use anyhow::Context;
use starc_hil::sim::run::{run as run_sim, SimOptions};
use starc_hil::sim::scenario::{Scenario, SHIPPED};
use std::io::Write;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    /// A shipped scenario (lab, auditorium, tactical, corridor) or a scenario file.
    scenario: String,
    /// Output directory (created if missing; files in it are overwritten).
    #[arg(long)]
    out: PathBuf,
    /// Simulated seconds (default: the scenario's duration_s).
    #[arg(long)]
    duration: Option<f64>,
    /// Seed of every noise source; the same seed gives the same bytes.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Pace the simulation to the wall clock instead of running as fast as possible.
    #[arg(long)]
    realtime: bool,
    /// Skip the camera masks.
    #[arg(long)]
    no_camera: bool,
    /// List the shipped scenarios and exit.
    #[arg(long)]
    list: bool,
    /// Then run the see-through mission on the run (`starc mission DIR`): both LIOs, detection,
    /// alignment, AR frames and DIR/mission/report.json.
    #[arg(long)]
    mission: bool,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    if args.list {
        for (name, text) in SHIPPED {
            let s = Scenario::parse(text, name)?;
            println!("{name:12} {}", s.description);
        }
        return Ok(());
    }
    if args.mission && args.no_camera {
        anyhow::bail!("--mission scores the camera frames: leave out --no-camera");
    }
    let (scenario, text) = Scenario::load(&args.scenario)?;
    let opts = SimOptions {
        out: args.out.clone(),
        duration_s: args.duration,
        seed: args.seed,
        realtime: args.realtime,
        camera: !args.no_camera,
    };
    let interactive = std::io::IsTerminal::is_terminal(&std::io::stderr());
    let mut last_whole = -1i64;
    let mut progress = |done: f64, total: f64| {
        let whole = done.floor() as i64;
        if whole == last_whole {
            return;
        }
        last_whole = whole;
        let width = 30usize;
        let filled = ((done / total).clamp(0.0, 1.0) * width as f64) as usize;
        if interactive {
            eprint!("\r[{}{}] {done:5.1} / {total:.1} s simulated", "#".repeat(filled), " ".repeat(width - filled));
            let _ = std::io::stderr().flush();
        } else if whole % 5 == 0 {
            eprintln!("{done:.0} / {total:.0} s simulated");
        }
    };
    let summary = run_sim(&scenario, &text, &opts, &mut progress)
        .with_context(|| format!("simulating {} into {}", scenario.name, args.out.display()))?;
    if interactive {
        eprintln!();
    }
    println!(
        "{}: {:.1} s simulated in {:.2} s ({:.1}x real time), {} rays, {} pcap records, {} camera frames",
        summary.scenario,
        summary.duration_s,
        summary.wall_s,
        summary.realtime_factor,
        summary.rays_cast,
        summary.pcap_records,
        summary.camera_frames
    );
    for d in &summary.devices {
        println!(
            "  {:5} Avia {} -> host {}: on at {:.1} s, {} point + {} IMU packets, {} returns ({} on people)",
            d.name,
            d.avia_ip,
            d.host_ip,
            d.power_on_s,
            d.link.point_packets,
            d.link.imu_packets,
            d.returns,
            d.person_returns
        );
    }
    println!("  wrote {}", args.out.display());
    if args.mission {
        super::mission::run(super::mission::Args {
            dir: args.out.clone(),
            out: None,
            frames_every: 5,
            start_hint_m: 1.0,
            start_hint_deg: 20.0,
            start_gate_m: 2.0,
        })?;
    }
    Ok(())
}
