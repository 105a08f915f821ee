//! `starc mock`: mock devices that speak the real wire protocols.
//!
//! `starc mock avia` runs a Livox Avia on a loopback (or any local) address: it broadcasts, takes
//! a handshake, answers every control command, and streams points and IMU at the real rates from
//! a synthetic room or a capture, with optional faults. Ctrl-C (or `--duration`) stops it and
//! prints its counters.
//!
//! `--capture-device` and `--recorded-time` replay one Avia of a multi-device capture (a
//! `starc sim` run's avia.pcap) at its recorded stamps, so one mock per device, each in its own
//! process, plays the run back as `starc sim` does in one (docs/nodes.md, "Running the nodes as
//! separate processes").

use anyhow::{bail, Context};
use starc_hil::avia::{MockAvia, MockAviaConfig, MockStats, ReturnSetting, SourceConfig, TimeSource, TimeSourceSwitch};
use starc_livox::capture;
use starc_livox::data::DataPacket;
use starc_time::Stamp;
use std::collections::BTreeSet;
use std::net::{Ipv4Addr, SocketAddrV4};
use std::path::{Path, PathBuf};
use std::time::Duration;

/// Recorded-time playback starts this long after the mocks (with `--recorded-time` and no
/// `--start-at-unix-ns`, and in `starc sim`): time to discover and set up the devices.
pub(crate) const PLAYBACK_LEAD_NS: u64 = 2_500_000_000;
/// A `--start-at-unix-ns` farther from now than this is a mistake (seconds or ms, not ns).
const MAX_START_OFFSET_NS: u64 = 3600 * 1_000_000_000;

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
    /// With a capture: replay only the packets sent from this address (one device of a
    /// multi-device capture; `starc sim` runs: robot 192.168.1.101, rig 192.168.2.102)
    /// [default: the first device seen].
    #[arg(long, value_name = "IP")]
    pub capture_device: Option<Ipv4Addr>,
    /// With a capture: send every packet at its recorded time stamp (the mock's PTP clock set to
    /// match), once, no looping; mocks of the devices of one capture, started with the same
    /// --start-at-unix-ns, keep their recorded relative timing.
    #[arg(long)]
    pub recorded_time: bool,
    /// With --recorded-time: when (host realtime, Unix ns) the capture's first data packet, of
    /// any device, plays, e.g. $(( $(date +%s%N) + 4000000000 )); within an hour of now (a past
    /// time skips what would have played) [default: 2.5 s after the mock starts].
    #[arg(long, value_name = "NS")]
    pub start_at_unix_ns: Option<u64>,
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
        if let Some(ip) = self.capture_device {
            c.capture_device = Some(ip);
        }
        c.recorded_time |= self.recorded_time;
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
        let capture_path = match &c.source {
            SourceConfig::Capture(path) => Some(path.clone()),
            SourceConfig::Synthetic => None,
        };
        if self.start_at_unix_ns.is_some() && !(capture_path.is_some() && c.recorded_time) {
            bail!("--start-at-unix-ns: needs --recorded-time with a capture --source");
        }
        if let (Some(path), true) = (&capture_path, c.capture_device.is_some() || c.recorded_time) {
            let first_ns = capture_start_ns(path, c.capture_device)?;
            if c.recorded_time && (self.start_at_unix_ns.is_some() || c.epoch_ns.is_none()) {
                let now_ns = Stamp::host_now().ns;
                let start_at_ns = self.start_at_unix_ns.unwrap_or(now_ns.saturating_add(PLAYBACK_LEAD_NS));
                c.epoch_ns = Some(recorded_epoch_ns(first_ns, start_at_ns, now_ns)?);
                tracing::info!(
                    "recorded time: the capture's first packet (stamp {first_ns} ns) plays in {:.3} s",
                    (i128::from(start_at_ns) - i128::from(now_ns)) as f64 * 1e-9
                );
            }
        }
        c.validate()?;
        Ok(c)
    }
}

