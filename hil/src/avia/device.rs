//! The sans-IO core of the mock Avia: datagrams and time in, [`Action`]s out.
//!
//! [`AviaDevice::handle_datagram`] answers control frames as a real Avia does;
//! [`AviaDevice::poll`] runs the timers (a broadcast every second while no host is connected, the
//! host lost after 3 s without a heartbeat) and returns the data and IMU packets due. Time is the
//! device's free-running clock in ns (any `Stamp`; only `ns` is read), always passed in, so tests
//! run seconds of device time in microseconds.
//!
//! Errors as a real device: a command before the handshake, a malformed payload, an unknown
//! command or a command from a host that is not the connected one gets an ACK with ret 1 (echoing
//! seq, set and id); a datagram that is not a frame gets nothing; CRC failures are dropped
//! silently and counted. ACKs go back to the address the command came from; the abnormal status
//! push goes to the host's command port from the handshake.

use crate::avia::faults::{FaultConfig, FaultStats, Faults};
use crate::avia::source::PointSource;
use crate::avia::stream::{
    point_data_type, Packet, PacketKind, StreamParams, StreamStats, Streamer, TimeSource, Timebase, NS_PER_S,
};
use crate::error::Result;
use serde::Serialize;
use starc_livox::control::{
    Body, BroadcastCode, CmdType, CommandId, ControlFrame, CoordinateSystem, DeviceType, Extrinsics, LidarMode,
    Message, RawFrame, Request, Response, ReturnMode, UtcTime,
};
use starc_livox::data::timestamp;
use starc_livox::ports::HOST_BROADCAST_PORT;
use starc_livox::LivoxError;
use starc_time::Stamp;
use std::net::{Ipv4Addr, SocketAddrV4};

/// Firmware version a mock reports.
pub const MOCK_FIRMWARE: [u8; 4] = [11, 6, 0, 0];
/// 2026-01-01T00:00:00Z in Unix ns: where a bare device's PTP and UTC clocks start.
pub const DEFAULT_EPOCH_NS: i64 = 1_767_225_600 * NS_PER_S as i64;
/// Return code of a refused command.
pub const RET_FAIL: u8 = 1;

/// How a mock device behaves. [`crate::avia::MockAviaConfig`] builds one from a TOML config.
#[derive(Clone, Debug)]
pub struct DeviceConfig {
    pub broadcast_code: BroadcastCode,
    /// Where broadcasts go (a real Avia: 255.255.255.255:55000; tests: a unicast address).
    pub broadcast_to: SocketAddrV4,
    pub firmware: [u8; 4],
    /// Return mode at power-on.
    pub return_mode: ReturnMode,
    /// Coordinate system at power-on.
    pub coordinates: CoordinateSystem,
    /// IMU push at power-on.
    pub imu_push: bool,
    /// Time stamp source at power-on.
    pub time_source: TimeSource,
    /// PTP time = device ns + this.
    pub ptp_offset_ns: i64,
    /// UTC (Unix ns) = device ns + this, until the host pushes a UTC time.
    pub utc_offset_ns: i64,
    /// A host is lost after this long without a heartbeat (3 s).
    pub host_timeout_ns: u64,
    /// Broadcast period while no host is connected (1 s).
    pub broadcast_interval_ns: u64,
    /// Packets due longer ago than this are skipped rather than sent late.
    pub max_lag_ns: u64,
    pub faults: FaultConfig,
    /// Seed of the fault PRNG when the fault config names none.
    pub seed: u64,
}

impl Default for DeviceConfig {
    fn default() -> Self {
        Self {
            broadcast_code: BroadcastCode(*b"STARCMOCK000001\0"),
            broadcast_to: SocketAddrV4::new(Ipv4Addr::LOCALHOST, HOST_BROADCAST_PORT),
            firmware: MOCK_FIRMWARE,
            return_mode: ReturnMode::First,
            coordinates: CoordinateSystem::Cartesian,
            imu_push: true,
            time_source: TimeSource::Ptp,
            ptp_offset_ns: DEFAULT_EPOCH_NS,
            utc_offset_ns: DEFAULT_EPOCH_NS,
            host_timeout_ns: 3 * NS_PER_S,
            broadcast_interval_ns: NS_PER_S,
            max_lag_ns: NS_PER_S / 2,
            faults: FaultConfig::default(),
            seed: 0,
        }
    }
}

