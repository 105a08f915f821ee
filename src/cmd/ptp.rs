//! `starc ptp`: a PTP grandmaster for the LiDAR network, and a slave that measures a master
//! against this host's clock without touching it (unless told to with `--adjust-clock`).
//!
//! Both print one line per second in ptp4l's words; see `starc_ptp::status` for the fields.

use anyhow::Context;
use starc_ptp::message::PortIdentity;
use starc_ptp::port::{Master, Port, Slave};
use starc_ptp::status;
use starc_ptp::transport::{
    run_port, AdjustTarget, ClockAdjuster, PtpSockets, TimestampMode, TransportConfig, TransportStats,
};
use starc_ptp::{LocalTimescale, PtpConfig};
use std::path::PathBuf;
use std::time::Duration;

#[derive(clap::Subcommand)]
pub enum Command {
    /// Be the grandmaster on an interface: Announce, two-step Sync + Follow_Up, Delay_Resp.
    Master(MasterArgs),
    /// Follow the best master on an interface and print offset, frequency and path delay.
    Slave(SlaveArgs),
}

#[derive(clap::Args)]
pub struct Common {
    /// The interface to run on (the LiDAR NIC, e.g. eth1).
    #[arg(long)]
    pub iface: String,
    /// PTP domain [default: 0, or the config's].
    #[arg(long)]
    pub domain: Option<u8>,
    /// Settings from a TOML file (see config/ptp.toml); flags override it.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Ask the NIC for hardware timestamps (falls back to software ones, saying so, when it
    /// has none). Hardware stamps are on the NIC's PTP clock, taken to count TAI.
    #[arg(long)]
    pub hw_timestamps: bool,
    /// Stop after this many seconds (0: run until Ctrl-C).
    #[arg(long, default_value_t = 0.0)]
    pub seconds: f64,
}

#[derive(clap::Args)]
pub struct MasterArgs {
    #[command(flatten)]
    pub common: Common,
    /// log2 of the Sync interval in seconds (-3: 8 per second) [default: 0].
    #[arg(long, allow_negative_numbers = true)]
    pub sync_interval: Option<i8>,
    /// log2 of the Announce interval in seconds [default: 0].
    #[arg(long, allow_negative_numbers = true)]
    pub announce_interval: Option<i8>,
    /// Send the host clock as-is (ARB timescale) instead of TAI with ptpTimescale.
    #[arg(long)]
    pub arb: bool,
}

#[derive(clap::Args)]
pub struct SlaveArgs {
    #[command(flatten)]
    pub common: Common,
    /// Measure only, never adjust a clock. This is the default; the flag exists so ptp4l
    /// habits (`--free_running 1`) carry over.
    #[arg(long, conflicts_with = "adjust_clock")]
    pub free_running: bool,
    /// Steer this clock with the servo: `realtime` (the system clock) or a PHC such as
    /// /dev/ptp0. Off by default; never use it where something else owns the clock.
    #[arg(long, value_name = "CLOCK")]
    pub adjust_clock: Option<AdjustTarget>,
    /// log2 of the Delay_Req interval until the master names its own [default: 0].
    #[arg(long, allow_negative_numbers = true)]
    pub delay_req_interval: Option<i8>,
}

pub fn run(command: Command) -> anyhow::Result<()> {
    match command {
        Command::Master(a) => master(a),
        Command::Slave(a) => slave(a),
    }
}

fn load(common: &Common) -> anyhow::Result<PtpConfig> {
    let mut cfg = match &common.config {
        Some(p) => PtpConfig::load(p)?,
        None => PtpConfig::default(),
    };
    if let Some(d) = common.domain {
        cfg.master.domain = d;
        cfg.slave.domain = d;
    }
    Ok(cfg)
}

fn transport(common: &Common) -> TransportConfig {
    let mut t = TransportConfig::on(&common.iface);
    if common.hw_timestamps {
        t.want = TimestampMode::Hardware;
    }
    t
}

fn port_identity(sockets: &PtpSockets) -> PortIdentity {
    PortIdentity { clock: sockets.iface.clock_identity(), port: 1 }
}

