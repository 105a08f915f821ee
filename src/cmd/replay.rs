//! `starc replay FILE --to udp://HOST:PORT`: sends a capture's datagrams to a UDP socket with their
//! original spacing (scaled by `--rate`), e.g. into a running driver or pipeline.
//!
//! (Rerunning the pipeline on the nodes' MCAP recordings is `starc rerun`.)
//!
//! Timing: datagram k is sent at `start + (t_k - t_0) / rate`, sleeping until that instant (never
//! spinning); a late sender catches up without drifting. pcap/pcapng use capture times, .lvx the
//! packets' own stamps. Destinations outside loopback need `--allow-remote`.

use anyhow::{bail, Context};
use starc_livox::capture::{self, Datagram};
use starc_livox::control::RawFrame;
use starc_livox::data::DataPacket;
use starc_livox::ports::DEVICE_CMD_PORT;
use starc_time::Stamp;
use std::io::Write;
use std::net::{SocketAddr, ToSocketAddrs, UdpSocket};
use std::path::PathBuf;
use std::time::{Duration, Instant};

/// Which datagrams to send.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Only {
    /// Point data packets.
    Data,
    /// IMU packets.
    Imu,
    /// Control frames (to or from port 65000, or anything that verifies as one).
    Control,
    /// Everything, undecodable datagrams included.
    All,
}

#[derive(clap::Args, Clone, Debug)]
pub struct Args {
    /// Capture file (pcap, pcapng or .lvx).
    pub file: PathBuf,
    /// Destination of a capture's datagrams, udp://HOST:PORT.
    #[arg(long, value_name = "udp://HOST:PORT")]
    pub to: Option<String>,
    /// Speed factor: 2 plays twice as fast, 0.5 at half speed, 0 as fast as possible.
    #[arg(long, default_value_t = 1.0)]
    pub rate: f64,
    /// Play the capture N times (0: until interrupted).
    #[arg(long = "loop", value_name = "N", default_value_t = 1)]
    pub loops: u32,
    /// Send only these datagrams.
    #[arg(long, value_enum, default_value_t = Only::All)]
    pub only: Only,
    /// A pause longer than this many seconds (capture time) is skipped.
    #[arg(long, default_value_t = 10.0)]
    pub max_gap: f64,
    /// Allow a destination outside 127.0.0.0/8 and ::1.
    #[arg(long)]
    pub allow_remote: bool,
}

/// What a replay did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Report {
    pub packets: u64,
    pub bytes: u64,
    pub elapsed_s: f64,
    /// Capture time covered by the sent datagrams.
    pub capture_s: f64,
    /// Datagrams refused by the destination (nobody listening), not counted as sent.
    pub refused: u64,
}

impl Report {
    /// Capture seconds played per wall-clock second.
    pub fn achieved_rate(&self) -> f64 {
        if self.elapsed_s > 0.0 {
            self.capture_s / self.elapsed_s
        } else {
            0.0
        }
    }

    pub fn line(&self) -> String {
        let pps = if self.elapsed_s > 0.0 { self.packets as f64 / self.elapsed_s } else { 0.0 };
        let mut line = format!(
            "replayed {} packets, {} bytes in {:.3} s ({:.0} packets/s, {:.2}x capture speed)",
            self.packets,
            self.bytes,
            self.elapsed_s,
            pps,
            self.achieved_rate()
        );
        if self.refused > 0 {
            line.push_str(&format!(", {} refused by the destination", self.refused));
        }
        line
    }
}

pub fn run(args: Args) -> anyhow::Result<()> {
    if starc_bridge::is_mcap(&args.file) {
        bail!(
            "{} is a node's MCAP recording: rerun the pipeline on it with `starc rerun FILE...`",
            args.file.display()
        );
    }
    let report = replay(&args)?;
    let mut out = std::io::stdout().lock();
    writeln!(out, "{}", report.line())?;
    Ok(())
}

/// Parses `udp://HOST:PORT` and resolves it; refuses non-loopback addresses unless allowed.
pub fn destination(url: &str, allow_remote: bool) -> anyhow::Result<SocketAddr> {
    let Some(rest) = url.strip_prefix("udp://") else {
        bail!("destination must look like udp://HOST:PORT, got {url:?}");
    };
    let rest = rest.trim_end_matches('/');
    let addrs: Vec<SocketAddr> =
        rest.to_socket_addrs().with_context(|| format!("resolving {rest:?} (HOST:PORT expected)"))?.collect();
    let Some(first) = addrs.iter().find(|a| a.is_ipv4()).or(addrs.first()).copied() else {
        bail!("{rest:?} resolves to no address");
    };
    if !allow_remote && !first.ip().is_loopback() {
        bail!(
            "refusing to send to {first}: not a loopback address (127.0.0.0/8, ::1); pass --allow-remote to send \
             over the network"
        );
    }
    if first.port() == 0 {
        bail!("destination port must not be 0");
    }
    Ok(first)
}