/// The heartbeat's work_state.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum WorkState {
    Init = 0,
    Normal = 1,
    PowerSave = 2,
    Standby = 3,
    Error = 4,
}

/// The connected host, from its handshake.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct HostLink {
    /// Source address of the handshake; later commands must come from this IP.
    pub from: SocketAddrV4,
    /// The host's command port (status pushes go there).
    pub cmd_to: SocketAddrV4,
    pub data_to: SocketAddrV4,
    pub imu_to: SocketAddrV4,
    /// Device time of the handshake.
    pub since_ns: u64,
    pub last_heartbeat_ns: u64,
}

/// State changes worth a log line.
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
#[serde(tag = "event", rename_all = "snake_case")]
pub enum DeviceEvent {
    Connected { host: HostLink },
    HostLost { from: SocketAddrV4, silent_ns: u64 },
    Disconnected { from: SocketAddrV4 },
    TimeSourceChanged { from: TimeSource, to: TimeSource },
    Refused { from: SocketAddrV4, cmd_set: u8, cmd_id: u8, reason: &'static str },
}

/// What the transport must do.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Action {
    /// A control frame (ACK or MSG) from the command port (65000).
    SendControl {
        to: SocketAddrV4,
        bytes: Vec<u8>,
    },
    /// A point packet from the data port.
    SendPoints {
        to: SocketAddrV4,
        bytes: Vec<u8>,
    },
    /// An IMU packet from the IMU port.
    SendImu {
        to: SocketAddrV4,
        bytes: Vec<u8>,
    },
    /// Streaming began (or its destinations changed); packets follow from `poll`.
    StartStreaming {
        data_to: SocketAddrV4,
        imu_to: SocketAddrV4,
    },
    StopStreaming,
    Event(DeviceEvent),
}

/// Counters of one device.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct DeviceStats {
    pub datagrams: u64,
    /// Verified frames that were requests.
    pub commands: u64,
    /// ACKs sent, refusals included.
    pub answered: u64,
    /// ACKs with ret 1.
    pub refused: u64,
    /// Frames with a bad CRC16 or CRC32 (dropped silently).
    pub crc_errors: u64,
    /// Datagrams that are not control frames (dropped silently).
    pub malformed: u64,
    /// Verified frames that are not requests (ACK or MSG from a host).
    pub ignored: u64,
    pub heartbeats: u64,
    pub heartbeats_unanswered: u64,
    pub broadcasts: u64,
    pub status_pushes: u64,
    pub connections: u64,
    pub host_losses: u64,
    /// Point and IMU packets handed to the transport (after faults).
    pub point_packets: u64,
    pub imu_packets: u64,
    pub stream: StreamStats,
    pub faults: FaultStats,
}

#[derive(Clone, Copy, Debug)]
enum Link {
    Broadcasting { next_ns: u64 },
    Connected(HostLink),
}

/// The mock Avia, sans IO.
pub struct AviaDevice {
    config: DeviceConfig,
    power_on_ns: u64,
    link: Link,
    sampling: bool,
    mode: LidarMode,
    coordinates: CoordinateSystem,
    return_mode: ReturnMode,
    imu_push: bool,
    extrinsics: Extrinsics,
    timebase: Timebase,
    msg_seq: u16,
    status_sent: u32,
    streamer: Option<Streamer>,
    streaming_to: Option<(SocketAddrV4, SocketAddrV4)>,
    stream_done: StreamStats,
    source: Box<dyn PointSource>,
    faults: Faults,
    switch_pending: Option<(u64, TimeSource)>,
    stats: DeviceStats,
    scratch: Vec<Packet>,
    faulted: Vec<Packet>,
}

impl std::fmt::Debug for AviaDevice {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("AviaDevice")
            .field("code", &self.config.broadcast_code)
            .field("link", &self.link)
            .field("sampling", &self.sampling)
            .field("time_source", &self.timebase.source)
            .finish_non_exhaustive()
    }
}

