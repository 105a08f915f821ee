//! The tokio transport: sockets, timers and a typed event stream around the sans-IO driver state
//! ([`super::table`]: sessions, scan assemblers, the device table and its bounds).

use super::session::{HostEndpoint, SessionConfig};
use super::socket::{bind_udp, local_v4};
use super::table::{Core, DriverStats};
use crate::control::{BroadcastCode, CommandId, DeviceType, Request};
use crate::data::{DataHeader, ImuSample, Point, ReturnCounts, StatusWord};
use crate::error::{LivoxError, Result};
use crate::ports;
use crate::scan::{Scan, ScanConfig};
use serde::{Deserialize, Serialize};
use starc_time::Stamp;
use std::net::{Ipv4Addr, SocketAddr, SocketAddrV4};
use std::time::Duration;
use tokio::net::UdpSocket;
use tokio::sync::{mpsc, oneshot, watch};
use tokio::task::JoinHandle;
use tokio::time::Instant;

/// How the host finds and talks to its devices (`[livox]` in a node config).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DriverConfig {
    /// The host address devices send data and ACKs to; host sockets bind to it.
    pub host_ip: Ipv4Addr,
    /// Listen for broadcasts here (0.0.0.0 hears real broadcasts); none disables discovery.
    pub broadcast_listen: Option<SocketAddrV4>,
    /// Connect to these device addresses without waiting for their broadcast.
    pub connect: Vec<Ipv4Addr>,
    /// Only connect to these broadcast codes (empty: every device heard).
    pub accept_codes: Vec<String>,
    /// Connect to a device whose broadcast comes from one of these addresses too, whatever its
    /// code (a node's `lidar_ip` lands here, so a config that names its Avia takes only it).
    pub accept_ips: Vec<Ipv4Addr>,
    /// Host command port (0 picks a free one; it goes into the handshake).
    pub cmd_port: u16,
    /// Host point-data port.
    pub data_port: u16,
    /// Host IMU port; equal to `data_port` shares one socket, as the SDK does.
    pub imu_port: u16,
    /// Decode packets from addresses with no session too (a replayed capture). Off, they are
    /// dropped and counted (`DriverStats::unsolicited_data`): anyone on the network could
    /// otherwise feed the LIO, each spoofed address costing a scan assembler. A passive driver
    /// (no `broadcast_listen`, no `connect`) takes them whatever this says: it has no other way
    /// to get data.
    pub accept_unsolicited_data: bool,
    /// Connect to devices whose broadcast code is not in `accept_codes` (and whose address is
    /// not in `connect` or `accept_ips`) too. A config that names no device at all (all three
    /// lists empty) takes any device heard, as this does; one that names its devices takes only
    /// them.
    pub accept_any_device: bool,
    /// Devices held at once (sessions and data-only senders, each with a scan in progress);
    /// a new one beyond is refused and counted. 32 is the Livox SDK's own limit.
    pub max_devices: usize,
    /// A device not in `connect` that sent nothing that decoded for this long is forgotten:
    /// its session and scan in progress are dropped (a real device broadcasts again and is
    /// found again). Devices in `connect` are kept and their handshake retried.
    pub forget_after_ms: u64,
    /// Emit every point packet as an event (scans are always assembled).
    pub emit_packets: bool,
    pub session: SessionConfig,
    pub scan: ScanConfig,
    /// Events buffered for a slow consumer; point packets beyond it are dropped and counted.
    pub channel_capacity: usize,
}

impl Default for DriverConfig {
    fn default() -> Self {
        Self {
            host_ip: Ipv4Addr::LOCALHOST,
            broadcast_listen: Some(SocketAddrV4::new(Ipv4Addr::UNSPECIFIED, ports::HOST_BROADCAST_PORT)),
            connect: Vec::new(),
            accept_codes: Vec::new(),
            accept_ips: Vec::new(),
            cmd_port: ports::host_cmd_port(1),
            data_port: ports::host_data_port(1),
            imu_port: ports::host_data_port(1),
            accept_unsolicited_data: false,
            accept_any_device: false,
            max_devices: 32,
            forget_after_ms: 10_000,
            emit_packets: false,
            session: SessionConfig::default(),
            scan: ScanConfig::default(),
            channel_capacity: 4096,
        }
    }
}