/// Runs until --seconds pass or Ctrl-C.
async fn stop_after(seconds: f64) {
    let ctrl_c = async {
        let _ = tokio::signal::ctrl_c().await;
    };
    if seconds > 0.0 {
        tokio::select! {
            _ = tokio::time::sleep(Duration::from_secs_f64(seconds)) => {}
            _ = ctrl_c => {}
        }
    } else {
        ctrl_c.await;
    }
}

fn local_timescale(mode: TimestampMode) -> LocalTimescale {
    match mode {
        TimestampMode::Software => LocalTimescale::Utc,
        TimestampMode::Hardware => LocalTimescale::Tai,
    }
}

fn master(args: MasterArgs) -> anyhow::Result<()> {
    let mut cfg = load(&args.common)?;
    if let Some(v) = args.sync_interval {
        cfg.master.log_sync_interval = v;
    }
    if let Some(v) = args.announce_interval {
        cfg.master.log_announce_interval = v;
    }
    if args.arb {
        cfg.master.ptp_timescale = false;
    }
    cfg.validate()?;
    super::runtime()?.block_on(async {
        let sockets = PtpSockets::open(&transport(&args.common)).context("opening the PTP sockets")?;
        cfg.master.local_timescale = local_timescale(sockets.mode);
        let identity = port_identity(&sockets);
        println!(
            "starc-ptp: grandmaster {identity} on {} ({} timestamps), domain {}, {} with UTC offset {} s",
            sockets.iface.name,
            sockets.mode.name(),
            cfg.master.domain,
            if cfg.master.ptp_timescale { "PTP timescale (TAI)" } else { "ARB timescale" },
            cfg.master.utc_offset_s
        );
        let port = Port::Master(Master::new(cfg.master.clone(), identity));
        let on_status = |port: &Port, _t: &TransportStats| {
            if let Port::Master(m) = port {
                println!("{}", status::master_line(status::uptime_s(), &m.stats()));
            }
        };
        let (port, stats) = run_port(port, sockets, None, on_status, stop_after(args.common.seconds)).await?;
        if let Port::Master(m) = port {
            println!("summary: {:?}; transport {:?}", m.stats(), stats);
        }
        Ok(())
    })
}

fn slave(args: SlaveArgs) -> anyhow::Result<()> {
    let mut cfg = load(&args.common)?;
    if let Some(v) = args.delay_req_interval {
        cfg.slave.log_min_delay_req_interval = v;
    }
    let adjuster = match &args.adjust_clock {
        Some(target) => {
            cfg.slave.adjust_clock = true;
            Some(ClockAdjuster::open(target)?)
        }
        None => {
            cfg.slave.adjust_clock = false;
            None
        }
    };
    cfg.validate()?;
    super::runtime()?.block_on(async {
        let sockets = PtpSockets::open(&transport(&args.common)).context("opening the PTP sockets")?;
        cfg.slave.local_timescale = local_timescale(sockets.mode);
        let identity = port_identity(&sockets);
        let mode = match &adjuster {
            Some(a) => format!("STEERING {}", a.name()),
            None => "measure-only (no clock is adjusted)".to_string(),
        };
        println!(
            "starc-ptp: slave {identity} on {} ({} timestamps), domain {}, {mode}",
            sockets.iface.name,
            sockets.mode.name(),
            cfg.slave.domain
        );
        let port = Port::Slave(Slave::new(cfg.slave.clone(), identity));
        let mut last_printed = None;
        let on_status = |port: &Port, _t: &TransportStats| {
            let Port::Slave(s) = port else { return };
            match s.latest() {
                Some(sample) if Some(sample.local_ns) != last_printed => {
                    last_printed = Some(sample.local_ns);
                    println!("{}", status::slave_line(status::uptime_s(), &sample));
                }
                _ => println!(
                    "starc-ptp[{:.3}]: {:?}, master {}",
                    status::uptime_s(),
                    s.state(),
                    s.selected_master().map(|m| m.to_string()).unwrap_or_else(|| "none".into())
                ),
            }
        };
        let (port, stats) = run_port(port, sockets, adjuster, on_status, stop_after(args.common.seconds)).await?;
        if let Port::Slave(s) = port {
            println!("summary: {:?}; transport {:?}", s.stats(), stats);
        }
        Ok(())
    })
}
