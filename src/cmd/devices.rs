//! `starc devices`: list the Livox devices on the network.

use super::runtime;
use serde::Serialize;
use starc_livox::control::{BroadcastCode, DeviceType};
use starc_livox::data::StatusWord;
use starc_livox::live::{DriverConfig, LivoxDriver, LivoxEvent, SessionConfig};
use std::collections::BTreeMap;
use std::net::{Ipv4Addr, SocketAddrV4};
use std::time::Duration;

#[derive(clap::Args)]
pub struct Args {
    /// How long to listen for broadcasts and answers.
    #[arg(long, default_value_t = 2.0)]
    pub seconds: f64,
    /// The host address devices answer to (an address of this machine on the LiDAR network).
    #[arg(long, default_value = "127.0.0.1")]
    pub host_ip: Ipv4Addr,
    /// Where to listen for broadcasts (0.0.0.0:55000 hears real devices).
    #[arg(long, default_value = "0.0.0.0:55000")]
    pub listen: SocketAddrV4,
    /// Also query these addresses directly, without waiting for a broadcast.
    #[arg(long)]
    pub connect: Vec<Ipv4Addr>,
    /// Host command port (0 picks a free one).
    #[arg(long, default_value_t = 0)]
    pub cmd_port: u16,
    /// Print JSON instead of a table.
    #[arg(long)]
    pub json: bool,
}

#[derive(Default, Serialize)]
struct Listed {
    ip: String,
    broadcast_code: Option<String>,
    device_type: Option<String>,
    firmware: Option<String>,
    work_state: Option<&'static str>,
    status: Option<String>,
    sync: Option<String>,
    status_word: Option<u32>,
}

fn work_state(v: u8) -> &'static str {
    match v {
        0 => "initializing",
        1 => "normal",
        2 => "power-save",
        3 => "standby",
        4 => "error",
        _ => "unknown",
    }
}

fn describe(listed: &mut Listed, code: Option<BroadcastCode>, device_type: Option<DeviceType>) {
    if let Some(c) = code {
        listed.broadcast_code = Some(c.text());
    }
    if let Some(t) = device_type {
        listed.device_type = Some(t.name());
    }
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let config = DriverConfig {
        host_ip: args.host_ip,
        broadcast_listen: Some(args.listen),
        connect: args.connect.clone(),
        cmd_port: args.cmd_port,
        data_port: 0,
        imu_port: 0,
        accept_unsolicited_data: false,
        session: SessionConfig { configure: false, start_sampling: false, imu_push: false, ..SessionConfig::default() },
        ..DriverConfig::default()
    };
    let listed = runtime()?.block_on(async move {
        let (driver, mut events) = LivoxDriver::start(config).await?;
        let mut found: BTreeMap<Ipv4Addr, Listed> = BTreeMap::new();
        let deadline = tokio::time::Instant::now() + Duration::from_secs_f64(args.seconds.max(0.1));
        while let Ok(Some(event)) = tokio::time::timeout_at(deadline, events.recv()).await {
            match event {
                LivoxEvent::Discovered { ip, code, device_type } => {
                    describe(found.entry(ip).or_default(), Some(code), Some(device_type));
                }
                LivoxEvent::Connected { ip, code } => describe(found.entry(ip).or_default(), code, None),
                LivoxEvent::DeviceInfo { ip, firmware } => {
                    let [a, b, c, d] = firmware;
                    found.entry(ip).or_default().firmware = Some(format!("{a}.{b}.{c}.{d}"));
                }
                LivoxEvent::Heartbeat { ip, work_state: w, status } => {
                    let l = found.entry(ip).or_default();
                    l.work_state = Some(work_state(w));
                    fill_status(l, status);
                }
                LivoxEvent::AbnormalStatus { ip, status } => fill_status(found.entry(ip).or_default(), status),
                _ => {}
            }
        }
        driver.stop().await?;
        for (ip, l) in found.iter_mut() {
            l.ip = ip.to_string();
        }
        anyhow::Ok(found.into_values().collect::<Vec<_>>())
    })?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&listed)?);
        return Ok(());
    }
    if listed.is_empty() {
        println!("no Livox devices heard in {:.1} s on {}", args.seconds, args.listen);
        return Ok(());
    }
    println!(
        "{:<17} {:<15} {:<8} {:<10} {:<13} {:<6} STATUS",
        "BROADCAST CODE", "IP", "TYPE", "FIRMWARE", "STATE", "SYNC"
    );
    let dash = || "-".to_string();
    for l in &listed {
        println!(
            "{:<17} {:<15} {:<8} {:<10} {:<13} {:<6} {}",
            l.broadcast_code.clone().unwrap_or_else(dash),
            l.ip,
            l.device_type.clone().unwrap_or_else(dash),
            l.firmware.clone().unwrap_or_else(dash),
            l.work_state.unwrap_or("-"),
            l.sync.clone().unwrap_or_else(dash),
            l.status.clone().unwrap_or_else(dash),
        );
    }
    Ok(())
}

fn fill_status(l: &mut Listed, status: StatusWord) {
    l.status = Some(status.describe());
    l.sync = Some(format!("{:?}", status.sync).to_lowercase());
    l.status_word = Some(status.raw);
}