/// A point packet as received.
#[derive(Clone, Debug, PartialEq)]
pub struct PointPacket {
    pub ip: Ipv4Addr,
    pub header: DataHeader,
    pub points: Vec<Point>,
    pub counts: ReturnCounts,
    pub host_receive: Stamp,
}

/// One IMU sample with both of its times.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ImuReading {
    pub ip: Ipv4Addr,
    pub device_time: Stamp,
    pub status: StatusWord,
    pub sample: ImuSample,
    pub host_receive: Stamp,
}

/// What the driver reports.
#[derive(Clone, Debug, PartialEq)]
pub enum LivoxEvent {
    Discovered {
        ip: Ipv4Addr,
        code: BroadcastCode,
        device_type: DeviceType,
    },
    Connected {
        ip: Ipv4Addr,
        code: Option<BroadcastCode>,
    },
    Configured {
        ip: Ipv4Addr,
    },
    DeviceInfo {
        ip: Ipv4Addr,
        firmware: [u8; 4],
    },
    Heartbeat {
        ip: Ipv4Addr,
        work_state: u8,
        status: StatusWord,
    },
    Refused {
        ip: Ipv4Addr,
        command: CommandId,
        ret: u8,
    },
    Unanswered {
        ip: Ipv4Addr,
        command: CommandId,
    },
    Lost {
        ip: Ipv4Addr,
    },
    AbnormalStatus {
        ip: Ipv4Addr,
        status: StatusWord,
    },
    Points(PointPacket),
    Scan {
        ip: Ipv4Addr,
        scan: Scan,
    },
    Imu(ImuReading),
    /// A datagram that did not decode (bad CRC, wrong length, ...).
    BadDatagram {
        from: SocketAddrV4,
        error: String,
    },
    /// Events dropped because the consumer was too slow (reported once it catches up).
    Dropped {
        events: u64,
    },
}

enum Control {
    Send { ip: Ipv4Addr, request: Request },
    Stop(oneshot::Sender<()>),
}

/// A running driver. Dropping it stops the task without saying goodbye; prefer [`stop`].
///
/// [`stop`]: LivoxDriver::stop
pub struct LivoxDriver {
    control: mpsc::Sender<Control>,
    task: JoinHandle<()>,
    stats: watch::Receiver<DriverStats>,
    /// The ports actually bound (they go into every handshake).
    pub host: HostEndpoint,
}

impl LivoxDriver {
    /// Binds the host sockets and starts the driver task; events arrive on the receiver.
    pub async fn start(config: DriverConfig) -> Result<(Self, mpsc::Receiver<LivoxEvent>)> {
        config.validate()?;
        let cmd = bind_udp(SocketAddrV4::new(config.host_ip, config.cmd_port), false, false)?;
        let data = bind_udp(SocketAddrV4::new(config.host_ip, config.data_port), false, false)?;
        let data_port = local_v4(&data)?.port();
        let imu = if config.imu_port == config.data_port {
            None
        } else {
            Some(bind_udp(SocketAddrV4::new(config.host_ip, config.imu_port), false, false)?)
        };
        let imu_port = match &imu {
            Some(s) => local_v4(s)?.port(),
            None => data_port,
        };
        let broadcast = match config.broadcast_listen {
            Some(addr) => Some(bind_udp(addr, true, true)?),
            None => None,
        };
        let host = HostEndpoint { ip: config.host_ip, cmd_port: local_v4(&cmd)?.port(), data_port, imu_port };
        let (events_tx, events_rx) = mpsc::channel(config.channel_capacity.max(16));
        let (control_tx, control_rx) = mpsc::channel(64);
        let core = Core::new(config, host, events_tx)?;
        let (stats_tx, stats_rx) = watch::channel(core.stats());
        tracing::info!(cmd = %host.cmd_port, data = %host.data_port, imu = %host.imu_port, ip = %host.ip, "livox driver started");
        let sockets = Sockets { cmd, data, imu, broadcast };
        let task = tokio::spawn(run(core, sockets, control_rx, stats_tx));
        Ok((Self { control: control_tx, task, stats: stats_rx, host }, events_rx))
    }

