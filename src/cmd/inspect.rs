//! `starc inspect FILE [--json]`: what a capture (pcap, pcapng, .lvx) of Livox traffic holds,
//! or what a STARC recording (MCAP) holds: topics, types, counts, time span (docs/record.md).
//!
//! The counting is `starc_livox::capture::summarize`; this file only prints. The JSON keys are
//! documented in docs/inspect.md.

use anyhow::Context;
use starc_livox::capture::{self, CaptureSummary};
use std::fmt::Write as _;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    /// Capture file: pcap, pcapng or .lvx, or an MCAP recording (recognised by its first bytes).
    pub file: PathBuf,
    /// Print the summary as JSON (keys in docs/inspect.md) instead of a table.
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    if starc_bridge::is_mcap(&args.file) {
        return run_mcap(&args);
    }
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

/// An MCAP recording: read as far as it goes (a crashed recording is summarized up to its last
/// complete chunk, then exit status 1).
fn run_mcap(args: &Args) -> anyhow::Result<()> {
    use starc_pipeline::record::reader;
    let s = reader::summarize_file(&args.file).with_context(|| format!("reading {}", args.file.display()))?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&s)?);
    } else {
        print!("{}", mcap_table(&args.file.display().to_string(), &s));
    }
    if let Some(e) = &s.stopped_by {
        anyhow::bail!("{}: reading stopped early (everything before is summarized): {e}", args.file.display());
    }
    Ok(())
}

fn ns_text(ns: u64) -> String {
    format!("{}.{:09}", ns / 1_000_000_000, ns % 1_000_000_000)
}

/// The human-readable report of a recording.
pub fn mcap_table(name: &str, s: &starc_pipeline::record::RecordingSummary) -> String {
    let mut o = String::new();
    let state = if s.finished { "finished" } else { "not finished: no summary (crash or still recording)" };
    let _ = writeln!(o, "{:<16}{name} (MCAP, {state})", "file");
    let _ = writeln!(o, "{:<16}{} on {} topics", "messages", s.messages, s.topics.len());
    if let (Some(a), Some(b)) = (s.start_ns, s.end_ns) {
        let _ = writeln!(o, "{:<16}{} .. {}, {:.3} s", "log time", ns_text(a), ns_text(b), (b - a) as f64 * 1e-9);
    }
    let _ = writeln!(o, "\n{:<28}{:<38}{:>9}{:>10}", "topic", "type", "messages", "rate Hz");
    for (topic, t) in &s.topics {
        let span_s = (t.last_ns - t.first_ns) as f64 * 1e-9;
        let rate = if t.messages > 1 && span_s > 0.0 {
            format!("{:.1}", (t.messages - 1) as f64 / span_s)
        } else {
            "-".into()
        };
        let _ = writeln!(o, "{topic:<28}{:<38}{:>9}{rate:>10}", t.type_name, t.messages);
    }
    if let Some(e) = &s.stopped_by {
        let _ = writeln!(o, "\n{:<16}{e}", "read error");
    }
    o
}
