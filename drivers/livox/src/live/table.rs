//! The driver's state, sans-IO: which devices it holds, their sessions and scan assemblers, and
//! what it refused. Datagrams go in with their source address and the host time; frames to send
//! come out, events go to the channel. The tokio task in [`super::driver`] owns sockets and
//! clocks, so everything here runs in tests without a network.
//!
//! Every sender costs memory (a session, a scan in progress), so the table is bounded: only
//! devices the config names are taken unless it opts in to others, at most `max_devices` are
//! held, and one not named in `connect` is forgotten after `forget_after_ms` of silence.

use super::driver::{DriverConfig, ImuReading, LivoxEvent, PointPacket};
use super::session::{DeviceSession, HostEndpoint, SessionEvent, SessionOutput};
use crate::control::{Body, BroadcastCode, ControlFrame, Message, Request};
use crate::data::DataPacket;
use crate::error::{LivoxError, Result};
use crate::scan::ScanAssembler;
use serde::Serialize;
use starc_time::Stamp;
use std::collections::BTreeMap;
use std::net::{Ipv4Addr, SocketAddr, SocketAddrV4};
use tokio::sync::mpsc;

/// What the driver holds and what it refused since it started (`LivoxDriver::stats`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct DriverStats {
    /// Devices held now: sessions and data-only senders, at most `max_devices`.
    pub devices: usize,
    /// Of those, devices with a control session (handshake, heartbeats).
    pub sessions: usize,
    /// Broadcasts from devices the config does not name (`accept_codes`, `connect`), ignored.
    pub unknown_broadcasts: u64,
    /// Data datagrams from addresses without a session, dropped (`accept_unsolicited_data` off).
    pub unsolicited_data: u64,
    /// Control frames from addresses without a session, ignored.
    pub unsolicited_control: u64,
    /// New devices refused because `max_devices` were held.
    pub refused_full: u64,
    /// Devices forgotten after `forget_after_ms` without a valid datagram.
    pub forgotten: u64,
    /// IMU packets holding a NaN or an infinity, dropped.
    pub non_finite_imu: u64,
    /// Points with a NaN or infinite coordinate, dropped.
    pub non_finite_points: u64,
    /// Points dropped because their scan held `scan.max_points_per_s` over its period already.
    pub cut_points: u64,
    /// Scans cut at that cap.
    pub cut_scans: u64,
    /// Datagrams that did not decode.
    pub bad_datagrams: u64,
    /// Events dropped because the consumer was slow.
    pub dropped_events: u64,
}

struct Device {
    session: Option<DeviceSession>,
    assembler: Option<ScanAssembler>,
    /// Named in `connect`: kept however long it is silent (its handshake is retried).
    pinned: bool,
    /// Host time of the last datagram from it that decoded.
    last_heard_ns: u64,
}

/// Sends to a device's command port: its address and the frame.
pub(crate) type Sends = Vec<(Ipv4Addr, Vec<u8>)>;

pub(crate) struct Core {
    config: DriverConfig,
    host: HostEndpoint,
    devices: BTreeMap<Ipv4Addr, Device>,
    events: mpsc::Sender<LivoxEvent>,
    /// Events dropped since the last `Dropped` event went out.
    dropped: u64,
    accept: Vec<BroadcastCode>,
    /// Any device heard may connect: `accept_any_device`, or a config that names none.
    open: bool,
    /// Data from addresses without a session is taken: `accept_unsolicited_data`, or a passive
    /// driver (no discovery, no `connect`), which has no other way to get any.
    takes_unsolicited: bool,
    stats: DriverStats,
}

/// Whether the `n`th occurrence of something is worth a log line: the 1st, 2nd, 4th, 8th...,
/// so that a flood logs a handful of lines, not one per datagram.
fn worth_logging(n: u64) -> bool {
    n.is_power_of_two()
}

fn v4(addr: SocketAddr) -> Option<SocketAddrV4> {
    match addr {
        SocketAddr::V4(a) => Some(a),
        SocketAddr::V6(_) => None,
    }
}

impl DriverConfig {
    /// Checks the values; the error names the key.
    pub fn validate(&self) -> Result<()> {
        self.scan.validate().map_err(LivoxError::BadConfig)?;
        if self.max_devices == 0 {
            return Err(LivoxError::BadConfig("max_devices must be at least 1".into()));
        }
        let mut connect = self.connect.clone();
        connect.sort_unstable();
        connect.dedup();
        if connect.len() > self.max_devices {
            return Err(LivoxError::BadConfig(format!(
                "connect names {} devices, more than max_devices ({})",
                connect.len(),
                self.max_devices
            )));
        }
        if self.forget_after_ms == 0 {
            return Err(LivoxError::BadConfig("forget_after_ms must be at least 1".into()));
        }
        for c in &self.accept_codes {
            BroadcastCode::from_text(c)?;
        }
        Ok(())
    }
}

