//! `starc sim SCENARIO --out DIR`: runs a scenario's simulated sensors through the mock devices,
//! writes the Avia pcap and the ground truth, then runs the see-through mission on it live: mock
//! Avias play the run back over their real protocol to the robot and rig nodes, linked over
//! zenoh on loopback (`sim_live.rs`), into DIR/mission. `--offline` runs the mission in one
//! process instead (`mission.rs`); `--sensors-only` (or `--no-camera`) stops after the sensors.

use anyhow::Context;
use starc_eval::explore_loop::{ExploreLoop, LoopConfig};
use starc_hil::sim::run::{run_driven, RobotDriver, SimOptions};
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
    /// Only simulate the sensors (no mission).
    #[arg(long)]
    sensors_only: bool,
    /// Run the mission offline, in one process without nodes or link (`starc mission DIR`).
    #[arg(long)]
    offline: bool,
    /// Live mission: serve the rig's AR view in a browser here (e.g. 127.0.0.1:8080).
    #[arg(long)]
    http: Option<std::net::SocketAddr>,
    /// Live mission: serve the Foxglove WebSocket view here (e.g. 127.0.0.1:8765).
    #[arg(long)]
    foxglove: Option<std::net::SocketAddr>,
    /// A file holding the token viewers must present (`openssl rand -hex 16 > FILE`); required
    /// when --http or --foxglove binds beyond loopback. A file, so the token is not in `ps`.
    #[arg(long, value_name = "FILE")]
    view_token_file: Option<std::path::PathBuf>,
    /// Write every Nth camera frame's AR view as PNG (0: none).
    #[arg(long, default_value_t = 5)]
    frames_every: u64,
    /// Live mission: give the rig node a start hint from the simulator's truth, its true start
    /// moved this far (m) and turned `--start-hint-deg`, and refuse first alignments more than
    /// `--start-gate-m` from it (as an operator's marked entry would). Default: no hint, the
    /// rig searches the whole map, as in a scored run.
    #[arg(long)]
    start_hint_m: Option<f64>,
    #[arg(long, default_value_t = 20.0)]
    start_hint_deg: f64,
    #[arg(long, default_value_t = 2.0)]
    start_gate_m: f64,
    /// Apply the rig's first alignment once searches have found it again over this long (s;
    /// 0: the first accepted one at once).
    #[arg(long, default_value_t = starc_pipeline::mission::CONFIRM_FIRST_S)]
    confirm_first_s: f64,
    /// Live mission: both nodes publish their topics to the ROS 2 (rmw_zenoh) router at this
    /// zenoh endpoint (`tcp/127.0.0.1:7447`, `rmw_zenohd`'s default; docs/ros2.md).
    #[arg(long, value_name = "ENDPOINT")]
    ros2: Option<String>,
    /// The explorer drives the robot instead of its scripted waypoints: the robot's LIO and
    /// the explorer run in the loop, the base driver sends their twist over CAN (slcan bytes)
    /// to the mock motor controllers, and the robot moves as its motors turn
    /// (docs/explore.md). Writes DIR/exploration.json, which the mission's report.json
    /// carries under `exploration.closed_loop`.
    #[arg(long, conflicts_with = "measure_route")]
    explore: bool,
    /// The robot follows its scripted waypoints, measured as --explore measures the explorer
    /// (its LIO in the loop, the same grid, the reachable floor's coverage, contacts), into
    /// DIR/exploration.json: the baseline to compare the explorer with.
    #[arg(long)]
    measure_route: bool,
    /// With --explore: the base driver's settings (config/base.toml's form); its kinematics,
    /// protocol and wheel ids are set to the simulated base's. Default: the shipped file.
    #[arg(long)]
    base_config: Option<PathBuf>,
    #[command(flatten)]
    detector: super::detector_arg::DetectorArgs,
}

/// The shipped base driver settings (--explore's template).
const BASE_TOML: &str = include_str!("../../config/base.toml");

/// The closed loop `--explore` asks for, or none.
fn explore_loop(args: &Args, scenario: &Scenario) -> anyhow::Result<Option<ExploreLoop>> {
    if !(args.explore || args.measure_route) {
        anyhow::ensure!(args.base_config.is_none(), "--base-config is for --explore");
        return Ok(None);
    }
    let text = match &args.base_config {
        Some(path) => std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?,
        None => BASE_TOML.to_string(),
    };
    let template = starc_base::BaseConfig::from_toml(&text).context("--base-config")?;
    let cfg = LoopConfig {
        scripted: args.measure_route,
        ..LoopConfig::for_robot(scenario.robot.get_ref(), template, args.seed)
    };
    Ok(Some(ExploreLoop::new(scenario, cfg)?))
}