/// The stamp of the capture's first data packet (any device): where recorded-time playback
/// starts. With `device`, also checks that it sends data packets in the capture.
pub(crate) fn capture_start_ns(path: &Path, device: Option<Ipv4Addr>) -> anyhow::Result<u64> {
    let mut first_ns = None;
    let mut found = device.is_none();
    let mut others = BTreeSet::new();
    for d in capture::open(path).with_context(|| format!("opening {}", path.display()))? {
        let d = d.with_context(|| format!("reading {}", path.display()))?;
        let Ok(packet) = DataPacket::parse(&d.payload) else { continue };
        first_ns.get_or_insert(packet.header.timestamp.ns);
        let src = d.src.map(|a| *a.ip());
        if device.is_none() || src == device {
            found = true;
            break;
        }
        others.insert(match (src, d.device_index) {
            (Some(ip), _) => ip.to_string(),
            (None, Some(i)) => format!("lvx device {i} (no address)"),
            (None, None) => "no address".into(),
        });
    }
    let Some(first_ns) = first_ns else { bail!("{}: no Livox data packet", path.display()) };
    if !found {
        let others: Vec<String> = others.into_iter().collect();
        bail!(
            "--capture-device {}: no data packets from it in {} (devices there: {})",
            device.map_or_else(String::new, |ip| ip.to_string()),
            path.display(),
            others.join(", ")
        );
    }
    Ok(first_ns)
}

/// The mock's PTP epoch (device clock zero, taken as now) that plays a capture starting at
/// stamp `first_ns` when the host's realtime clock reads `start_at_ns`.
fn recorded_epoch_ns(first_ns: u64, start_at_ns: u64, now_ns: u64) -> anyhow::Result<u64> {
    let lead_ns = i128::from(start_at_ns) - i128::from(now_ns);
    if lead_ns.unsigned_abs() > u128::from(MAX_START_OFFSET_NS) {
        bail!(
            "--start-at-unix-ns {start_at_ns} is {:.0} s from now: give the start in Unix nanoseconds within an hour, e.g. $(( $(date +%s%N) + 4000000000 ))",
            lead_ns as f64 * 1e-9
        );
    }
    if lead_ns < 0 {
        tracing::warn!(
            "--start-at-unix-ns is {:.3} s past: what would have played by now is skipped",
            lead_ns as f64 * -1e-9
        );
    }
    u64::try_from(i128::from(first_ns) - lead_ns)
        .map_err(|_| anyhow::anyhow!("the capture's first stamp ({first_ns} ns) is too early to play at recorded time"))
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

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used)]
mod tests {
    use super::*;
    use clap::Parser;
    use starc_hil::avia::stream::{point_data_type, StreamParams, Timebase};
    use starc_hil::avia::{Packet, PointSource, Streamer, SyntheticScene};
    use starc_livox::capture::{PcapWriter, TsPrecision};
    use starc_livox::control::ReturnMode;