fn add_stream(a: StreamStats, b: StreamStats) -> StreamStats {
    StreamStats {
        point_packets: a.point_packets + b.point_packets,
        imu_packets: a.imu_packets + b.imu_packets,
        skipped_packets: a.skipped_packets + b.skipped_packets,
        encode_errors: a.encode_errors + b.encode_errors,
    }
}

impl AviaDevice {
    /// Powers on at `now`: broadcasting, not sampling.
    pub fn new(config: DeviceConfig, source: Box<dyn PointSource>, now: Stamp) -> Result<Self> {
        config.faults.validate()?;
        let faults = Faults::new(&config.faults, config.seed);
        let timebase = Timebase {
            source: config.time_source,
            ptp_offset_ns: config.ptp_offset_ns,
            utc_offset_ns: config.utc_offset_ns,
        };
        Ok(Self {
            power_on_ns: now.ns,
            link: Link::Broadcasting { next_ns: now.ns },
            sampling: false,
            mode: LidarMode::Normal,
            coordinates: config.coordinates,
            return_mode: config.return_mode,
            imu_push: config.imu_push,
            extrinsics: Extrinsics { roll_deg: 0.0, pitch_deg: 0.0, yaw_deg: 0.0, x_mm: 0, y_mm: 0, z_mm: 0 },
            status_sent: timebase.source.status_bits(),
            timebase,
            msg_seq: 0,
            streamer: None,
            streaming_to: None,
            stream_done: StreamStats::default(),
            source,
            switch_pending: config.faults.switch_at_ns(),
            faults,
            stats: DeviceStats::default(),
            scratch: Vec::new(),
            faulted: Vec::new(),
            config,
        })
    }

    pub fn config(&self) -> &DeviceConfig {
        &self.config
    }

    pub fn broadcast_code(&self) -> BroadcastCode {
        self.config.broadcast_code
    }

    pub fn host(&self) -> Option<HostLink> {
        match self.link {
            Link::Connected(h) => Some(h),
            Link::Broadcasting { .. } => None,
        }
    }

    pub fn is_sampling(&self) -> bool {
        self.sampling
    }

    pub fn is_streaming(&self) -> bool {
        self.streamer.is_some()
    }

    pub fn time_source(&self) -> TimeSource {
        self.timebase.source
    }

    pub fn timebase(&self) -> Timebase {
        self.timebase
    }

    pub fn return_mode(&self) -> ReturnMode {
        self.return_mode
    }

    pub fn coordinates(&self) -> CoordinateSystem {
        self.coordinates
    }

    pub fn imu_push(&self) -> bool {
        self.imu_push
    }

    pub fn extrinsics(&self) -> Extrinsics {
        self.extrinsics
    }

    pub fn work_state(&self) -> WorkState {
        match self.mode {
            LidarMode::Normal => WorkState::Normal,
            LidarMode::PowerSave => WorkState::PowerSave,
            LidarMode::Standby => WorkState::Standby,
        }
    }

    /// The status word of heartbeats and data packets: the time source's sync bits, otherwise
    /// all normal.
    pub fn status_word(&self) -> u32 {
        self.timebase.source.status_bits()
    }

    pub fn stats(&self) -> DeviceStats {
        let mut s = self.stats;
        s.stream = add_stream(self.stream_done, self.streamer.as_ref().map(Streamer::stats).unwrap_or_default());
        s.faults = self.faults.stats();
        s
    }

    /// The device time at which `poll` next has work when not streaming (broadcast, host
    /// timeout, time source switch). While streaming, poll every 1-2 ms.
    pub fn next_timer_ns(&self) -> u64 {
        let mut t = match self.link {
            Link::Broadcasting { next_ns } => next_ns,
            Link::Connected(h) => h.last_heartbeat_ns.saturating_add(self.config.host_timeout_ns),
        };
        if let Some((at, _)) = self.switch_pending {
            t = t.min(self.power_on_ns.saturating_add(at));
        }
        t
    }

