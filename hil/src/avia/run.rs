//! The tokio transport of the mock Avia: sockets and timers around [`AviaDevice`].
//!
//! ```no_run
//! # async fn demo() -> starc_hil::Result<()> {
//! use starc_hil::avia::{MockAvia, MockAviaConfig};
//! let config = MockAviaConfig {
//!     ip: "127.0.0.2".parse().unwrap_or(std::net::Ipv4Addr::LOCALHOST),
//!     broadcast_to: "127.0.0.1:55000".parse().unwrap_or(MockAviaConfig::default().broadcast_to),
//!     ..MockAviaConfig::default()
//! };
//! let mock = MockAvia::spawn(config).await?;
//! // ... a host discovers, handshakes and streams ...
//! let stats = mock.stop().await?;
//! println!("{} point packets", stats.device.point_packets);
//! # Ok(()) }
//! ```
//!
//! Sockets: commands on `ip:cmd_port` (65000; broadcasts leave from it, with SO_BROADCAST so a
//! test inside its own network namespace may use 255.255.255.255), point packets from
//! `ip:data_port` (60001) and IMU from `ip:imu_port` (60003), as a real device (a real Tele-15
//! capture shows those ports). Port 0 picks a free port. Several mocks run side by side on
//! 127.0.0.2, 127.0.0.3, ... (Linux routes all of 127/8 to lo).
//!
//! While streaming the task wakes every `tick_us` (1 ms) and sends every packet due; the stamps
//! come from the device clock, not from the wake-up time.

use crate::avia::capture::CaptureSource;
use crate::avia::device::{Action, AviaDevice, DeviceConfig, DeviceEvent, DeviceStats};
use crate::avia::faults::FaultConfig;
use crate::avia::source::PointSource;
use crate::avia::stream::{ReturnSetting, TimeSource, NS_PER_S};
use crate::avia::synthetic::SyntheticScene;
use crate::error::{HilError, Result};
use serde::{Deserialize, Serialize};
use starc_livox::control::{BroadcastCode, CoordinateSystem};
use starc_livox::ports::{DEVICE_CMD_PORT, HOST_BROADCAST_PORT};
use starc_time::{Clock, Stamp};
use std::net::{Ipv4Addr, SocketAddr, SocketAddrV4};
use std::path::PathBuf;
use std::str::FromStr;
use std::time::Duration;
use tokio::net::UdpSocket;
use tokio::sync::{oneshot, watch};
use tokio::task::JoinHandle;
use tokio::time::Instant;

/// Data port of a real Avia/Tele-15 (source port of point packets).
pub const DEVICE_DATA_PORT: u16 = 60001;
/// IMU port of a real Avia/Tele-15 (source port of IMU packets).
pub const DEVICE_IMU_PORT: u16 = 60003;

/// What the mock sees.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SourceConfig {
    /// The synthetic room ([`SyntheticScene`]), seeded by the mock's seed.
    #[default]
    Synthetic,
    /// Replay the point and IMU packets of a pcap, pcapng or .lvx file, looping.
    Capture(PathBuf),
}

impl FromStr for SourceConfig {
    type Err = String;
    /// `synthetic`, or the path of a capture file.
    fn from_str(s: &str) -> std::result::Result<Self, Self::Err> {
        match s {
            "" => Err("empty source".into()),
            "synthetic" => Ok(Self::Synthetic),
            path => Ok(Self::Capture(PathBuf::from(path))),
        }
    }
}

