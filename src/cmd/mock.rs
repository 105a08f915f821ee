//! `starc mock`: mock devices that speak the real wire protocols.
//!
//! `starc mock avia` runs a Livox Avia on a loopback (or any local) address: it broadcasts, takes
//! a handshake, answers every control command, and streams points and IMU at the real rates from
//! a synthetic room or a capture, with optional faults. Ctrl-C (or `--duration`) stops it and
//! prints its counters.

use anyhow::Context;
use starc_hil::avia::{MockAvia, MockAviaConfig, MockStats, ReturnSetting, SourceConfig, TimeSource, TimeSourceSwitch};
use std::net::{Ipv4Addr, SocketAddrV4};
use std::path::PathBuf;
use std::time::Duration;

#[derive(clap::Subcommand)]
pub enum Command {
    /// A mock Livox Avia: broadcast, handshake, every command, points and IMU at the real rates.
    Avia(AviaArgs),
    /// Mock motor controllers (DJI C620 or CiA 402) behind an slcan adapter on a pty, with faults.
    Motors(super::base::MockArgs),
    /// A mock serial IMU (MicroStrain MIP or WitMotion) on a pty: streams, answers MIP commands
    /// and WitMotion config writes, with optional faults.
    Imu(super::imu::MockArgs),
}

#[derive(clap::Args)]
pub struct AviaArgs {
    /// A TOML mock config (the fields of `MockAviaConfig`); flags override it.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Address to bind: commands on :65000, points from :60001, IMU from :60003 [default: 127.0.0.1].
    #[arg(long)]
    pub ip: Option<Ipv4Addr>,
    /// Broadcast code, at most 16 characters [default: STARCMOCK + 6 digits from the ip].
    #[arg(long)]
    pub code: Option<String>,
    /// `synthetic` (a room with a box) or the path of a pcap, pcapng or .lvx capture to replay.
    #[arg(long)]
    pub source: Option<SourceConfig>,
    /// Where broadcasts go [default: 127.0.0.1:55000]; 255.255.255.255:55000 only inside a
    /// network namespace of your own.
    #[arg(long)]
    pub broadcast_to: Option<SocketAddrV4>,
    /// single, dual or triple [default: single].
    #[arg(long)]
    pub return_mode: Option<ReturnSetting>,
    /// Packet time stamps: none, ptp, gps or pps [default: ptp].
    #[arg(long)]
    pub time_source: Option<TimeSource>,
    /// Seed of the synthetic scene and of the faults [default: 0].
    #[arg(long)]
    pub seed: Option<u64>,
    /// Fraction of data/IMU packets dropped.
    #[arg(long)]
    pub drop: Option<f64>,
    /// Fraction of data/IMU packets sent twice.
    #[arg(long)]
    pub duplicate: Option<f64>,
    /// Fraction of data/IMU packets swapped with the next one.
    #[arg(long)]
    pub reorder: Option<f64>,
    /// Fraction of data/IMU packets with 1-3 bytes flipped.
    #[arg(long)]
    pub corrupt: Option<f64>,
    /// Stop answering heartbeats S seconds after each handshake (0: never answer).
    #[arg(long, value_name = "S")]
    pub no_heartbeat_after: Option<f64>,
    /// Switch the time stamp source S seconds after start, e.g. `5:gps`.
    #[arg(long, value_name = "S:SRC")]
    pub switch_time_source_after: Option<TimeSourceSwitch>,
    /// Stop after S seconds [default: run until Ctrl-C].
    #[arg(long, value_name = "S")]
    pub duration: Option<f64>,
    /// Print the final counters as JSON.
    #[arg(long)]
    pub json: bool,
}