    /// Answers one datagram received on the command port from `from`.
    pub fn handle_datagram(&mut self, now: Stamp, from: SocketAddrV4, bytes: &[u8]) -> Vec<Action> {
        let now_ns = now.ns;
        let mut actions = Vec::new();
        self.stats.datagrams += 1;
        let raw = match RawFrame::decode(bytes) {
            Ok(raw) => raw,
            Err(e @ (LivoxError::BadHeaderCrc { .. } | LivoxError::BadFrameCrc { .. })) => {
                self.stats.crc_errors += 1;
                tracing::trace!(%from, "dropped: {e}");
                return actions;
            }
            Err(e) => {
                self.stats.malformed += 1;
                tracing::trace!(%from, "dropped: {e}");
                return actions;
            }
        };
        // The official SDK sends its handshake with cmd_type 1 (ACK).
        let handshake_as_ack =
            raw.cmd_type == CmdType::Ack && (raw.cmd_set, raw.cmd_id) == CommandId::Handshake.set_id();
        if raw.cmd_type != CmdType::Cmd && !handshake_as_ack {
            self.stats.ignored += 1;
            return actions;
        }
        self.stats.commands += 1;
        let outcome = match ControlFrame::from_raw(&raw) {
            Ok(ControlFrame { body: Body::Request(request), .. }) => self.execute(now_ns, from, request, &mut actions),
            Ok(_) => Err("not a request"),
            Err(LivoxError::UnknownCommand { .. }) => Err("unknown command"),
            Err(_) => Err("malformed payload"),
        };
        match outcome {
            Ok(Some(response)) => {
                if response.ret() != 0 {
                    self.stats.refused += 1;
                }
                self.push_control(&mut actions, from, ControlFrame::response(raw.seq, response).encode());
            }
            Ok(None) => {}
            Err(reason) => {
                self.stats.refused += 1;
                actions.push(Action::Event(DeviceEvent::Refused {
                    from,
                    cmd_set: raw.cmd_set,
                    cmd_id: raw.cmd_id,
                    reason,
                }));
                let refusal = RawFrame {
                    cmd_type: CmdType::Ack,
                    seq: raw.seq,
                    cmd_set: raw.cmd_set,
                    cmd_id: raw.cmd_id,
                    payload: &[RET_FAIL],
                };
                self.push_control(&mut actions, from, refusal.encode());
            }
        }
        self.settle(now_ns, &mut actions);
        actions
    }

    fn push_control(&mut self, actions: &mut Vec<Action>, to: SocketAddrV4, bytes: starc_livox::Result<Vec<u8>>) {
        match bytes {
            Ok(bytes) => {
                self.stats.answered += 1;
                actions.push(Action::SendControl { to, bytes });
            }
            Err(e) => tracing::warn!("ACK not encoded: {e}"),
        }
    }