/// Whether a datagram passes the `--only` filter.
pub fn selected(only: Only, d: &Datagram) -> bool {
    if only == Only::All {
        return true;
    }
    let p = d.payload.as_slice();
    let on_control_port = [d.src, d.dst].iter().flatten().any(|a| a.port() == DEVICE_CMD_PORT);
    let control = p.first() == Some(&0xAA) && (on_control_port || RawFrame::decode(p).is_ok());
    match only {
        Only::Control => control,
        Only::Data | Only::Imu if control => false,
        Only::Data => DataPacket::parse(p).is_ok_and(|pk| !pk.is_imu()),
        Only::Imu => DataPacket::parse(p).is_ok_and(|pk| pk.is_imu()),
        Only::All => true,
    }
}

/// Plays the capture as the arguments say; returns what was sent.
pub fn replay(args: &Args) -> anyhow::Result<Report> {
    if !(args.rate >= 0.0 && args.rate.is_finite()) {
        bail!("--rate must be a finite number >= 0, got {}", args.rate);
    }
    if !(args.max_gap > 0.0 && args.max_gap.is_finite()) {
        bail!("--max-gap must be a positive number of seconds, got {}", args.max_gap);
    }
    let Some(to) = args.to.as_deref() else { bail!("--to udp://HOST:PORT: where to send the capture's datagrams") };
    let dest = destination(to, args.allow_remote)?;
    let bind: SocketAddr = match (dest, dest.ip().is_loopback()) {
        (SocketAddr::V4(_), true) => "127.0.0.1:0".parse()?,
        (SocketAddr::V4(_), false) => "0.0.0.0:0".parse()?,
        (SocketAddr::V6(_), true) => "[::1]:0".parse()?,
        (SocketAddr::V6(_), false) => "[::]:0".parse()?,
    };
    let socket = UdpSocket::bind(bind).with_context(|| format!("binding a UDP socket on {bind}"))?;
    if let SocketAddr::V4(v4) = dest {
        if v4.ip().is_broadcast() {
            socket.set_broadcast(true).context("enabling broadcast")?;
        }
    }
    let max_gap_ns = (args.max_gap * 1e9) as u64;
    let mut report = Report::default();
    let started = Instant::now();
    let mut pass = 0u32;
    while args.loops == 0 || pass < args.loops {
        pass += 1;
        let mut cap = capture::open(&args.file).with_context(|| format!("opening {}", args.file.display()))?;
        let mut d = Datagram::default();
        // The wall instant and capture stamp the schedule is measured from, and the last stamp.
        let mut anchor: Option<(Instant, Stamp)> = None;
        let mut last: Option<Stamp> = None;
        let mut sent_in_pass = 0u64;
        while cap.read_into(&mut d).with_context(|| format!("reading {}", args.file.display()))? {
            if !selected(args.only, &d) {
                continue;
            }
            let t = d.time;
            // A new clock, a jump back or a long pause restarts the schedule from now.
            let step = last.and_then(|l| t.since(l));
            let restart = match step {
                None => true,
                Some(s) => s < -(max_gap_ns as i64) || s > max_gap_ns as i64,
            };
            if let (false, Some(l)) = (restart, last) {
                report.capture_s += (t.since(l).unwrap_or(0).max(0)) as f64 * 1e-9;
            }
            if restart || anchor.is_none() {
                anchor = Some((Instant::now(), t));
            }
            last = Some(t);
            if let (Some((wall0, t0)), true) = (anchor, args.rate > 0.0) {
                let offset_ns = t.since(t0).unwrap_or(0).max(0) as f64 / args.rate;
                let target = wall0 + Duration::from_secs_f64(offset_ns * 1e-9);
                let now = Instant::now();
                if target > now {
                    std::thread::sleep(target - now);
                }
            }
            match socket.send_to(&d.payload, dest) {
                Ok(n) => {
                    report.packets += 1;
                    report.bytes += n as u64;
                    sent_in_pass += 1;
                }
                // An ICMP "port unreachable" from an earlier datagram: nobody listens (yet).
                Err(e) if e.kind() == std::io::ErrorKind::ConnectionRefused => report.refused += 1,
                Err(e) => return Err(e).with_context(|| format!("sending to {dest}")),
            }
        }
        tracing::debug!(pass, sent_in_pass, "replay pass done");
        if sent_in_pass == 0 && args.loops == 0 {
            bail!("nothing in {} passes --only {:?}; refusing to loop forever", args.file.display(), args.only);
        }
    }
    report.elapsed_s = started.elapsed().as_secs_f64();
    Ok(report)
}

#[cfg(test)]
mod tests {
    use super::*;
    use starc_livox::capture::{PcapWriter, TsPrecision};
    use starc_livox::control::{ControlFrame, Request};
    use starc_livox::data::{encode_imu_packet, DataHeader, DataType, ImuSample, StatusWord};
    use starc_time::Clock;
    use std::net::{Ipv4Addr, SocketAddrV4};