impl AviaArgs {
    fn config(&self) -> anyhow::Result<MockAviaConfig> {
        let mut c = match &self.config {
            Some(path) => {
                let text = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
                toml::from_str(&text).with_context(|| format!("parsing {}", path.display()))?
            }
            None => MockAviaConfig::default(),
        };
        if let Some(ip) = self.ip {
            c.ip = ip;
        }
        if let Some(code) = &self.code {
            c.broadcast_code = Some(code.clone());
        }
        if let Some(source) = &self.source {
            c.source = source.clone();
        }
        if let Some(to) = self.broadcast_to {
            c.broadcast_to = to;
        }
        if let Some(mode) = self.return_mode {
            c.return_mode = mode;
        }
        if let Some(source) = self.time_source {
            c.time_source = source;
        }
        if let Some(seed) = self.seed {
            c.seed = seed;
        }
        let f = &mut c.faults;
        for (flag, field) in [
            (self.drop, &mut f.drop),
            (self.duplicate, &mut f.duplicate),
            (self.reorder, &mut f.reorder),
            (self.corrupt, &mut f.corrupt),
        ] {
            if let Some(v) = flag {
                *field = v;
            }
        }
        if let Some(s) = self.no_heartbeat_after {
            f.no_heartbeat_after_s = Some(s);
        }
        if let Some(sw) = self.switch_time_source_after {
            f.switch_time_source = Some(sw);
        }
        c.validate()?;
        Ok(c)
    }
}

pub fn run(command: Command) -> anyhow::Result<()> {
    match command {
        Command::Avia(args) => avia(args),
        Command::Motors(args) => super::base::mock(args),
        Command::Imu(args) => super::imu::mock(args),
    }
}

fn avia(args: AviaArgs) -> anyhow::Result<()> {
    let config = args.config()?;
    let duration = match args.duration {
        Some(s) if s.is_finite() && s > 0.0 => Some(Duration::from_secs_f64(s)),
        Some(s) => anyhow::bail!("--duration {s}: must be a positive number of seconds"),
        None => None,
    };
    let runtime = tokio::runtime::Builder::new_current_thread().enable_all().build()?;
    let (stats, elapsed) = runtime.block_on(async move {
        let started = tokio::time::Instant::now();
        let mock = MockAvia::spawn(config).await?;
        let stopped = async {
            match duration {
                Some(d) => tokio::time::sleep(d).await,
                None => std::future::pending().await,
            }
        };
        tokio::select! {
            signal = tokio::signal::ctrl_c() => signal.context("waiting for Ctrl-C")?,
            _ = stopped => {}
        }
        let code = mock.broadcast_code();
        let stats = mock.stop().await?;
        anyhow::Ok(((code, stats), started.elapsed()))
    })?;
    let (code, stats) = stats;
    if args.json {
        let value = serde_json::json!({
            "broadcast_code": code.text(),
            "seconds": elapsed.as_secs_f64(),
            "stats": stats,
        });
        println!("{}", serde_json::to_string_pretty(&value)?);
    } else {
        print_stats(&code.text(), elapsed, &stats);
    }
    Ok(())
}

fn print_stats(code: &str, elapsed: Duration, s: &MockStats) {
    let d = &s.device;
    println!("{code}: ran {:.1} s", elapsed.as_secs_f64());
    println!(
        "  sent       {} point packets, {} imu packets, {} datagrams, {} bytes, {} send errors",
        d.point_packets, d.imu_packets, s.datagrams_sent, s.bytes_sent, s.send_errors
    );
    println!(
        "  control    {} commands, {} answered, {} refused, {} heartbeats ({} unanswered), {} broadcasts, {} status pushes",
        d.commands, d.answered, d.refused, d.heartbeats, d.heartbeats_unanswered, d.broadcasts, d.status_pushes
    );
    println!(
        "  dropped    {} crc errors, {} malformed, {} ignored; {} connections, {} hosts lost",
        d.crc_errors, d.malformed, d.ignored, d.connections, d.host_losses
    );
    println!(
        "  faults     {} dropped, {} duplicated, {} reordered, {} corrupted; {} packets skipped late",
        d.faults.dropped, d.faults.duplicated, d.faults.reordered, d.faults.corrupted, d.stream.skipped_packets
    );
}
