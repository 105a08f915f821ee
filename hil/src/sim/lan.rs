//! A virtual Ethernet segment on the simulator's clock: a mock Avia ([`AviaDevice`]) and a host
//! ([`DeviceSession`], the live driver's own protocol core) exchange their real datagrams:
//! broadcast, handshake, setup commands, heartbeats, point and IMU packets. Every datagram is
//! handed to a tap (the pcap writer) with its time and addresses, as a switch's mirror port would.

use crate::avia::device::DEFAULT_EPOCH_NS;
use crate::avia::run::{DEVICE_DATA_PORT, DEVICE_IMU_PORT};
use crate::avia::{Action, AviaDevice, DeviceConfig, DeviceEvent, PointSource, ReturnSetting};
use crate::error::Result;
use starc_livox::control::{Body, BroadcastCode, ControlFrame, Message};
use starc_livox::live::session::{DeviceSession, HostEndpoint, SessionConfig, SessionOutput};
use starc_livox::ports::{host_cmd_port, host_data_port, DEVICE_CMD_PORT, HOST_BROADCAST_PORT};
use starc_time::{Clock, Stamp};
use std::net::{Ipv4Addr, SocketAddrV4};

/// One datagram on the wire.
pub struct Wire<'a> {
    pub time_ns: u64,
    pub src: SocketAddrV4,
    pub dst: SocketAddrV4,
    pub payload: &'a [u8],
}

/// Counts of one link.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct LinkStats {
    pub control_frames: u64,
    pub point_packets: u64,
    pub imu_packets: u64,
    pub connected_at_ns: Option<u64>,
}

/// A mock Avia and its host on one segment.
pub struct AviaLink {
    pub name: String,
    device_ip: Ipv4Addr,
    host: HostEndpoint,
    code: BroadcastCode,
    power_on_ns: u64,
    return_mode: ReturnSetting,
    source: Option<Box<dyn PointSource>>,
    device: Option<AviaDevice>,
    session: Option<DeviceSession>,
    /// Host commands on their way to the device.
    pending: Vec<Vec<u8>>,
    stats: LinkStats,
}

impl AviaLink {
    /// A device at `device_ip` that powers on at `power_on_ns` (simulator time), and its host.
    pub fn new(
        name: &str,
        device_ip: Ipv4Addr,
        host_ip: Ipv4Addr,
        code: BroadcastCode,
        power_on_ns: u64,
        return_mode: ReturnSetting,
        source: Box<dyn PointSource>,
    ) -> Self {
        let host = HostEndpoint {
            ip: host_ip,
            cmd_port: host_cmd_port(1),
            data_port: host_data_port(1),
            imu_port: host_data_port(1),
        };
        Self {
            name: name.into(),
            device_ip,
            host,
            code,
            power_on_ns,
            return_mode,
            source: Some(source),
            device: None,
            session: None,
            pending: Vec::new(),
            stats: LinkStats::default(),
        }
    }

    pub fn stats(&self) -> LinkStats {
        self.stats
    }

    pub fn device_ip(&self) -> Ipv4Addr {
        self.device_ip
    }

    pub fn host_ip(&self) -> Ipv4Addr {
        self.host.ip
    }

    pub fn broadcast_code(&self) -> BroadcastCode {
        self.code
    }

    /// PTP time = simulator time + this.
    pub fn ptp_offset_ns() -> i64 {
        DEFAULT_EPOCH_NS
    }

    /// Advances the segment to `now_ns`, handing every datagram to `tap`. Commands the host
    /// sends reach the device at the next step (the caller's step is the network's latency).
    pub fn step(&mut self, now_ns: u64, tap: &mut dyn FnMut(Wire<'_>) -> Result<()>) -> Result<()> {
        if self.device.is_none() && now_ns >= self.power_on_ns {
            if let Some(source) = self.source.take() {
                let config = DeviceConfig {
                    broadcast_code: self.code,
                    broadcast_to: SocketAddrV4::new(Ipv4Addr::BROADCAST, HOST_BROADCAST_PORT),
                    return_mode: self.return_mode.mode(),
                    ..DeviceConfig::default()
                };
                self.device = Some(AviaDevice::new(config, source, Stamp::new(now_ns, Clock::Device))?);
            }
        }
        let Some(device) = self.device.as_mut() else { return Ok(()) };
        let now = Stamp::new(now_ns, Clock::Device);
        let dev_cmd = SocketAddrV4::new(self.device_ip, DEVICE_CMD_PORT);
        let host_cmd = SocketAddrV4::new(self.host.ip, self.host.cmd_port);
        let mut from_device = Vec::new();
        for bytes in std::mem::take(&mut self.pending) {
            self.stats.control_frames += 1;
            tap(Wire { time_ns: now_ns, src: host_cmd, dst: dev_cmd, payload: &bytes })?;
            from_device.extend(device.handle_datagram(now, host_cmd, &bytes));
        }
        from_device.extend(device.poll(now));
        for action in from_device {
            match action {
                Action::SendControl { to, bytes } => {
                    self.stats.control_frames += 1;
                    tap(Wire { time_ns: now_ns, src: dev_cmd, dst: to, payload: &bytes })?;
                    let Ok(frame) = ControlFrame::decode(&bytes) else { continue };
                    let outputs = match (&mut self.session, &frame.body) {
                        (None, Body::Message(Message::Broadcast { code, .. })) if *code == self.code => {
                            let config = SessionConfig { return_mode: None, ..SessionConfig::default() };
                            let session = self.session.insert(DeviceSession::new(Some(self.code), self.host, config));
                            session.poll(now_ns)
                        }
                        (Some(session), _) => session.handle(now_ns, &frame),
                        (None, _) => Vec::new(),
                    };
                    self.pending.extend(sends(outputs));
                }
                Action::SendPoints { to, bytes } => {
                    self.stats.point_packets += 1;
                    let src = SocketAddrV4::new(self.device_ip, DEVICE_DATA_PORT);
                    tap(Wire { time_ns: now_ns, src, dst: to, payload: &bytes })?;
                }
                Action::SendImu { to, bytes } => {
                    self.stats.imu_packets += 1;
                    let src = SocketAddrV4::new(self.device_ip, DEVICE_IMU_PORT);
                    tap(Wire { time_ns: now_ns, src, dst: to, payload: &bytes })?;
                }
                Action::Event(DeviceEvent::Connected { .. }) => {
                    self.stats.connected_at_ns.get_or_insert(now_ns);
                }
                Action::StartStreaming { .. } | Action::StopStreaming | Action::Event(_) => {}
            }
        }
        if let Some(session) = self.session.as_mut() {
            self.pending.extend(sends(session.poll(now_ns)));
        }
        Ok(())
    }
}

/// The datagrams among a host session's outputs (its events are not needed here).
fn sends(outputs: Vec<SessionOutput>) -> impl Iterator<Item = Vec<u8>> {
    outputs.into_iter().filter_map(|o| match o {
        SessionOutput::Send(b) => Some(b),
        SessionOutput::Event(_) => None,
    })
}
