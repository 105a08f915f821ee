//! `starc demo`: Avia mock devices and the live driver against each other on loopback.
//!
//! It shows what a host sees from real Avias (discovery, handshake, setup, points, IMU, loss,
//! sync), with nothing but this program.

use super::rates::Rates;
use super::runtime;
use starc_hil::avia::{MockAvia, MockAviaConfig};
use starc_livox::live::{DriverConfig, LivoxDriver, LivoxEvent, SessionConfig};
use std::net::{Ipv4Addr, SocketAddrV4};
use std::time::Duration;

#[derive(clap::Args)]
pub struct Args {
    /// How many mock Avias (on 127.0.0.2, 127.0.0.3, ...).
    #[arg(long, default_value_t = 2)]
    pub devices: u8,
    /// How long to stream.
    #[arg(long, default_value_t = 5.0)]
    pub seconds: f64,
    /// Port the host listens on for broadcasts (the SDK's is 55000).
    #[arg(long, default_value_t = 55000)]
    pub broadcast_port: u16,
    /// Host data port (the SDK's is 56001).
    #[arg(long, default_value_t = 56001)]
    pub data_port: u16,
    /// Host command port (the SDK's is 55501).
    #[arg(long, default_value_t = 55501)]
    pub cmd_port: u16,
    /// Fraction of data packets each mock drops, to see loss detection at work.
    #[arg(long, default_value_t = 0.0)]
    pub drop: f64,
    /// Seed of the synthetic scenes and faults.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    if args.devices == 0 || args.devices > 200 {
        anyhow::bail!("--devices must be within 1..=200");
    }
    runtime()?.block_on(async move {
        let broadcast = SocketAddrV4::new(Ipv4Addr::LOCALHOST, args.broadcast_port);
        let config = DriverConfig {
            host_ip: Ipv4Addr::LOCALHOST,
            broadcast_listen: Some(broadcast),
            cmd_port: args.cmd_port,
            data_port: args.data_port,
            imu_port: args.data_port,
            session: SessionConfig::default(),
            ..DriverConfig::default()
        };
        let (driver, mut events) = LivoxDriver::start(config).await?;
        let mut mocks = Vec::new();
        for k in 0..args.devices {
            let ip = Ipv4Addr::new(127, 0, 0, 2 + k);
            let mut m = MockAviaConfig::on(ip);
            m.broadcast_to = broadcast;
            m.seed = args.seed + u64::from(k);
            m.faults.drop = args.drop;
            let mock = MockAvia::spawn(m).await?;
            println!("mock Avia {} on {}:65000", mock.broadcast_code(), ip);
            mocks.push(mock);
        }
        let mut rates = Rates::default();
        let mut tick = tokio::time::interval(Duration::from_secs(1));
        tick.tick().await;
        let deadline = tokio::time::Instant::now() + Duration::from_secs_f64(args.seconds.max(1.0));
        let ctrl_c = tokio::signal::ctrl_c();
        tokio::pin!(ctrl_c);
        loop {
            tokio::select! {
                e = events.recv() => match e {
                    Some(e) => {
                        match &e {
                            LivoxEvent::Discovered { ip, code, device_type } => {
                                println!("discovered {} {} at {ip}", device_type.name(), code);
                            }
                            LivoxEvent::Connected { ip, .. } => println!("connected to {ip}"),
                            LivoxEvent::DeviceInfo { ip, firmware: [a, b, c, d] } => {
                                println!("{ip}: firmware {a}.{b}.{c}.{d}");
                            }
                            LivoxEvent::Configured { ip } => println!("{ip}: configured, sampling"),
                            _ => {}
                        }
                        rates.observe(&e);
                    }
                    None => break,
                },
                _ = tick.tick() => {
                    for line in rates.report(1.0, None) {
                        println!("{line}");
                    }
                    if tokio::time::Instant::now() >= deadline {
                        break;
                    }
                }
                _ = &mut ctrl_c => break,
            }
        }
        driver.stop().await?;
        while let Ok(e) = events.try_recv() {
            rates.observe(&e);
        }
        let _ = rates.report(1.0, Some("(flush)"));
        println!("\nsummary over {:.0} s:", args.seconds);
        println!(
            "{:<16} {:<10} {:>6} {:>12} {:>12} {:>10} {:>8} {:>8}",
            "device", "ip", "scans", "returns", "non-empty", "imu", "lost", "bad"
        );
        for (ip, d) in &rates.devices {
            let t = &d.total;
            println!(
                "{:<16} {:<10} {:>6} {:>12} {:>12} {:>10} {:>8} {:>8}",
                d.code.clone().unwrap_or_default(),
                ip,
                t.scans,
                t.returns,
                t.non_empty,
                t.imu_packets,
                t.lost_packets + t.imu_lost,
                t.bad_datagrams
            );
        }
        for mock in mocks {
            let stats = mock.stop().await?;
            tracing::debug!(?stats, "mock stopped");
        }
        anyhow::Ok(())
    })
}
