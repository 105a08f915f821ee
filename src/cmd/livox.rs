//! `starc livox ...`: tools for one live Livox device.

use super::rates::Rates;
use super::runtime;
use starc_livox::live::{DriverConfig, LivoxDriver, ReturnModeSetting, SessionConfig};
use std::net::{Ipv4Addr, SocketAddrV4};
use std::time::Duration;

#[derive(clap::Subcommand)]
pub enum Command {
    /// Live rates of a device: points/s, IMU Hz, packet loss, sync source, status.
    Monitor(MonitorArgs),
}

#[derive(clap::Args)]
pub struct MonitorArgs {
    /// Driver settings from a TOML file (see config/livox.toml); replaces the flags below but
    /// --device and --seconds.
    #[arg(long)]
    pub config: Option<std::path::PathBuf>,
    /// Broadcast code or IP of the device to show (default: every device).
    #[arg(long)]
    pub device: Option<String>,
    /// Connect to this address directly instead of waiting for its broadcast.
    #[arg(long)]
    pub connect: Vec<Ipv4Addr>,
    /// The host address devices send to.
    #[arg(long, default_value = "127.0.0.1")]
    pub host_ip: Ipv4Addr,
    /// Where to listen for broadcasts ("none" to disable discovery).
    #[arg(long, default_value = "0.0.0.0:55000")]
    pub listen: String,
    /// Host data port (the SDK's default is 56001).
    #[arg(long, default_value_t = 56001)]
    pub data_port: u16,
    /// Host command port (the SDK's default is 55501).
    #[arg(long, default_value_t = 55501)]
    pub cmd_port: u16,
    /// Return mode to set.
    #[arg(long, value_enum)]
    pub return_mode: Option<ReturnArg>,
    /// Only listen (a replayed capture, or a device another host drives).
    #[arg(long)]
    pub passive: bool,
    /// Stop after this many seconds (0 runs until Ctrl-C).
    #[arg(long, default_value_t = 0.0)]
    pub seconds: f64,
}

#[derive(Clone, Copy, clap::ValueEnum)]
pub enum ReturnArg {
    First,
    Strongest,
    Dual,
    Triple,
}

impl From<ReturnArg> for ReturnModeSetting {
    fn from(r: ReturnArg) -> Self {
        match r {
            ReturnArg::First => Self::First,
            ReturnArg::Strongest => Self::Strongest,
            ReturnArg::Dual => Self::Dual,
            ReturnArg::Triple => Self::Triple,
        }
    }
}

pub fn run(command: Command) -> anyhow::Result<()> {
    match command {
        Command::Monitor(a) => monitor(a),
    }
}

pub fn parse_listen(text: &str) -> anyhow::Result<Option<SocketAddrV4>> {
    if text == "none" {
        return Ok(None);
    }
    Ok(Some(text.parse().map_err(|e| anyhow::anyhow!("--listen {text}: {e}"))?))
}

/// Reads a driver config file; errors name the file, line and key.
pub fn load_driver_config(path: &std::path::Path) -> anyhow::Result<DriverConfig> {
    let text = std::fs::read_to_string(path).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    let config: DriverConfig = toml::from_str(&text).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    config.scan.validate().map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    Ok(config)
}

fn monitor(args: MonitorArgs) -> anyhow::Result<()> {
    let listen = if args.passive { None } else { parse_listen(&args.listen)? };
    let config = if let Some(path) = &args.config {
        load_driver_config(path)?
    } else {
        DriverConfig {
            host_ip: args.host_ip,
            broadcast_listen: listen,
            connect: if args.passive { Vec::new() } else { args.connect.clone() },
            cmd_port: args.cmd_port,
            data_port: args.data_port,
            imu_port: args.data_port,
            session: SessionConfig { return_mode: args.return_mode.map(Into::into), ..SessionConfig::default() },
            ..DriverConfig::default()
        }
    };
    runtime()?.block_on(async move {
        let (driver, mut events) = LivoxDriver::start(config).await?;
        let mut rates = Rates::default();
        let mut tick = tokio::time::interval(Duration::from_secs(1));
        tick.tick().await;
        let started = tokio::time::Instant::now();
        let ctrl_c = tokio::signal::ctrl_c();
        tokio::pin!(ctrl_c);
        loop {
            tokio::select! {
                e = events.recv() => match e {
                    Some(e) => rates.observe(&e),
                    None => break,
                },
                _ = tick.tick() => {
                    for line in rates.report(1.0, args.device.as_deref()) {
                        println!("{line}");
                    }
                    if args.seconds > 0.0 && started.elapsed().as_secs_f64() >= args.seconds {
                        break;
                    }
                }
                _ = &mut ctrl_c => break,
            }
        }
        driver.stop().await?;
        anyhow::Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_example_config_is_the_default_but_for_host_ip() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("config/livox.toml");
        let loaded = load_driver_config(&path);
        assert!(loaded.is_ok(), "{loaded:?}", loaded = loaded.as_ref().err());
        let Ok(loaded) = loaded else { return };
        let expected = DriverConfig { host_ip: Ipv4Addr::new(192, 168, 1, 50), ..DriverConfig::default() };
        assert_eq!(loaded, expected);
    }

    #[test]
    fn unknown_keys_are_refused_with_their_line() {
        let err = toml::from_str::<DriverConfig>("host_ip = \"127.0.0.1\"\n[scan]\nperiod = 5\n").err();
        let text = err.map(|e| e.to_string()).unwrap_or_default();
        assert!(text.contains("period") && text.contains("line 3"), "{text}");
    }
}
