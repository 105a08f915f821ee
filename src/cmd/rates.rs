//! Per-device live rates from the driver's events (shared by `livox monitor` and `demo`).

use serde::Serialize;
use starc_livox::data::{GapDetector, StatusWord};
use starc_livox::live::LivoxEvent;
use starc_time::Clock;
use std::collections::BTreeMap;
use std::net::Ipv4Addr;

/// Counters of one device over one reporting window and in total.
#[derive(Clone, Debug, Default, Serialize)]
pub struct Counters {
    pub scans: u64,
    pub point_packets: u64,
    pub returns: u64,
    pub non_empty: u64,
    pub kept: u64,
    pub lost_packets: u64,
    pub imu_packets: u64,
    pub imu_lost: u64,
    pub bad_datagrams: u64,
}

impl Counters {
    fn add(&mut self, o: &Counters) {
        self.scans += o.scans;
        self.point_packets += o.point_packets;
        self.returns += o.returns;
        self.non_empty += o.non_empty;
        self.kept += o.kept;
        self.lost_packets += o.lost_packets;
        self.imu_packets += o.imu_packets;
        self.imu_lost += o.imu_lost;
        self.bad_datagrams += o.bad_datagrams;
    }
}

#[derive(Default)]
pub struct DeviceRates {
    pub code: Option<String>,
    pub window: Counters,
    pub total: Counters,
    pub clock: Option<Clock>,
    pub status: Option<StatusWord>,
    pub connected: bool,
    pub lost_events: u64,
    imu_gaps: GapDetector,
}

#[derive(Default)]
pub struct Rates {
    pub devices: BTreeMap<Ipv4Addr, DeviceRates>,
}

impl Rates {
    pub fn observe(&mut self, event: &LivoxEvent) {
        match event {
            LivoxEvent::Discovered { ip, code, .. } => self.dev(*ip).code = Some(code.text()),
            LivoxEvent::Connected { ip, code } => {
                let d = self.dev(*ip);
                d.connected = true;
                if let Some(c) = code {
                    d.code = Some(c.text());
                }
            }
            LivoxEvent::Lost { ip } => {
                let d = self.dev(*ip);
                d.connected = false;
                d.lost_events += 1;
            }
            LivoxEvent::Heartbeat { ip, status, .. } | LivoxEvent::AbnormalStatus { ip, status } => {
                self.dev(*ip).status = Some(*status)
            }
            LivoxEvent::Scan { ip, scan } => {
                let d = self.dev(*ip);
                d.window.scans += 1;
                d.window.point_packets += u64::from(scan.packets);
                d.window.returns += scan.returns;
                d.window.non_empty += scan.returns - scan.empty;
                d.window.kept += scan.points.len() as u64;
                d.window.lost_packets += scan.lost_packets;
                d.clock = Some(scan.start.clock);
            }
            LivoxEvent::Imu(r) => {
                let d = self.dev(r.ip);
                d.window.imu_packets += 1;
                if let Some(g) = d.imu_gaps.observe(r.device_time, 5_000_000) {
                    d.window.imu_lost += g.lost_packets;
                }
                d.clock = Some(r.device_time.clock);
                d.status = Some(r.status);
            }
            LivoxEvent::BadDatagram { from, .. } => self.dev(*from.ip()).window.bad_datagrams += 1,
            _ => {}
        }
    }

    fn dev(&mut self, ip: Ipv4Addr) -> &mut DeviceRates {
        self.devices.entry(ip).or_default()
    }

    /// One line per device for the window of `seconds`, then the window restarts.
    pub fn report(&mut self, seconds: f64, only: Option<&str>) -> Vec<String> {
        let mut lines = Vec::new();
        for (ip, d) in self.devices.iter_mut() {
            let name = d.code.clone().unwrap_or_else(|| "(no broadcast)".into());
            if let Some(f) = only {
                if f != name && f != ip.to_string() {
                    continue;
                }
            }
            let w = &d.window;
            let expected = w.point_packets + w.lost_packets;
            let loss = if expected > 0 { 100.0 * w.lost_packets as f64 / expected as f64 } else { 0.0 };
            lines.push(format!(
                "{name:<16} {ip:<13} points/s {:>8.0} (non-empty {:>8.0}, kept {:>8.0})  imu {:>5.1} Hz  loss {:>5.2}% ({} pkts)  sync {:<6} {}",
                w.returns as f64 / seconds,
                w.non_empty as f64 / seconds,
                w.kept as f64 / seconds,
                w.imu_packets as f64 / seconds,
                loss,
                w.lost_packets + w.imu_lost,
                d.clock.map_or("-", |c| c.name()),
                d.status.map_or_else(|| if d.connected { "connected".into() } else { "waiting".into() }, |s| s.describe()),
            ));
            let window = std::mem::take(&mut d.window);
            d.total.add(&window);
        }
        lines
    }
}
