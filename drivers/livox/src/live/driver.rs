//! The tokio transport: sockets, timers and a typed event stream around [`DeviceSession`] and
//! [`ScanAssembler`].

use super::session::{DeviceSession, HostEndpoint, SessionConfig, SessionEvent, SessionOutput};
use super::socket::{bind_udp, local_v4};
use crate::control::{Body, BroadcastCode, CommandId, ControlFrame, DeviceType, Message, Request};
use crate::data::{DataHeader, DataPacket, ImuSample, Point, ReturnCounts, StatusWord};
use crate::error::{LivoxError, Result};
use crate::ports;
use crate::scan::{Scan, ScanAssembler, ScanConfig};
use serde::{Deserialize, Serialize};
use starc_time::Stamp;
use std::collections::BTreeMap;
use std::net::{Ipv4Addr, SocketAddr, SocketAddrV4};
use std::time::Duration;
use tokio::net::UdpSocket;
use tokio::sync::{mpsc, oneshot};
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
    /// Host command port (0 picks a free one; it goes into the handshake).
    pub cmd_port: u16,
    /// Host point-data port.
    pub data_port: u16,
    /// Host IMU port; equal to `data_port` shares one socket, as the SDK does.
    pub imu_port: u16,
    /// Decode packets from addresses with no session too (a replayed capture).
    pub accept_unsolicited_data: bool,
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
            cmd_port: ports::host_cmd_port(1),
            data_port: ports::host_data_port(1),
            imu_port: ports::host_data_port(1),
            accept_unsolicited_data: true,
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
    /// The ports actually bound (they go into every handshake).
    pub host: HostEndpoint,
}

struct Device {
    session: Option<DeviceSession>,
    assembler: Option<ScanAssembler>,
}

struct Core {
    config: DriverConfig,
    host: HostEndpoint,
    started: Instant,
    devices: BTreeMap<Ipv4Addr, Device>,
    events: mpsc::Sender<LivoxEvent>,
    dropped: u64,
    accept: Vec<BroadcastCode>,
}