    /// Carries out a request; `Ok(None)` means no answer (a silenced heartbeat).
    fn execute(
        &mut self,
        now_ns: u64,
        from: SocketAddrV4,
        request: Request,
        actions: &mut Vec<Action>,
    ) -> std::result::Result<Option<Response>, &'static str> {
        let done = |id: CommandId| Ok(Some(Response::Ret { id, ret: 0 }));
        if let Request::Handshake { host_ip, data_port, cmd_port, imu_port } = request {
            if host_ip.is_unspecified() || data_port == 0 || cmd_port == 0 || imu_port == 0 {
                return Err("handshake with a zero address or port");
            }
            let again = match self.link {
                Link::Connected(h) if h.from.ip() != from.ip() => return Err("connected to another host"),
                Link::Connected(_) => true,
                Link::Broadcasting { .. } => false,
            };
            let host = HostLink {
                from,
                cmd_to: SocketAddrV4::new(host_ip, cmd_port),
                data_to: SocketAddrV4::new(host_ip, data_port),
                imu_to: SocketAddrV4::new(host_ip, imu_port),
                since_ns: now_ns,
                last_heartbeat_ns: now_ns,
            };
            self.link = Link::Connected(host);
            if !again {
                self.stats.connections += 1;
            }
            actions.push(Action::Event(DeviceEvent::Connected { host }));
            return done(CommandId::Handshake);
        }
        let Link::Connected(host) = self.link else {
            return Err("no handshake yet");
        };
        if host.from.ip() != from.ip() {
            return Err("command from a host that is not connected");
        }
        match request {
            Request::Handshake { .. } => Err("handshake"),
            Request::Heartbeat => {
                if let Link::Connected(h) = &mut self.link {
                    h.last_heartbeat_ns = now_ns;
                }
                self.stats.heartbeats += 1;
                let silent = self
                    .faults
                    .config()
                    .heartbeat_silence_ns()
                    .is_some_and(|after| now_ns.saturating_sub(host.since_ns) >= after);
                if silent {
                    self.stats.heartbeats_unanswered += 1;
                    return Ok(None);
                }
                Ok(Some(Response::Heartbeat {
                    ret: 0,
                    work_state: self.work_state() as u8,
                    feature: 0,
                    status: self.status_word(),
                }))
            }
            Request::QueryDeviceInfo => Ok(Some(Response::QueryDeviceInfo { ret: 0, firmware: self.config.firmware })),
            Request::Sampling { start } => {
                self.sampling = start;
                done(CommandId::Sampling)
            }
            Request::CoordinateSystem { system } => {
                self.coordinates = system;
                done(CommandId::CoordinateSystem)
            }
            Request::Disconnect => {
                self.link = Link::Broadcasting { next_ns: now_ns };
                self.sampling = false;
                actions.push(Action::Event(DeviceEvent::Disconnected { from: host.from }));
                done(CommandId::Disconnect)
            }
            Request::SetMode { mode } => {
                self.mode = mode;
                done(CommandId::SetMode)
            }
            Request::WriteExtrinsics { extrinsics } => {
                self.extrinsics = extrinsics;
                done(CommandId::WriteExtrinsics)
            }
            Request::ReadExtrinsics => Ok(Some(Response::ReadExtrinsics { ret: 0, extrinsics: self.extrinsics })),
            Request::SetReturnMode { mode } => {
                self.return_mode = mode;
                done(CommandId::SetReturnMode)
            }
            Request::GetReturnMode => Ok(Some(Response::GetReturnMode { ret: 0, mode: self.return_mode })),
            Request::SetImuPush { enabled } => {
                self.imu_push = enabled;
                done(CommandId::SetImuPush)
            }
            Request::GetImuPush => Ok(Some(Response::GetImuPush { ret: 0, enabled: self.imu_push })),
            Request::UtcTime { time } => {
                let utc_ns = utc_ns(time).ok_or("invalid UTC time")?;
                let offset = i128::from(utc_ns) - i128::from(now_ns);
                self.timebase.utc_offset_ns = offset.clamp(i128::from(i64::MIN), i128::from(i64::MAX)) as i64;
                self.set_time_source(TimeSource::Gps, actions);
                done(CommandId::UtcTime)
            }
        }
    }

    fn set_time_source(&mut self, to: TimeSource, actions: &mut Vec<Action>) {
        let from = self.timebase.source;
        if from != to {
            self.timebase.source = to;
            actions.push(Action::Event(DeviceEvent::TimeSourceChanged { from, to }));
        }
    }

    fn next_msg_seq(&mut self) -> u16 {
        let seq = self.msg_seq;
        self.msg_seq = self.msg_seq.wrapping_add(1);
        seq
    }

    /// Runs the timers and returns what is due at `now`: broadcasts, host loss, time source
    /// switches, status pushes, and the data and IMU packets whose last firing is past.
    pub fn poll(&mut self, now: Stamp) -> Vec<Action> {
        let now_ns = now.ns;
        let mut actions = Vec::new();
        if let Link::Connected(h) = self.link {
            let silent_ns = now_ns.saturating_sub(h.last_heartbeat_ns);
            if silent_ns >= self.config.host_timeout_ns {
                self.link = Link::Broadcasting { next_ns: now_ns };
                self.sampling = false;
                self.stats.host_losses += 1;
                actions.push(Action::Event(DeviceEvent::HostLost { from: h.from, silent_ns }));
            }
        }
        if let Some((at, to)) = self.switch_pending {
            if now_ns >= self.power_on_ns.saturating_add(at) {
                self.switch_pending = None;
                self.set_time_source(to, &mut actions);
            }
        }
        if let Link::Broadcasting { next_ns } = self.link {
            if now_ns >= next_ns {
                let interval = self.config.broadcast_interval_ns.max(1);
                let next = if now_ns - next_ns >= interval { now_ns + interval } else { next_ns + interval };
                self.link = Link::Broadcasting { next_ns: next };
                let message = Message::Broadcast { code: self.config.broadcast_code, device_type: DeviceType::Avia };
                let seq = self.next_msg_seq();
                match ControlFrame::message(seq, message).encode() {
                    Ok(bytes) => {
                        self.stats.broadcasts += 1;
                        actions.push(Action::SendControl { to: self.config.broadcast_to, bytes });
                    }
                    Err(e) => tracing::warn!("broadcast not encoded: {e}"),
                }
            }
        }
        self.settle(now_ns, &mut actions);
        self.stream(now_ns, &mut actions);
        actions
    }

    /// Starts or stops streaming to match the state, and pushes a changed status word.
    fn settle(&mut self, now_ns: u64, actions: &mut Vec<Action>) {
        let want = match self.link {
            Link::Connected(h) if self.sampling && self.mode == LidarMode::Normal => Some((h.data_to, h.imu_to)),
            _ => None,
        };
        match (want, self.streaming_to) {
            (Some(to), None) => {
                self.streamer = Some(Streamer::start(now_ns, self.config.max_lag_ns, &mut *self.source));
                self.streaming_to = Some(to);
                actions.push(Action::StartStreaming { data_to: to.0, imu_to: to.1 });
            }
            (Some(to), Some(old)) if to != old => {
                self.streaming_to = Some(to);
                actions.push(Action::StartStreaming { data_to: to.0, imu_to: to.1 });
            }
            (None, Some(old)) => {
                self.faulted.clear();
                self.faults.flush(&mut self.faulted);
                let mut held = std::mem::take(&mut self.faulted);
                self.push_packets(&mut held, old, actions);
                self.faulted = held;
                if let Some(s) = self.streamer.take() {
                    self.stream_done = add_stream(self.stream_done, s.stats());
                }
                self.streaming_to = None;
                actions.push(Action::StopStreaming);
            }
            _ => {}
        }
        let status = self.status_word();
        if status != self.status_sent {
            self.status_sent = status;
            if let Link::Connected(h) = self.link {
                let seq = self.next_msg_seq();
                match ControlFrame::message(seq, Message::AbnormalStatus { status }).encode() {
                    Ok(bytes) => {
                        self.stats.status_pushes += 1;
                        actions.push(Action::SendControl { to: h.cmd_to, bytes });
                    }
                    Err(e) => tracing::warn!("status push not encoded: {e}"),
                }
            }
        }
    }

    fn stream(&mut self, now_ns: u64, actions: &mut Vec<Action>) {
        let (Some(streamer), Some(to)) = (self.streamer.as_mut(), self.streaming_to) else {
            return;
        };
        let params = StreamParams {
            data_type: point_data_type(self.return_mode, self.coordinates == CoordinateSystem::Spherical),
            imu: self.imu_push,
            status: self.timebase.source.status_bits(),
            timebase: self.timebase,
        };
        self.scratch.clear();
        streamer.poll(now_ns, &params, &mut *self.source, &mut self.scratch);
        self.faulted.clear();
        for p in self.scratch.drain(..) {
            self.faults.apply(p, &mut self.faulted);
        }
        let mut out = std::mem::take(&mut self.faulted);
        self.push_packets(&mut out, to, actions);
        self.faulted = out;
    }

    /// Turns packets into send actions, emptying `packets`.
    fn push_packets(&mut self, packets: &mut Vec<Packet>, to: (SocketAddrV4, SocketAddrV4), actions: &mut Vec<Action>) {
        for p in packets.drain(..) {
            match p.kind {
                PacketKind::Points => {
                    self.stats.point_packets += 1;
                    actions.push(Action::SendPoints { to: to.0, bytes: p.bytes });
                }
                PacketKind::Imu => {
                    self.stats.imu_packets += 1;
                    actions.push(Action::SendImu { to: to.1, bytes: p.bytes });
                }
            }
        }
    }
}

/// Unix ns of a pushed UTC time, if it is a valid date.
fn utc_ns(t: UtcTime) -> Option<u64> {
    let us = t.microseconds_in_hour.to_le_bytes();
    let raw = [t.year_since_2000, t.month, t.day, t.hour, us[0], us[1], us[2], us[3]];
    timestamp::decode(3, raw).ok().map(|s| s.ns)
}