/// The live views `--http`, `--foxglove` and `--view-token-file` ask for, checked before any
/// simulating: a bind beyond loopback without a token is refused here, not minutes later.
fn views(args: &Args) -> anyhow::Result<starc_view::ViewConfig> {
    let token = match &args.view_token_file {
        Some(path) => {
            let text = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
            Some(
                starc_view::ViewToken::new(text.trim())
                    .with_context(|| format!("--view-token-file {}", path.display()))?,
            )
        }
        None => None,
    };
    let view =
        starc_view::ViewConfig { http_bind: args.http, foxglove_bind: args.foxglove, token, ..Default::default() };
    view.validate().context("--http / --foxglove")?;
    Ok(view)
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let view = views(&args)?;
    if args.list {
        for (name, text) in SHIPPED {
            let s = Scenario::parse(text, name)?;
            println!("{name:12} {}", s.description);
        }
        return Ok(());
    }
    if args.offline && (args.no_camera || args.sensors_only) {
        anyhow::bail!(
            "--offline runs the mission, which scores the camera frames: leave out --no-camera and --sensors-only"
        );
    }
    let (scenario, text) = Scenario::load(&args.scenario)?;
    let mut blocked = starc_hil::sim::route_check::check_routes(&scenario);
    if args.explore {
        // The explorer chooses the robot's way; only the others' scripted routes must be clear.
        blocked.retain(|v| v.mover != starc_hil::sim::route_check::Mover::Robot);
    }
    if !blocked.is_empty() {
        let lines: Vec<String> = blocked.iter().map(|v| format!("  {v}")).collect();
        anyhow::bail!("{}: a route runs into something:\n{}", args.scenario, lines.join("\n"));
    }
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
    let mut driver = explore_loop(&args, &scenario)?;
    let summary =
        run_driven(&scenario, &text, &opts, driver.as_mut().map(|d| d as &mut dyn RobotDriver), &mut progress)
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
    let exploration_json = args.out.join("exploration.json");
    match driver.map(|d| d.report()) {
        Some(r) => {
            super::explore::print_loop(&r);
            std::fs::write(&exploration_json, serde_json::to_string_pretty(&r)?)
                .with_context(|| format!("writing {}", exploration_json.display()))?;
        }
        // A scripted run into a directory an explored one used: its mission must not read that.
        None if exploration_json.exists() => std::fs::remove_file(&exploration_json)
            .with_context(|| format!("removing the old {}", exploration_json.display()))?,
        None => {}
    }
    println!("  wrote {}", args.out.display());
    if args.offline {
        super::mission::run(super::mission::Args {
            dir: args.out.clone(),
            out: None,
            frames_every: args.frames_every,
            start_hint_m: args.start_hint_m,
            start_hint_deg: args.start_hint_deg,
            start_gate_m: args.start_gate_m,
            confirm_first_s: args.confirm_first_s,
            no_coverage: false,
            walker_min_height_m: None,
            no_wheels: false,
            align_config: None,
            rig_lio_config: None,
            detector: args.detector.clone(),
        })?;
    } else if !args.sensors_only && !args.no_camera {
        let opts = super::sim_live::LiveOptions {
            out: args.out.join("mission"),
            frames_every: args.frames_every,
            start_hint: args.start_hint_m.map(|m| (m, args.start_hint_deg)),
            start_gate_m: args.start_gate_m,
            confirm_first_s: args.confirm_first_s,
            view,
            detect: args.detector.config()?,
            wheels: true,
            ros2: args.ros2.clone(),
        };
        super::sim_live::run(&args.out, &opts)?;
    }
    Ok(())
}

/// The wheel odometry of a `starc sim` run's directory, decoded with the base its
/// scenario.toml describes.
pub fn run_wheel_samples(dir: &std::path::Path) -> anyhow::Result<Vec<starc_pipeline::lio::WheelSample>> {
    let base = starc_eval::wheels::run_wheel_feedback(dir)?;
    Ok(starc_eval::wheels::run_wheel_samples(dir, &base)?)
}

/// The simulated base's wheel odometry from a run's `robot_can.log`, decoded with the
/// scenario's wheel layout and motor controllers (its log is on the Avias' PTP clock).
pub fn wheel_samples(
    dir: &std::path::Path,
    robot: &starc_hil::sim::scenario::Robot,
) -> anyhow::Result<Vec<starc_pipeline::lio::WheelSample>> {
    let base = starc_eval::wheels::sim_wheel_feedback(robot);
    Ok(starc_eval::wheels::run_wheel_samples(dir, &base)?)
}