impl Core {
    /// A driver state with the `connect` devices' sessions (their handshakes go out on the
    /// first [`Core::poll`]).
    pub(crate) fn new(config: DriverConfig, host: HostEndpoint, events: mpsc::Sender<LivoxEvent>) -> Result<Self> {
        config.validate()?;
        let accept = config.accept_codes.iter().map(|c| BroadcastCode::from_text(c)).collect::<Result<Vec<_>>>()?;
        let names_none = accept.is_empty() && config.connect.is_empty() && config.accept_ips.is_empty();
        let open = config.accept_any_device || names_none;
        if open && !config.accept_any_device && config.broadcast_listen.is_some() {
            tracing::warn!(
                max_devices = config.max_devices,
                "no Livox device configured (connect, accept_codes, accept_ips): any device heard is taken"
            );
        }
        let takes_unsolicited =
            config.accept_unsolicited_data || (config.broadcast_listen.is_none() && config.connect.is_empty());
        let mut core = Self {
            takes_unsolicited,
            host,
            devices: BTreeMap::new(),
            events,
            dropped: 0,
            accept,
            open,
            stats: DriverStats::default(),
            config,
        };
        for ip in core.config.connect.clone() {
            core.add_session(0, ip, None, true);
        }
        Ok(core)
    }

    pub(crate) fn stats(&self) -> DriverStats {
        DriverStats {
            devices: self.devices.len(),
            sessions: self.devices.values().filter(|d| d.session.is_some()).count(),
            ..self.stats
        }
    }

    fn emit(&mut self, event: LivoxEvent) {
        if self.dropped > 0 && self.events.try_send(LivoxEvent::Dropped { events: self.dropped }).is_ok() {
            self.dropped = 0;
        }
        if self.events.try_send(event).is_err() {
            self.dropped += 1;
            self.stats.dropped_events += 1;
        }
    }

    /// Room for one more device; counts and logs a refusal when there is none.
    fn has_room(&mut self, ip: Ipv4Addr) -> bool {
        if self.devices.len() < self.config.max_devices {
            return true;
        }
        self.stats.refused_full += 1;
        if worth_logging(self.stats.refused_full) {
            tracing::warn!(%ip, max_devices = self.config.max_devices, refused = self.stats.refused_full,
                "Livox device table full: new device refused");
        }
        false
    }

    fn new_assembler(&self) -> Option<ScanAssembler> {
        ScanAssembler::new(self.config.scan.clone()).ok()
    }

    /// Gives `ip` a session, keeping the scan it may be assembling already (a data-only sender
    /// that broadcasts). The caller has checked for room.
    fn add_session(&mut self, now_ns: u64, ip: Ipv4Addr, code: Option<BroadcastCode>, pinned: bool) {
        let session = DeviceSession::new(code, self.host, self.config.session.clone());
        let assembler = match self.devices.remove(&ip) {
            Some(d) => d.assembler.or_else(|| self.new_assembler()),
            None => self.new_assembler(),
        };
        self.devices.insert(ip, Device { session: Some(session), assembler, pinned, last_heard_ns: now_ns });
    }

    /// Queues a command for a device with a session (ignored for others).
    pub(crate) fn enqueue(&mut self, ip: Ipv4Addr, request: Request) {
        if let Some(s) = self.devices.get_mut(&ip).and_then(|d| d.session.as_mut()) {
            s.enqueue(request);
        }
    }

    /// A verified control frame, or a `BadDatagram` event saying why not.
    fn decode_control(&mut self, from: SocketAddrV4, bytes: &[u8]) -> Option<ControlFrame> {
        match ControlFrame::decode(bytes) {
            Ok(f) => Some(f),
            Err(e) => {
                self.stats.bad_datagrams += 1;
                self.emit(LivoxEvent::BadDatagram { from, error: e.to_string() });
                None
            }
        }
    }

    pub(crate) fn on_broadcast(&mut self, now_ns: u64, from: SocketAddr, bytes: &[u8]) -> Sends {
        let Some(from) = v4(from) else { return Vec::new() };
        let Some(frame) = self.decode_control(from, bytes) else { return Vec::new() };
        let Body::Message(Message::Broadcast { code, device_type }) = frame.body else { return Vec::new() };
        let ip = *from.ip();
        if let Some(d) = self.devices.get_mut(&ip) {
            d.last_heard_ns = now_ns;
            if d.session.is_some() {
                return Vec::new();
            }
        }
        if !(self.open || self.accept.contains(&code) || self.config.accept_ips.contains(&ip)) {
            self.stats.unknown_broadcasts += 1;
            if worth_logging(self.stats.unknown_broadcasts) {
                tracing::warn!(%ip, code = %code, ignored = self.stats.unknown_broadcasts,
                    "broadcast from a Livox device not in connect, accept_codes or accept_ips: ignored");
            }
            return Vec::new();
        }
        if !self.devices.contains_key(&ip) && !self.has_room(ip) {
            return Vec::new();
        }
        tracing::info!(%ip, code = %code, device = %device_type.name(), "discovered");
        self.emit(LivoxEvent::Discovered { ip, code, device_type });
        self.add_session(now_ns, ip, Some(code), false);
        self.poll(now_ns)
    }