    /// The driver's counters: devices held, what it refused, dropped and cut (updated every
    /// 20 ms).
    pub fn stats(&self) -> DriverStats {
        *self.stats.borrow()
    }

    /// Sends a command to a connected device (after its queued setup commands).
    pub async fn command(&self, ip: Ipv4Addr, request: Request) -> Result<()> {
        self.control.send(Control::Send { ip, request }).await.map_err(|_| LivoxError::Timeout("driver task".into()))
    }

    /// Stops sampling on every device, disconnects, flushes the last scans and ends the task.
    pub async fn stop(self) -> Result<()> {
        let (tx, rx) = oneshot::channel();
        if self.control.send(Control::Stop(tx)).await.is_ok() {
            let _ = tokio::time::timeout(Duration::from_secs(2), rx).await;
        }
        let _ = tokio::time::timeout(Duration::from_secs(2), self.task).await;
        Ok(())
    }
}

async fn recv_opt(socket: &Option<UdpSocket>, buf: &mut [u8]) -> std::io::Result<(usize, SocketAddr)> {
    match socket {
        Some(s) => s.recv_from(buf).await,
        None => std::future::pending().await,
    }
}

struct Sockets {
    cmd: UdpSocket,
    data: UdpSocket,
    imu: Option<UdpSocket>,
    broadcast: Option<UdpSocket>,
}

async fn run(
    mut core: Core,
    sockets: Sockets,
    mut control: mpsc::Receiver<Control>,
    stats: watch::Sender<DriverStats>,
) {
    let Sockets { cmd, data, imu, broadcast } = sockets;
    let started = Instant::now();
    let now_ns = || u64::try_from(started.elapsed().as_nanos()).unwrap_or(u64::MAX);
    let mut tick = tokio::time::interval(Duration::from_millis(20));
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
    let (mut cbuf, mut dbuf, mut ibuf, mut bbuf) = ([0u8; 2048], [0u8; 2048], [0u8; 2048], [0u8; 2048]);
    loop {
        let mut outgoing: Vec<(Ipv4Addr, Vec<u8>)> = Vec::new();
        tokio::select! {
            r = data.recv_from(&mut dbuf) => {
                if let Ok((n, from)) = r {
                    core.on_data(now_ns(), from, &dbuf[..n.min(dbuf.len())], Stamp::host_now());
                }
            }
            r = recv_opt(&imu, &mut ibuf) => {
                if let Ok((n, from)) = r {
                    core.on_data(now_ns(), from, &ibuf[..n.min(ibuf.len())], Stamp::host_now());
                }
            }
            r = cmd.recv_from(&mut cbuf) => {
                if let Ok((n, from)) = r {
                    outgoing = core.on_control(now_ns(), from, &cbuf[..n.min(cbuf.len())]);
                }
            }
            r = recv_opt(&broadcast, &mut bbuf) => {
                if let Ok((n, from)) = r {
                    outgoing = core.on_broadcast(now_ns(), from, &bbuf[..n.min(bbuf.len())]);
                }
            }
            _ = tick.tick() => {
                outgoing = core.poll(now_ns());
                let now = core.stats();
                stats.send_if_modified(|s| {
                    let changed = *s != now;
                    *s = now;
                    changed
                });
            }
            c = control.recv() => match c {
                Some(Control::Send { ip, request }) => {
                    core.enqueue(ip, request);
                    outgoing = core.poll(now_ns());
                }
                Some(Control::Stop(done)) => {
                    for (ip, bytes) in core.close() {
                        let _ = cmd.send_to(&bytes, SocketAddrV4::new(ip, ports::DEVICE_CMD_PORT)).await;
                    }
                    stats.send_replace(core.stats());
                    let _ = done.send(());
                    return;
                }
                None => return,
            }
        }
        for (ip, bytes) in outgoing {
            if let Err(e) = cmd.send_to(&bytes, SocketAddrV4::new(ip, ports::DEVICE_CMD_PORT)).await {
                tracing::warn!(%ip, error = %e, "sending a command failed");
            }
        }
    }
}