/// Everything a mock Avia needs; TOML-ready (unknown keys are refused, missing ones default).
///
/// ```toml
/// ip = "127.0.0.2"
/// broadcast_to = "127.0.0.1:55000"
/// source = "synthetic"            # or source = { capture = "run.pcapng" }
/// # capture_device = "192.168.1.101"  # a capture: only this device's packets
/// # recorded_time = true              # a capture: each packet at its recorded stamp (needs epoch_ns)
/// return_mode = "dual"
/// time_source = "ptp"
/// seed = 7
/// [faults]
/// drop = 0.01
/// ```
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MockAviaConfig {
    /// Address to bind (127.0.0.1).
    pub ip: Ipv4Addr,
    /// Command port (65000); 0 picks a free one.
    pub cmd_port: u16,
    /// Source port of point packets (60001); 0 picks a free one.
    pub data_port: u16,
    /// Source port of IMU packets (60003); 0 picks a free one; equal to `data_port` shares it.
    pub imu_port: u16,
    /// Where broadcasts go (127.0.0.1:55000; 255.255.255.255:55000 only inside a test netns).
    pub broadcast_to: SocketAddrV4,
    /// At most 16 characters; derived from the ip when absent ("STARCMOCK000002" for 127.0.0.2).
    pub broadcast_code: Option<String>,
    pub source: SourceConfig,
    /// With a capture source: replay only the packets of the device at this address (a
    /// capture of several devices); absent: the first device seen.
    pub capture_device: Option<Ipv4Addr>,
    /// With a capture source: play every packet at its recorded stamp, once, no looping
    /// ([`CaptureSource::at_recorded_time`] with `epoch_ns`, which must be set): a packet stamped
    /// `s` leaves `s - epoch_ns` after the mock starts and carries `s` (PTP or GPS time stamps),
    /// so mocks replaying the devices of one capture keep their recorded relative timing.
    pub recorded_time: bool,
    /// Seed of the synthetic scene and of the faults.
    pub seed: u64,
    pub return_mode: ReturnSetting,
    pub spherical: bool,
    pub time_source: TimeSource,
    pub imu_push: bool,
    /// Unix ns of the PTP/UTC clock at power-on; the host's realtime clock when absent.
    pub epoch_ns: Option<u64>,
    /// Wake-up period while streaming, in microseconds (100..=20000).
    pub tick_us: u64,
    pub faults: FaultConfig,
}

impl Default for MockAviaConfig {
    fn default() -> Self {
        Self {
            ip: Ipv4Addr::LOCALHOST,
            cmd_port: DEVICE_CMD_PORT,
            data_port: DEVICE_DATA_PORT,
            imu_port: DEVICE_IMU_PORT,
            broadcast_to: SocketAddrV4::new(Ipv4Addr::LOCALHOST, HOST_BROADCAST_PORT),
            broadcast_code: None,
            source: SourceConfig::Synthetic,
            capture_device: None,
            recorded_time: false,
            seed: 0,
            return_mode: ReturnSetting::Single,
            spherical: false,
            time_source: TimeSource::Ptp,
            imu_push: true,
            epoch_ns: None,
            tick_us: 1000,
            faults: FaultConfig::default(),
        }
    }
}

/// The broadcast code a mock on `ip` uses by default: "STARCMOCK" and six digits from the last
/// two octets, so mocks on 127.0.0.1, 127.0.0.2, ... differ.
pub fn default_broadcast_code(ip: Ipv4Addr) -> String {
    let o = ip.octets();
    format!("STARCMOCK{:06}", u16::from_be_bytes([o[2], o[3]]))
}

impl MockAviaConfig {
    /// A config for `ip` with everything else default.
    pub fn on(ip: Ipv4Addr) -> Self {
        Self { ip, ..Self::default() }
    }

    pub fn broadcast_code(&self) -> Result<BroadcastCode> {
        let text = self.broadcast_code.clone().unwrap_or_else(|| default_broadcast_code(self.ip));
        if text.is_empty() || !text.is_ascii() {
            return Err(HilError::config("broadcast_code", format!("{text:?} must be 1-16 ASCII characters")));
        }
        BroadcastCode::from_text(&text).map_err(|e| HilError::config("broadcast_code", e.to_string()))
    }

    pub fn validate(&self) -> Result<()> {
        self.broadcast_code()?;
        self.faults.validate()?;
        if !(100..=20_000).contains(&self.tick_us) {
            return Err(HilError::config("tick_us", format!("{} is outside 100..=20000", self.tick_us)));
        }
        if self.source == SourceConfig::Synthetic {
            if let Some(ip) = self.capture_device {
                return Err(HilError::config("capture_device", format!("{ip}: needs a capture source")));
            }
            if self.recorded_time {
                return Err(HilError::config("recorded_time", "needs a capture source"));
            }
        }
        if self.recorded_time {
            if self.epoch_ns.is_none() {
                return Err(HilError::config("recorded_time", "needs epoch_ns (the PTP time at the mock's start)"));
            }
            if !matches!(self.time_source, TimeSource::Ptp | TimeSource::Gps) {
                return Err(HilError::config(
                    "recorded_time",
                    format!("needs time_source ptp or gps to carry the recorded stamps, not {}", self.time_source),
                ));
            }
        }
        Ok(())
    }

