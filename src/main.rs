//! `starc`: the one command-line program of STARC.

mod cmd;

use clap::{Parser, Subcommand};
use std::process::ExitCode;

#[derive(Parser)]
#[command(name = "starc", version, about = "STARC: see people behind walls (drivers, mock devices, pipeline)")]
struct Cli {
    /// Log filter in RUST_LOG syntax (also read from RUST_LOG).
    #[arg(long, global = true, default_value = "info")]
    log: String,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run an Avia mock device and the live driver against each other on loopback (no hardware
    /// needed).
    Demo(cmd::demo::Args),
    /// List the Livox devices on the network.
    Devices(cmd::devices::Args),
    /// Livox device tools.
    #[command(subcommand)]
    Livox(cmd::livox::Command),
    /// Serial IMU tools (MicroStrain MIP, WitMotion).
    #[command(subcommand)]
    Imu(cmd::imu::Command),
    /// Mock devices that speak the real wire protocols.
    #[command(subcommand)]
    Mock(cmd::mock::Command),
    /// Summarize a capture (pcap, pcapng, .lvx) of Livox traffic.
    Inspect(cmd::inspect::Args),
    /// Send a capture's packets to a UDP socket with their original timing.
    Replay(cmd::replay::Args),
    /// Rerun the mission's pipeline on the nodes' MCAP recordings (offline, in time order).
    Rerun(cmd::rerun::Args),
    /// Write the scans of a capture as point-cloud files.
    Export(cmd::export::Args),
    /// Simulate a scenario and run the see-through mission on it live: mock devices, the robot
    /// and rig nodes, the link on loopback; report.json, recordings, AR frames, plots.
    Sim(cmd::sim::Args),
    /// Generate a building (flat, office, warehouse, hall, lab) as a scenario file.
    Gen(cmd::gen::Args),
    /// The explorer on generated buildings, kinematic (ideal poses, an idealised Avia), beside
    /// the scripted route: floor known, contacts, time per control step.
    Explore(cmd::explore::Args),
    /// Run the mission on a range of generated buildings; eval.json, a summary and plots.
    Eval(cmd::eval::Args),
    /// The learned detector's training data from generated buildings (docs/pillars.md).
    Dataset(cmd::dataset::Args),
    /// PTP (IEEE 1588): a grandmaster for the LiDAR network, a measure-only slave.
    #[command(subcommand)]
    Ptp(cmd::ptp::Command),
    /// The omni-wheel base over CAN: status, keyboard teleop.
    #[command(subcommand)]
    Base(cmd::base::Command),
    /// Register a source cloud against a target cloud (NDT, then point-to-plane ICP).
    Align(cmd::align::Args),
    /// LiDAR-inertial odometry on a capture: a TUM trajectory, a map and timing per device.
    Lio(cmd::lio::Args),
    /// The see-through mission, offline, on a `starc sim` run: both LIOs, detection, alignment,
    /// projection, AR frames, and report.json scored against the truth.
    Mission(cmd::mission::Args),
    /// The robot node: its Avia, LIO, person detection, the map and detections to the rig.
    Robot(cmd::robot::Args),
    /// The responder's rig node: its Avia, LIO, alignment to the robot's map, the AR view.
    Fpv(cmd::fpv::Args),
    /// The robot-to-rig link: `certs` makes the private CA and certificates for mutual TLS.
    #[command(subcommand)]
    Link(cmd::link::Command),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let filter = std::env::var("RUST_LOG").unwrap_or_else(|_| cli.log.clone());
    tracing_subscriber::fmt()
        .with_env_filter(tracing_subscriber::EnvFilter::new(filter))
        .with_writer(std::io::stderr)
        .init();
    let result = match cli.command {
        Command::Demo(a) => cmd::demo::run(a),
        Command::Devices(a) => cmd::devices::run(a),
        Command::Livox(c) => cmd::livox::run(c),
        Command::Mock(c) => cmd::mock::run(c),
        Command::Imu(c) => cmd::imu::run(c),
        Command::Inspect(a) => cmd::inspect::run(a),
        Command::Replay(a) => cmd::replay::run(a),
        Command::Rerun(a) => cmd::rerun::run(a),
        Command::Export(a) => cmd::export::run(a),
        Command::Sim(a) => cmd::sim::run(a),
        Command::Gen(a) => cmd::gen::run(a),
        Command::Explore(a) => cmd::explore::run(a),
        Command::Eval(a) => cmd::eval::run(a),
        Command::Dataset(a) => cmd::dataset::run(a),
        Command::Ptp(c) => cmd::ptp::run(c),
        Command::Base(c) => cmd::base::run(c),
        Command::Align(a) => cmd::align::run(a),
        Command::Lio(a) => cmd::lio::run(a),
        Command::Mission(a) => cmd::mission::run(a),
        Command::Robot(a) => cmd::robot::run(a),
        Command::Fpv(a) => cmd::fpv::run(a),
        Command::Link(c) => cmd::link::run(c),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