    pub(crate) fn on_control(&mut self, now_ns: u64, from: SocketAddr, bytes: &[u8]) -> Sends {
        let Some(from) = v4(from) else { return Vec::new() };
        let ip = *from.ip();
        if self.devices.get(&ip).is_none_or(|d| d.session.is_none()) {
            // Checked before decoding: a stranger's frames cost no CRC and no event.
            self.stats.unsolicited_control += 1;
            return Vec::new();
        }
        let Some(frame) = self.decode_control(from, bytes) else { return Vec::new() };
        let outputs = match self.devices.get_mut(&ip) {
            Some(Device { session: Some(s), last_heard_ns, .. }) => {
                *last_heard_ns = now_ns;
                s.handle(now_ns, &frame)
            }
            _ => return Vec::new(),
        };
        self.apply(ip, outputs)
    }

    /// Timers: every session's, then forgetting devices silent for `forget_after_ms`.
    pub(crate) fn poll(&mut self, now_ns: u64) -> Sends {
        self.forget_silent(now_ns);
        let mut all = Vec::new();
        let ips: Vec<Ipv4Addr> = self.devices.keys().copied().collect();
        for ip in ips {
            let outputs = match self.devices.get_mut(&ip).and_then(|d| d.session.as_mut()) {
                Some(s) => s.poll(now_ns),
                None => continue,
            };
            all.extend(self.apply(ip, outputs));
        }
        all
    }

    fn forget_silent(&mut self, now_ns: u64) {
        let silence_ns = self.config.forget_after_ms.saturating_mul(1_000_000);
        let before = self.devices.len();
        // Its scan in progress goes too: after this long it is stale for any consumer.
        self.devices.retain(|_, d| d.pinned || now_ns.saturating_sub(d.last_heard_ns) < silence_ns);
        let gone = (before - self.devices.len()) as u64;
        if gone > 0 {
            self.stats.forgotten += gone;
            tracing::debug!(gone, held = self.devices.len(), "forgot silent Livox devices");
        }
    }

    fn apply(&mut self, ip: Ipv4Addr, outputs: Vec<SessionOutput>) -> Sends {
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

    /// A datagram on the data or IMU port, received at `host_receive`.
    pub(crate) fn on_data(&mut self, now_ns: u64, from: SocketAddr, bytes: &[u8], host_receive: Stamp) {
        let Some(from) = v4(from) else { return };
        let ip = *from.ip();
        let known = self.devices.contains_key(&ip);
        if !known && !self.takes_unsolicited {
            // Checked before parsing: a stranger's packets cost no decoding and no event.
            self.stats.unsolicited_data += 1;
            if worth_logging(self.stats.unsolicited_data) {
                tracing::warn!(%ip, dropped = self.stats.unsolicited_data,
                    "Livox data from an address without a session: dropped (accept_unsolicited_data = false)");
            }
            return;
        }
        let packet = match DataPacket::parse(bytes) {
            Ok(p) => p,
            Err(e) => {
                self.stats.bad_datagrams += 1;
                self.emit(LivoxEvent::BadDatagram { from, error: e.to_string() });
                return;
            }
        };
        if !known {
            if !self.has_room(ip) {
                return;
            }
            let assembler = self.new_assembler();
            self.devices.insert(ip, Device { session: None, assembler, pinned: false, last_heard_ns: now_ns });
        }
        if let Some(d) = self.devices.get_mut(&ip) {
            d.last_heard_ns = now_ns;
        }
        if packet.is_imu() {
            let Some(sample) = packet.imu() else {
                self.stats.non_finite_imu += 1;
                if worth_logging(self.stats.non_finite_imu) {
                    tracing::warn!(%ip, dropped = self.stats.non_finite_imu, "IMU packet with NaN or infinity: dropped");
                }
                return;
            };
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
        let emit_packets = self.config.emit_packets;
        let mut packet_event = None;
        if let Some(a) = self.devices.get_mut(&ip).and_then(|d| d.assembler.as_mut()) {
            let before = (a.cut_points(), a.cut_scans(), a.non_finite_points());
            if emit_packets {
                // Decode once: the assembler takes the same points the event carries.
                let mut points = Vec::new();
                let counts = packet.decode_points(&mut points);
                let decoded = points.len();
                points.retain(|p| p.x_m.is_finite() && p.y_m.is_finite() && p.z_m.is_finite());
                self.stats.non_finite_points += (decoded - points.len()) as u64;
                a.push_points(&packet.header, &points, counts, Some(host_receive), &mut done);
                packet_event = Some(PointPacket { ip, header: packet.header, points, counts, host_receive });
            } else {
                a.push(&packet, Some(host_receive), &mut done);
            }
            self.stats.cut_points += a.cut_points() - before.0;
            self.stats.cut_scans += a.cut_scans() - before.1;
            self.stats.non_finite_points += a.non_finite_points() - before.2;
        }
        if let Some(p) = packet_event {
            self.emit(LivoxEvent::Points(p));
        }
        for scan in done {
            self.emit(LivoxEvent::Scan { ip, scan });
        }
    }

    /// Stops sampling and disconnects every session (the frames to send) and flushes the scans
    /// in progress.
    pub(crate) fn close(&mut self) -> Sends {
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

#[cfg(test)]
mod tests;