impl LivoxDriver {
    /// Binds the host sockets and starts the driver task; events arrive on the receiver.
    pub async fn start(config: DriverConfig) -> Result<(Self, mpsc::Receiver<LivoxEvent>)> {
        config.scan.validate().map_err(LivoxError::BadConfig)?;
        let accept = config.accept_codes.iter().map(|c| BroadcastCode::from_text(c)).collect::<Result<Vec<_>>>()?;
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
        let mut core = Core {
            host,
            started: Instant::now(),
            devices: BTreeMap::new(),
            events: events_tx,
            dropped: 0,
            accept,
            config,
        };
        for ip in core.config.connect.clone() {
            core.add_session(ip, None);
        }
        tracing::info!(cmd = %host.cmd_port, data = %host.data_port, imu = %host.imu_port, ip = %host.ip, "livox driver started");
        let task = tokio::spawn(run(core, cmd, data, imu, broadcast, control_rx));
        Ok((Self { control: control_tx, task, host }, events_rx))
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

fn v4(addr: SocketAddr) -> Option<SocketAddrV4> {
    match addr {
        SocketAddr::V4(a) => Some(a),
        SocketAddr::V6(_) => None,
    }
}

async fn run(
    mut core: Core,
    cmd: UdpSocket,
    data: UdpSocket,
    imu: Option<UdpSocket>,
    broadcast: Option<UdpSocket>,
    mut control: mpsc::Receiver<Control>,
) {
    let mut tick = tokio::time::interval(Duration::from_millis(20));
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
    let (mut cbuf, mut dbuf, mut ibuf, mut bbuf) = ([0u8; 2048], [0u8; 2048], [0u8; 2048], [0u8; 2048]);
    loop {
        let mut outgoing: Vec<(Ipv4Addr, Vec<u8>)> = Vec::new();
        tokio::select! {
            r = data.recv_from(&mut dbuf) => {
                if let Ok((n, from)) = r {
                    core.on_data(from, &dbuf[..n.min(dbuf.len())]);
                }
            }
            r = recv_opt(&imu, &mut ibuf) => {
                if let Ok((n, from)) = r {
                    core.on_data(from, &ibuf[..n.min(ibuf.len())]);
                }
            }
            r = cmd.recv_from(&mut cbuf) => {
                if let Ok((n, from)) = r {
                    outgoing = core.on_control(from, &cbuf[..n.min(cbuf.len())]);
                }
            }
            r = recv_opt(&broadcast, &mut bbuf) => {
                if let Ok((n, from)) = r {
                    outgoing = core.on_broadcast(from, &bbuf[..n.min(bbuf.len())]);
                }
            }
            _ = tick.tick() => {
                outgoing = core.poll();
            }
            c = control.recv() => match c {
                Some(Control::Send { ip, request }) => {
                    if let Some(s) = core.devices.get_mut(&ip).and_then(|d| d.session.as_mut()) {
                        s.enqueue(request);
                    }
                    outgoing = core.poll();
                }
                Some(Control::Stop(done)) => {
                    for (ip, bytes) in core.close() {
                        let _ = cmd.send_to(&bytes, SocketAddrV4::new(ip, ports::DEVICE_CMD_PORT)).await;
                    }
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

impl Core {
    fn now_ns(&self) -> u64 {
        u64::try_from(self.started.elapsed().as_nanos()).unwrap_or(u64::MAX)
    }

    fn emit(&mut self, event: LivoxEvent) {
        if self.dropped > 0 && self.events.try_send(LivoxEvent::Dropped { events: self.dropped }).is_ok() {
            self.dropped = 0;
        }
        if self.events.try_send(event).is_err() {
            self.dropped += 1;
        }
    }

    fn add_session(&mut self, ip: Ipv4Addr, code: Option<BroadcastCode>) {
        let session = DeviceSession::new(code, self.host, self.config.session.clone());
        let assembler = ScanAssembler::new(self.config.scan.clone()).ok();
        self.devices.insert(ip, Device { session: Some(session), assembler });
    }

    /// A verified control frame, or a `BadDatagram` event saying why not.
    fn decode_control(&mut self, from: SocketAddrV4, bytes: &[u8]) -> Option<ControlFrame> {
        match ControlFrame::decode(bytes) {
            Ok(f) => Some(f),
            Err(e) => {
                self.emit(LivoxEvent::BadDatagram { from, error: e.to_string() });
                None
            }
        }
    }

    fn on_broadcast(&mut self, from: SocketAddr, bytes: &[u8]) -> Vec<(Ipv4Addr, Vec<u8>)> {
        let Some(from) = v4(from) else { return Vec::new() };
        let Some(frame) = self.decode_control(from, bytes) else { return Vec::new() };
        let Body::Message(Message::Broadcast { code, device_type }) = frame.body else { return Vec::new() };
        let ip = *from.ip();
        let known = self.devices.get(&ip).is_some_and(|d| d.session.is_some());
        if known || (!self.accept.is_empty() && !self.accept.contains(&code)) {
            return Vec::new();
        }
        tracing::info!(%ip, code = %code, device = %device_type.name(), "discovered");
        self.emit(LivoxEvent::Discovered { ip, code, device_type });
        self.add_session(ip, Some(code));
        self.poll()
    }

    fn on_control(&mut self, from: SocketAddr, bytes: &[u8]) -> Vec<(Ipv4Addr, Vec<u8>)> {
        let Some(from) = v4(from) else { return Vec::new() };
        let Some(frame) = self.decode_control(from, bytes) else { return Vec::new() };
        let ip = *from.ip();
        let now = self.now_ns();
        let outputs = match self.devices.get_mut(&ip).and_then(|d| d.session.as_mut()) {
            Some(s) => s.handle(now, &frame),
            None => return Vec::new(),
        };
        self.apply(ip, outputs)
    }

    fn poll(&mut self) -> Vec<(Ipv4Addr, Vec<u8>)> {
        let now = self.now_ns();
        let mut all = Vec::new();
        let ips: Vec<Ipv4Addr> = self.devices.keys().copied().collect();
        for ip in ips {
            let outputs = match self.devices.get_mut(&ip).and_then(|d| d.session.as_mut()) {
                Some(s) => s.poll(now),
                None => continue,
            };
            all.extend(self.apply(ip, outputs));
        }
        all
    }

    fn apply(&mut self, ip: Ipv4Addr, outputs: Vec<SessionOutput>) -> Vec<(Ipv4Addr, Vec<u8>)> {
        let mut sends = Vec::new();
        for o in outputs {
            match o {
                SessionOutput::Send(bytes) => sends.push((ip, bytes)),
                SessionOutput::Event(e) => {
                    let event = match e {
                        SessionEvent::Connected => {
                            let code = self.devices.get(&ip).and_then(|d| d.session.as_ref()).and_then(|s| s.code);
                            tracing::info!(%ip, "connected");
                            LivoxEvent::Connected { ip, code }
                        }
                        SessionEvent::Configured => LivoxEvent::Configured { ip },
                        SessionEvent::DeviceInfo { firmware } => LivoxEvent::DeviceInfo { ip, firmware },
                        SessionEvent::Heartbeat { work_state, status } => {
                            LivoxEvent::Heartbeat { ip, work_state, status }
                        }
                        SessionEvent::Refused { command, ret } => {
                            tracing::warn!(%ip, command = command.name(), ret, "device refused a command");
                            LivoxEvent::Refused { ip, command, ret }
                        }
                        SessionEvent::Unanswered { command } => {
                            tracing::warn!(%ip, command = command.name(), "device did not answer");
                            LivoxEvent::Unanswered { ip, command }
                        }
                        SessionEvent::Lost => {
                            tracing::warn!(%ip, "device lost (3 s without an answer); reconnecting");
                            LivoxEvent::Lost { ip }
                        }
                        SessionEvent::AbnormalStatus { status } => {
                            tracing::warn!(%ip, status = %status.describe(), "abnormal status");
                            LivoxEvent::AbnormalStatus { ip, status }
                        }
                        SessionEvent::Acked { .. } => continue,
                    };
                    self.emit(event);
                }
            }
        }
        sends
    }

    fn on_data(&mut self, from: SocketAddr, bytes: &[u8]) {
        let host_receive = Stamp::host_now();
        let Some(from) = v4(from) else { return };
        let ip = *from.ip();
        if !self.devices.contains_key(&ip) {
            if !self.config.accept_unsolicited_data {
                return;
            }
            let assembler = ScanAssembler::new(self.config.scan.clone()).ok();
            self.devices.insert(ip, Device { session: None, assembler });
        }
        let packet = match DataPacket::parse(bytes) {
            Ok(p) => p,
            Err(e) => {
                self.emit(LivoxEvent::BadDatagram { from, error: e.to_string() });
                return;
            }
        };
        if let Some(sample) = packet.imu() {
            self.emit(LivoxEvent::Imu(ImuReading {
                ip,
                device_time: packet.header.timestamp,
                status: packet.header.status,
                sample,
                host_receive,
            }));
            return;
        }
        let mut done = Vec::new();
        let assembler = self.devices.get_mut(&ip).and_then(|d| d.assembler.as_mut());
        if self.config.emit_packets {
            // Decode once: the assembler takes the same points the event carries.
            let mut points = Vec::new();
            let counts = packet.decode_points(&mut points);
            if let Some(a) = assembler {
                a.push_points(&packet.header, &points, counts, Some(host_receive), &mut done);
            }
            self.emit(LivoxEvent::Points(PointPacket { ip, header: packet.header, points, counts, host_receive }));
        } else if let Some(a) = assembler {
            a.push(&packet, Some(host_receive), &mut done);
        }
        for scan in done {
            self.emit(LivoxEvent::Scan { ip, scan });
        }
    }

    fn close(&mut self) -> Vec<(Ipv4Addr, Vec<u8>)> {
        let mut frames = Vec::new();
        let mut scans = Vec::new();
        for (ip, d) in self.devices.iter_mut() {
            if let Some(s) = d.session.as_mut() {
                frames.extend(s.close().into_iter().map(|b| (*ip, b)));
            }
            if let Some(scan) = d.assembler.as_mut().and_then(|a| a.finish()) {
                scans.push((*ip, scan));
            }
        }
        for (ip, scan) in scans {
            self.emit(LivoxEvent::Scan { ip, scan });
        }
        frames
    }
}