    fn imu(ns: u64) -> Vec<u8> {
        let h = DataHeader {
            version: 5,
            slot: 1,
            lidar_id: 1,
            status: StatusWord::from_raw(0),
            data_type: DataType::Imu,
            timestamp: Stamp::new(ns, Clock::Ptp),
        };
        let mut out = Vec::new();
        let _ = encode_imu_packet(&h, &ImuSample { gyro_rad_s: [0.0; 3], acc_g: [0.0, 0.0, 1.0] }, &mut out);
        out
    }

    /// 11 IMU packets 10 ms apart and one heartbeat, as a pcap.
    fn capture_file(dir: &std::path::Path) -> PathBuf {
        let path = dir.join("replay.pcap");
        let lidar = SocketAddrV4::new(Ipv4Addr::new(192, 168, 1, 10), 60003);
        let host = SocketAddrV4::new(Ipv4Addr::new(192, 168, 1, 50), 56001);
        let Ok(mut w) = PcapWriter::create(&path, TsPrecision::Nano) else { panic!("create pcap") };
        for k in 0..11u64 {
            assert!(w.write_udp(1_000_000_000 + k * 10_000_000, lidar, host, &imu(k * 10_000_000)).is_ok());
        }
        let hb = ControlFrame::request(1, Request::Heartbeat).encode().unwrap_or_default();
        let cmd = SocketAddrV4::new(Ipv4Addr::new(192, 168, 1, 10), 65000);
        assert!(w.write_udp(1_100_000_001, host, cmd, &hb).is_ok());
        assert!(w.finish().is_ok());
        path
    }

    fn args(file: PathBuf, to: String, rate: f64, only: Only) -> Args {
        Args { file, to: Some(to), rate, loops: 1, only, max_gap: 10.0, allow_remote: false }
    }

    #[test]
    fn destinations_must_be_loopback_unless_allowed() {
        assert!(destination("udp://127.0.0.1:56001", false).is_ok());
        assert!(destination("udp://127.3.4.5:9/", false).is_ok());
        assert!(destination("udp://[::1]:9", false).is_ok());
        assert!(destination("udp://localhost:9", false).is_ok_and(|a| a.ip().is_loopback()));
        assert!(destination("udp://192.168.1.50:56001", false).is_err());
        assert!(destination("udp://192.168.1.50:56001", true).is_ok());
        assert!(destination("tcp://127.0.0.1:1", false).is_err());
        assert!(destination("udp://127.0.0.1", false).is_err());
        assert!(destination("udp://127.0.0.1:0", false).is_err());
    }

    #[test]
    fn sends_everything_in_order_with_the_original_spacing() {
        let Ok(dir) = tempfile::tempdir() else { panic!("tempdir") };
        let file = capture_file(dir.path());
        let Ok(rx) = UdpSocket::bind("127.0.0.1:0") else { panic!("bind") };
        let Ok(port) = rx.local_addr().map(|a| a.port()) else { panic!("addr") };
        let to = format!("udp://127.0.0.1:{port}");

        let Ok(report) = replay(&args(file.clone(), to.clone(), 1.0, Only::All)) else { panic!("replay") };
        assert_eq!(report.packets, 12);
        // 100 ms of capture at rate 1: not faster, and not much slower.
        assert!(report.elapsed_s >= 0.099 && report.elapsed_s < 0.5, "{report:?}");
        assert!((report.capture_s - 0.100_000_001).abs() < 1e-6, "{report:?}");
        let mut buf = [0u8; 2048];
        for k in 0..11u64 {
            let Ok(n) = rx.recv(&mut buf) else { panic!("recv") };
            assert_eq!(&buf[..n], imu(k * 10_000_000).as_slice());
        }
        let Ok(n) = rx.recv(&mut buf) else { panic!("recv") };
        assert_eq!(buf[0], 0xAA);
        assert_eq!(n, 15);
        assert!(report.line().starts_with("replayed 12 packets"));

        // Ten times faster, IMU only, twice.
        let mut a = args(file.clone(), to.clone(), 10.0, Only::Imu);
        a.loops = 2;
        let Ok(report) = replay(&a) else { panic!("replay") };
        assert_eq!(report.packets, 22);
        assert!(report.elapsed_s < 0.1, "{report:?}");
        for _ in 0..22 {
            let Ok(n) = rx.recv(&mut buf) else { panic!("recv") };
            assert_eq!(n, 42);
        }
        let Ok(report) = replay(&args(file.clone(), to.clone(), 0.0, Only::Control)) else { panic!("replay") };
        assert_eq!(report.packets, 1);
        let Ok(report) = replay(&args(file, to, 0.0, Only::Data)) else { panic!("replay") };
        assert_eq!(report.packets, 0);
    }

    #[test]
    fn remote_destinations_and_bad_rates_are_refused() {
        let a = args(PathBuf::from("/nonexistent.pcap"), "udp://10.1.2.3:56001".into(), 1.0, Only::All);
        assert!(replay(&a).is_err_and(|e| e.to_string().contains("--allow-remote")));
        let a = args(PathBuf::from("/nonexistent.pcap"), "udp://127.0.0.1:56001".into(), -1.0, Only::All);
        assert!(replay(&a).is_err());
    }
}