    /// The sans-IO device's configuration; `epoch_ns` is used when the config has none.
    pub fn device_config(&self, epoch_ns: u64) -> Result<DeviceConfig> {
        self.validate()?;
        let epoch = i64::try_from(self.epoch_ns.unwrap_or(epoch_ns))
            .map_err(|_| HilError::config("epoch_ns", "beyond the year 2262"))?;
        Ok(DeviceConfig {
            broadcast_code: self.broadcast_code()?,
            broadcast_to: self.broadcast_to,
            return_mode: self.return_mode.mode(),
            coordinates: if self.spherical { CoordinateSystem::Spherical } else { CoordinateSystem::Cartesian },
            imu_push: self.imu_push,
            time_source: self.time_source,
            ptp_offset_ns: epoch,
            utc_offset_ns: epoch,
            faults: self.faults.clone(),
            seed: self.seed,
            ..DeviceConfig::default()
        })
    }

    /// The source the config names (a capture with its `capture_device` and `recorded_time`).
    pub fn open_source(&self) -> Result<Box<dyn PointSource>> {
        self.validate()?;
        Ok(match &self.source {
            SourceConfig::Synthetic => Box::new(SyntheticScene::new(self.seed)),
            SourceConfig::Capture(path) => {
                let mut capture = CaptureSource::open(path)?;
                if let Some(ip) = self.capture_device {
                    capture = capture.for_device(ip);
                }
                if let (true, Some(epoch)) = (self.recorded_time, self.epoch_ns) {
                    capture = capture.at_recorded_time(epoch);
                }
                Box::new(capture)
            }
        })
    }
}

/// Counters of a running mock: the device's and the transport's.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct MockStats {
    pub device: DeviceStats,
    /// Datagrams sent (control, points, IMU).
    pub datagrams_sent: u64,
    pub bytes_sent: u64,
    pub send_errors: u64,
    pub recv_errors: u64,
}

impl MockStats {
    /// Point and IMU packets sent.
    pub fn packets_sent(&self) -> u64 {
        self.device.point_packets + self.device.imu_packets
    }

    /// ACKs sent (refusals included).
    pub fn commands_answered(&self) -> u64 {
        self.device.answered
    }
}

struct Sockets {
    cmd: UdpSocket,
    data: UdpSocket,
    /// `None`: IMU shares the data socket.
    imu: Option<UdpSocket>,
}

/// A running mock Avia. Dropping it aborts the task; [`MockAvia::stop`] ends it cleanly.
#[derive(Debug)]
pub struct MockAvia {
    cmd_addr: SocketAddrV4,
    data_addr: SocketAddrV4,
    imu_addr: SocketAddrV4,
    code: BroadcastCode,
    stats: watch::Receiver<MockStats>,
    stop: Option<oneshot::Sender<()>>,
    task: Option<JoinHandle<()>>,
}

async fn bind(ip: Ipv4Addr, port: u16) -> Result<UdpSocket> {
    let addr = SocketAddrV4::new(ip, port);
    UdpSocket::bind(addr).await.map_err(|source| HilError::Bind { addr, source })
}

fn local_v4(socket: &UdpSocket, ip: Ipv4Addr) -> Result<SocketAddrV4> {
    match socket.local_addr() {
        Ok(SocketAddr::V4(a)) => Ok(a),
        Ok(SocketAddr::V6(a)) => Ok(SocketAddrV4::new(ip, a.port())),
        Err(source) => Err(HilError::Io { context: "reading a bound address".into(), source }),
    }
}

impl MockAvia {
    /// Binds the sockets, powers the device on and runs it on the current tokio runtime.
    pub async fn spawn(config: MockAviaConfig) -> Result<Self> {
        let source = config.open_source()?;
        Self::spawn_with_source(config, source).await
    }