    const S: u64 = 1_000_000_000;
    const ROBOT: Ipv4Addr = Ipv4Addr::new(192, 168, 1, 101);
    const RIG: Ipv4Addr = Ipv4Addr::new(192, 168, 2, 102);

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        avia: AviaArgs,
    }

    fn args(extra: &[&str]) -> anyhow::Result<MockAviaConfig> {
        let cli = Cli::try_parse_from(std::iter::once("avia").chain(extra.iter().copied()))?;
        cli.avia.config()
    }

    /// 20 ms of one synthetic device whose PTP clock reads `epoch_ns` at its power-on.
    fn stream(epoch_ns: u64, seed: u64) -> Vec<Packet> {
        let mut scene = SyntheticScene::new(seed);
        let mut streamer = Streamer::start(0, S, &mut scene);
        let offset = i64::try_from(epoch_ns).unwrap();
        let params = StreamParams {
            data_type: point_data_type(ReturnMode::First, false),
            imu: true,
            status: 0,
            timebase: Timebase { source: TimeSource::Ptp, ptp_offset_ns: offset, utc_offset_ns: offset },
        };
        let mut out = Vec::new();
        streamer.poll(20_000_000, &params, &mut scene, &mut out);
        out
    }

    /// A capture of two devices, the robot's first (by 5 ms), as a `starc sim` run holds them.
    fn two_device_pcap(dir: &Path, robot_epoch_ns: u64) -> (PathBuf, Vec<Packet>) {
        let host = SocketAddrV4::new(Ipv4Addr::new(192, 168, 1, 50), 56001);
        let mut all: Vec<(u64, Ipv4Addr, Packet)> = Vec::new();
        let rig = stream(robot_epoch_ns + 5_000_000, 2);
        for (ip, epoch, packets) in
            [(ROBOT, robot_epoch_ns, stream(robot_epoch_ns, 1)), (RIG, robot_epoch_ns + 5_000_000, rig.clone())]
        {
            all.extend(packets.into_iter().map(|p| (p.device_ns + epoch, ip, p)));
        }
        all.sort_by_key(|(t, ..)| *t);
        let mut w = PcapWriter::new(Vec::new(), TsPrecision::Nano).unwrap();
        for (t, ip, p) in &all {
            w.write_udp(*t, SocketAddrV4::new(*ip, 60001), host, &p.bytes).unwrap();
        }
        let path = dir.join("two.pcap");
        std::fs::write(&path, w.finish().unwrap()).unwrap();
        (path, rig)
    }

    #[test]
    fn the_epoch_puts_the_first_packet_at_the_start_time() {
        let first = 1_767_225_600 * S;
        let now = 1_800_000_000 * S;
        assert_eq!(recorded_epoch_ns(first, now + 3 * S, now).unwrap(), first - 3 * S);
        // A start in the past skips what would have played.
        assert_eq!(recorded_epoch_ns(first, now - S, now).unwrap(), first + S);
        // Seconds or milliseconds instead of nanoseconds are refused, as is an epoch before 1970.
        let e = recorded_epoch_ns(first, 1_800_000_000, now).unwrap_err();
        assert!(e.to_string().contains("Unix nanoseconds"), "{e}");
        assert!(recorded_epoch_ns(S, now + 3 * S, now).is_err());
    }

    #[test]
    fn one_device_of_a_capture_plays_at_its_recorded_stamps() {
        let dir = tempfile::tempdir().unwrap();
        let robot_epoch = 1_767_225_600 * S;
        let (path, rig) = two_device_pcap(dir.path(), robot_epoch);
        let path_arg = path.to_str().unwrap();
        let start_at = Stamp::host_now().ns + 2 * S;
        let start_arg = start_at.to_string();
        let c = args(&[
            "--ip",
            "127.0.7.2",
            "--source",
            path_arg,
            "--capture-device",
            "192.168.2.102",
            "--recorded-time",
            "--start-at-unix-ns",
            &start_arg,
        ])
        .unwrap();
        assert_eq!((c.capture_device, c.recorded_time), (Some(RIG), true));
        // The capture's first packet (the robot's) plays at start_at: its stamp less the lead.
        let epoch = c.epoch_ns.unwrap();
        let lead = robot_epoch as i128 - epoch as i128;
        assert!((2 * S as i128 - lead).abs() < 200_000_000, "lead {lead} ns");
        // The rig's packets, at their recorded stamps: device time = stamp - epoch.
        let mut source = c.open_source().unwrap();
        source.start(0);
        let first_rig_points = rig.iter().find(|p| p.kind == starc_hil::avia::PacketKind::Points).unwrap();
        let want = robot_epoch + 5_000_000 + first_rig_points.device_ns - epoch;
        assert_eq!(source.next_firing_ns(0), want);
        // Its first IMU sample too: the robot's, read ahead when the capture was opened, is not
        // played by the rig's mock.
        let first_rig_imu = rig.iter().find(|p| p.kind == starc_hil::avia::PacketKind::Imu).unwrap();
        assert_eq!(source.next_imu_ns(0), robot_epoch + 5_000_000 + first_rig_imu.device_ns - epoch);
    }

    #[test]
    fn recorded_time_flags_are_checked() {
        let dir = tempfile::tempdir().unwrap();
        let (path, _) = two_device_pcap(dir.path(), 1_767_225_600 * S);
        let path_arg = path.to_str().unwrap();
        let err = |extra: &[&str]| format!("{:#}", args(extra).unwrap_err());
        assert!(err(&["--capture-device", "192.168.2.102"]).contains("needs a capture source"));
        assert!(err(&["--recorded-time"]).contains("needs a capture source"));
        assert!(err(&["--start-at-unix-ns", "1"]).contains("needs --recorded-time"));
        assert!(err(&["--source", path_arg, "--start-at-unix-ns", "1"]).contains("needs --recorded-time"));
        let e = err(&["--source", path_arg, "--capture-device", "10.0.0.9"]);
        assert!(
            e.contains("no data packets from it") && e.contains("192.168.1.101") && e.contains("192.168.2.102"),
            "{e}"
        );
        let e = err(&["--source", path_arg, "--recorded-time", "--time-source", "none"]);
        assert!(e.contains("ptp or gps"), "{e}");
        let e = err(&["--source", path_arg, "--recorded-time", "--start-at-unix-ns", "1700000000"]);
        assert!(e.contains("Unix nanoseconds"), "{e}");
        // Without a start time, playback starts 2.5 s from now.
        let c = args(&["--source", path_arg, "--recorded-time"]).unwrap();
        let lead = 1_767_225_600 * S as i128 - c.epoch_ns.unwrap() as i128;
        assert!((lead - PLAYBACK_LEAD_NS as i128).abs() < 200_000_000, "{lead}");
    }
}
