//! `starc inspect FILE [--json]`: what a capture (pcap, pcapng, .lvx) of Livox traffic holds.
//!
//! The counting is `starc_livox::capture::summarize`; this file only prints. The JSON keys are
//! documented in docs/inspect.md.

use anyhow::Context;
use starc_livox::capture::{self, CaptureSummary};
use std::fmt::Write as _;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    /// Capture file: pcap, pcapng or .lvx (recognised by its first bytes).
    pub file: PathBuf,
    /// Print the summary as JSON (keys in docs/inspect.md) instead of a table.
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let mut cap = capture::open(&args.file).with_context(|| format!("opening {}", args.file.display()))?;
    let summary = capture::summarize(&mut cap);
    if args.json {
        println!("{}", serde_json::to_string_pretty(&summary)?);
    } else {
        print!("{}", table(&args.file.display().to_string(), &summary));
    }
    if let Some(e) = &summary.read_error {
        anyhow::bail!("{}: reading stopped early (everything before is summarized): {e}", args.file.display());
    }
    Ok(())
}

fn counts(map: &std::collections::BTreeMap<String, u64>) -> String {
    let parts: Vec<String> = map.iter().filter(|(_, n)| **n > 0).map(|(k, n)| format!("{k} {n}")).collect();
    if parts.is_empty() {
        "-".into()
    } else {
        parts.join(", ")
    }
}

fn percent(part: u64, whole: u64) -> f64 {
    if whole == 0 {
        0.0
    } else {
        part as f64 * 100.0 / whole as f64
    }
}

/// The human-readable report.
pub fn table(name: &str, s: &CaptureSummary) -> String {
    let mut o = String::new();
    let r = &s.read;
    let _ = writeln!(o, "{:<16}{name} ({})", "file", s.format.name());
    let _ = writeln!(
        o,
        "{:<16}{} datagrams from {} records (skipped: {} not UDP/IPv4, {} fragments, {} malformed; {} truncated)",
        "records", s.records, r.records, r.non_udp, r.fragments, r.malformed, r.truncated
    );
    if r.unsupported_link > 0 || r.skipped_blocks > 0 {
        let _ = writeln!(
            o,
            "{:<16}{} packets on unsupported link types, {} other blocks",
            "", r.unsupported_link, r.skipped_blocks
        );
    }
    if let Some(h) = &s.lvx {
        let v = match h.version {
            starc_livox::capture::LvxVersion::V1_0 => "1.0",
            starc_livox::capture::LvxVersion::V1_1 => "1.1",
        };
        let frame = h.frame_duration_ms.map_or(String::new(), |d| format!(", {d} ms frames"));
        let _ = writeln!(o, "{:<16}v{v}, {} frames{frame}, {} devices", "lvx", r.lvx_frames, h.devices.len());
        for d in &h.devices {
            let _ = writeln!(
                o,
                "{:<16}#{} {} type {} extrinsics {} rpy ({:.2}, {:.2}, {:.2}) deg xyz ({:.3}, {:.3}, {:.3}) m",
                "",
                d.device_index,
                d.lidar_sn_text(),
                d.device_type,
                if d.extrinsic_enable { "on" } else { "off" },
                d.roll_deg,
                d.pitch_deg,
                d.yaw_deg,
                d.x_m,
                d.y_m,
                d.z_m
            );
        }
    }
    if s.capture_start_ns.is_some() {
        let _ = writeln!(o, "{:<16}{:.3} s of capture time", "captured", s.capture_duration_s);
    }
    let _ = writeln!(
        o,
        "{:<16}{} packets, {} points ({} non-empty, {:.1} %)",
        "point packets",
        s.point_packets,
        s.points,
        s.non_empty_points,
        percent(s.non_empty_points, s.points)
    );
    let _ = writeln!(o, "{:<16}{}", "imu packets", s.imu_packets);
    let _ = writeln!(o, "{:<16}{}", "data types", counts(&s.data_types));
    let _ = writeln!(o, "{:<16}{}", "time stamps", counts(&s.timestamp_types));
    let _ = writeln!(o, "{:<16}{}", "sync (status)", counts(&s.sync_sources));
    if let (Some(first), Some(last), Some(clock)) = (s.first_timestamp_ns, s.last_timestamp_ns, s.timestamp_clock) {
        let _ = writeln!(
            o,
            "{:<16}{}.{:09} .. {}.{:09} ({clock}), {:.3} s",
            "device time",
            first / 1_000_000_000,
            first % 1_000_000_000,
            last / 1_000_000_000,
            last % 1_000_000_000,
            s.duration_s
        );
    }
    let _ = writeln!(
        o,
        "{:<16}{} gaps, {} lost packets, {} reordered, {} clock jumps",
        "loss", s.gaps, s.lost_packets, s.reordered, s.clock_jumps
    );
    let _ = writeln!(
        o,
        "{:<16}{} CRC failures, {} decode errors, {} undecodable",
        "errors", s.crc_failures, s.decode_errors, s.undecodable
    );
    if !s.flows.is_empty() {
        let _ = writeln!(o, "{:<16}{}", "udp ports", counts(&s.flows));
    }
    if !s.control_frames.is_empty() {
        let _ = writeln!(
            o,
            "\n{:<22}{:>8}{:>8}{:>8}{:>8}{:>10}",
            "control command", "cmd", "ack", "msg", "ack ok", "ack error"
        );
        for (name, c) in &s.control_frames {
            let _ = writeln!(o, "{name:<22}{:>8}{:>8}{:>8}{:>8}{:>10}", c.cmd, c.ack, c.msg, c.ack_ok, c.ack_error);
        }
    }
    if !s.devices.is_empty() {
        let _ = writeln!(
            o,
            "\n{:<18}{:>9}{:>9}{:>7}{:>11}{:>11}{:>7}{:>7}{:>9}  serial",
            "device", "packets", "pt pkts", "imu", "returns", "non-empty", "lost", "gaps", "control"
        );
        for (name, d) in &s.devices {
            let _ = writeln!(
                o,
                "{name:<18}{:>9}{:>9}{:>7}{:>11}{:>11}{:>7}{:>7}{:>9}  {}",
                d.packets,
                d.point_packets,
                d.imu_packets,
                d.points,
                d.non_empty_points,
                d.lost_packets,
                d.gaps,
                d.control_frames,
                d.lidar_sn.as_deref().unwrap_or("-")
            );
        }
    }
    if let Some(e) = &s.read_error {
        let _ = writeln!(o, "\n{:<16}{e}", "read error");
    }
    o
}