    /// As [`MockAvia::spawn`] with any [`PointSource`] (the simulator's); `config.source` is
    /// ignored.
    pub async fn spawn_with_source(config: MockAviaConfig, source: Box<dyn PointSource>) -> Result<Self> {
        let device_config = config.device_config(Stamp::host_now().ns)?;
        let code = device_config.broadcast_code;
        let cmd = bind(config.ip, config.cmd_port).await?;
        cmd.set_broadcast(true).map_err(|source| HilError::Io { context: "setting SO_BROADCAST".into(), source })?;
        let data = bind(config.ip, config.data_port).await?;
        let imu = if config.imu_port == config.data_port && config.imu_port != 0 {
            None
        } else {
            Some(bind(config.ip, config.imu_port).await?)
        };
        let cmd_addr = local_v4(&cmd, config.ip)?;
        let data_addr = local_v4(&data, config.ip)?;
        let imu_addr = match &imu {
            Some(s) => local_v4(s, config.ip)?,
            None => data_addr,
        };
        let start = Instant::now();
        let device = AviaDevice::new(device_config, source, Stamp::new(0, Clock::Device))?;
        let (stats_tx, stats_rx) = watch::channel(MockStats::default());
        let (stop_tx, stop_rx) = oneshot::channel();
        let tick = Duration::from_micros(config.tick_us);
        tracing::info!(code = %code, %cmd_addr, %data_addr, %imu_addr, broadcast_to = %config.broadcast_to, "mock avia on");
        let sockets = Sockets { cmd, data, imu };
        let task = tokio::spawn(run_loop(device, sockets, start, tick, stop_rx, stats_tx));
        Ok(Self { cmd_addr, data_addr, imu_addr, code, stats: stats_rx, stop: Some(stop_tx), task: Some(task) })
    }

    /// Where the mock takes commands (and broadcasts from).
    pub fn cmd_addr(&self) -> SocketAddrV4 {
        self.cmd_addr
    }

    /// Source address of point packets.
    pub fn data_addr(&self) -> SocketAddrV4 {
        self.data_addr
    }

    /// Source address of IMU packets.
    pub fn imu_addr(&self) -> SocketAddrV4 {
        self.imu_addr
    }

    pub fn broadcast_code(&self) -> BroadcastCode {
        self.code
    }

    /// The counters now (updated after every wake-up).
    pub fn stats(&self) -> MockStats {
        *self.stats.borrow()
    }

    /// Whether the task still runs.
    pub fn is_running(&self) -> bool {
        self.task.as_ref().is_some_and(|t| !t.is_finished())
    }

    /// Stops the device (no more packets once this returns) and returns its final counters.
    pub async fn stop(mut self) -> Result<MockStats> {
        if let Some(tx) = self.stop.take() {
            let _ = tx.send(());
        }
        if let Some(task) = self.task.take() {
            task.await.map_err(|e| HilError::Task(e.to_string()))?;
        }
        Ok(*self.stats.borrow())
    }
}

impl Drop for MockAvia {
    fn drop(&mut self) {
        if let Some(task) = self.task.take() {
            task.abort();
        }
    }
}

fn device_now(start: Instant) -> Stamp {
    Stamp::new(u64::try_from(start.elapsed().as_nanos()).unwrap_or(u64::MAX), Clock::Device)
}

async fn run_loop(
    mut device: AviaDevice,
    sockets: Sockets,
    start: Instant,
    tick: Duration,
    mut stop: oneshot::Receiver<()>,
    stats_tx: watch::Sender<MockStats>,
) {
    let code = device.broadcast_code();
    let mut stats = MockStats::default();
    let mut buf = vec![0u8; 2048];
    loop {
        let actions = device.poll(device_now(start));
        execute(&sockets, actions, &mut stats, code).await;
        stats.device = device.stats();
        stats_tx.send_replace(stats);
        let deadline = if device.is_streaming() {
            Instant::now() + tick
        } else {
            let wake_ns = device.next_timer_ns().min(device_now(start).ns + NS_PER_S / 10);
            start + Duration::from_nanos(wake_ns)
        };
        tokio::select! {
            biased;
            _ = &mut stop => break,
            received = sockets.cmd.recv_from(&mut buf) => match received {
                Ok((n, SocketAddr::V4(from))) => {
                    let bytes = buf.get(..n).unwrap_or_default();
                    let actions = device.handle_datagram(device_now(start), from, bytes);
                    execute(&sockets, actions, &mut stats, code).await;
                }
                Ok((_, SocketAddr::V6(_))) => {}
                Err(e) => {
                    // ICMP port unreachable from an earlier send shows up here; keep going.
                    stats.recv_errors += 1;
                    tracing::trace!(code = %code, "recv: {e}");
                }
            },
            _ = tokio::time::sleep_until(deadline) => {}
        }
    }
    stats.device = device.stats();
    stats_tx.send_replace(stats);
    tracing::info!(code = %code, "mock avia off");
}

async fn send(socket: &UdpSocket, to: SocketAddrV4, bytes: &[u8], stats: &mut MockStats) {
    match socket.send_to(bytes, to).await {
        Ok(n) => {
            stats.datagrams_sent += 1;
            stats.bytes_sent += n as u64;
        }
        Err(e) => {
            stats.send_errors += 1;
            if stats.send_errors <= 3 {
                tracing::debug!("send to {to}: {e}");
            }
        }
    }
}

async fn execute(sockets: &Sockets, actions: Vec<Action>, stats: &mut MockStats, code: BroadcastCode) {
    for action in actions {
        match action {
            Action::SendControl { to, bytes } => {
                if tracing::enabled!(tracing::Level::DEBUG) {
                    log_control(&code, to, &bytes);
                }
                send(&sockets.cmd, to, &bytes, stats).await;
            }
            Action::SendPoints { to, bytes } => send(&sockets.data, to, &bytes, stats).await,
            Action::SendImu { to, bytes } => {
                send(sockets.imu.as_ref().unwrap_or(&sockets.data), to, &bytes, stats).await;
            }
            Action::StartStreaming { data_to, imu_to } => {
                tracing::info!(code = %code, "sampling on: points to {data_to}, imu to {imu_to}");
            }
            Action::StopStreaming => tracing::info!(code = %code, "sampling off"),
            Action::Event(event) => log_event(code, &event),
        }
    }
}

fn log_event(code: BroadcastCode, event: &DeviceEvent) {
    match event {
        DeviceEvent::Connected { host } => tracing::info!(
            code = %code,
            "handshake from {}: points to {}, imu to {}, commands to {}",
            host.from,
            host.data_to,
            host.imu_to,
            host.cmd_to
        ),
        DeviceEvent::HostLost { from, silent_ns } => tracing::warn!(
            code = %code,
            "host {from} lost: no heartbeat for {:.1} s; broadcasting again",
            *silent_ns as f64 * 1e-9
        ),
        DeviceEvent::Disconnected { from } => tracing::info!(code = %code, "host {from} disconnected"),
        DeviceEvent::TimeSourceChanged { from, to } => {
            tracing::info!(code = %code, "time source {from} -> {to}");
        }
        DeviceEvent::Refused { from, cmd_set, cmd_id, reason } => {
            tracing::debug!(code = %code, "refused ({cmd_set},{cmd_id}) from {from}: {reason}");
        }
    }
}

/// Every frame the mock sends, at debug level: what a user bringing up a host wants to see.
fn log_control(code: &impl std::fmt::Display, to: SocketAddrV4, bytes: &[u8]) {
    match starc_livox::control::ControlFrame::decode(bytes) {
        Ok(frame) => match frame.body {
            starc_livox::control::Body::Response(r) => tracing::debug!(
                code = %code,
                "ack {} seq {} ret {} to {to}",
                r.id().name(),
                frame.seq,
                r.ret()
            ),
            _ => {
                tracing::debug!(code = %code, "{} {} seq {} to {to}", frame.cmd_type.name(), frame.id().name(), frame.seq)
            }
        },
        Err(e) => tracing::debug!(code = %code, "undecodable frame to {to}: {e}"),
    }
}
