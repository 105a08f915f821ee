//! The host side of one device's control session, sans-IO.
//!
//! Time goes in as host monotonic nanoseconds; frames go in as decoded [`ControlFrame`]s; what to
//! send and what happened come out as [`SessionOutput`]s. The transport owns sockets and clocks.

use crate::control::{Body, BroadcastCode, CommandId, ControlFrame, CoordinateSystem, Request, Response, ReturnMode};
use crate::data::StatusWord;
use serde::{Deserialize, Serialize};
use std::collections::VecDeque;
use std::net::Ipv4Addr;

/// What the host asks of every device it connects to (`[livox]` in a config file).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SessionConfig {
    /// Send the setup commands below; false only queries the device (for listing it).
    pub configure: bool,
    /// Start sampling once connected.
    pub start_sampling: bool,
    /// Return mode to set, or none to leave the device's own.
    pub return_mode: Option<ReturnModeSetting>,
    /// Ask for spherical packets instead of Cartesian ones.
    pub spherical: bool,
    /// Turn the 200 Hz IMU push on.
    pub imu_push: bool,
    pub heartbeat_interval_ms: u64,
    /// A device that has not acknowledged anything for this long is lost and reconnected.
    pub lost_after_ms: u64,
    /// Resend an unacknowledged command after this long.
    pub retry_after_ms: u64,
    /// Give a command up after this many sends.
    pub max_sends: u32,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ReturnModeSetting {
    First,
    Strongest,
    Dual,
    Triple,
}

impl From<ReturnModeSetting> for ReturnMode {
    fn from(s: ReturnModeSetting) -> Self {
        match s {
            ReturnModeSetting::First => ReturnMode::First,
            ReturnModeSetting::Strongest => ReturnMode::Strongest,
            ReturnModeSetting::Dual => ReturnMode::Dual,
            ReturnModeSetting::Triple => ReturnMode::Triple,
        }
    }
}

impl Default for SessionConfig {
    fn default() -> Self {
        Self {
            configure: true,
            start_sampling: true,
            return_mode: None,
            spherical: false,
            imu_push: true,
            heartbeat_interval_ms: 800,
            lost_after_ms: 3000,
            retry_after_ms: 500,
            max_sends: 4,
        }
    }
}

/// Where the device must send things (goes into the handshake).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct HostEndpoint {
    pub ip: Ipv4Addr,
    pub cmd_port: u16,
    pub data_port: u16,
    pub imu_port: u16,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum SessionState {
    /// Handshake sent, waiting for its ACK (also after a loss).
    Handshaking,
    /// Connected: setup commands in flight or done; heartbeats running.
    Connected,
    /// Stopped by the host (disconnect sent).
    Closed,
}

/// What happened, for the transport to report upwards.
#[derive(Clone, Debug, PartialEq)]
pub enum SessionEvent {
    Connected,
    /// All setup commands acknowledged.
    Configured,
    DeviceInfo {
        firmware: [u8; 4],
    },
    Heartbeat {
        work_state: u8,
        status: StatusWord,
    },
    Refused {
        command: CommandId,
        ret: u8,
    },
    /// A command went unanswered `max_sends` times.
    Unanswered {
        command: CommandId,
    },
    Lost,
    AbnormalStatus {
        status: StatusWord,
    },
    Acked {
        command: CommandId,
        response: Response,
    },
}

#[derive(Clone, Debug, PartialEq)]
pub enum SessionOutput {
    /// Send these bytes to the device's command port.
    Send(Vec<u8>),
    Event(SessionEvent),
}

#[derive(Clone, Copy, Debug)]
struct InFlight {
    request: Request,
    seq: u16,
    sent_ns: u64,
    sends: u32,
}

/// One device, from the host's point of view.
#[derive(Debug)]
pub struct DeviceSession {
    pub code: Option<BroadcastCode>,
    config: SessionConfig,
    host: HostEndpoint,
    state: SessionState,
    seq: u16,
    queue: VecDeque<Request>,
    in_flight: Option<InFlight>,
    handshake_sent_ns: Option<u64>,
    last_heartbeat_ns: u64,
    last_ack_ns: u64,
    configured: bool,
}

impl DeviceSession {
    pub fn new(code: Option<BroadcastCode>, host: HostEndpoint, config: SessionConfig) -> Self {
        Self {
            code,
            config,
            host,
            state: SessionState::Handshaking,
            seq: 0,
            queue: VecDeque::new(),
            in_flight: None,
            handshake_sent_ns: None,
            last_heartbeat_ns: 0,
            last_ack_ns: 0,
            configured: false,
        }
    }

    pub fn state(&self) -> SessionState {
        self.state
    }

    fn next_seq(&mut self) -> u16 {
        self.seq = self.seq.wrapping_add(1);
        self.seq
    }

    fn encode(&mut self, request: Request) -> (u16, Option<Vec<u8>>) {
        let seq = self.next_seq();
        (seq, ControlFrame::request(seq, request).encode().ok())
    }

    fn handshake(&self) -> Request {
        Request::Handshake {
            host_ip: self.host.ip,
            data_port: self.host.data_port,
            cmd_port: self.host.cmd_port,
            imu_port: self.host.imu_port,
        }
    }

    fn setup_commands(&self) -> VecDeque<Request> {
        let mut q = VecDeque::from([Request::QueryDeviceInfo]);
        if !self.config.configure {
            return q;
        }
        if self.config.spherical {
            q.push_back(Request::CoordinateSystem { system: CoordinateSystem::Spherical });
        } else {
            q.push_back(Request::CoordinateSystem { system: CoordinateSystem::Cartesian });
        }
        if let Some(mode) = self.config.return_mode {
            q.push_back(Request::SetReturnMode { mode: mode.into() });
        }
        q.push_back(Request::SetImuPush { enabled: self.config.imu_push });
        if self.config.start_sampling {
            q.push_back(Request::Sampling { start: true });
        }
        q
    }

    /// Queues a command; it is sent after those before it are acknowledged.
    pub fn enqueue(&mut self, request: Request) {
        self.queue.push_back(request);
    }

    /// Timers: handshake retries, heartbeats, command retries, loss detection.
    pub fn poll(&mut self, now_ns: u64) -> Vec<SessionOutput> {
        let ms = 1_000_000u64;
        let mut out = Vec::new();
        match self.state {
            SessionState::Closed => {}
            SessionState::Handshaking => {
                let due = self.handshake_sent_ns.is_none_or(|t| now_ns.saturating_sub(t) >= 1000 * ms);
                if due {
                    let request = self.handshake();
                    let (_, bytes) = self.encode(request);
                    out.extend(bytes.map(SessionOutput::Send));
                    self.handshake_sent_ns = Some(now_ns);
                }
            }
            SessionState::Connected => {
                if now_ns.saturating_sub(self.last_ack_ns) >= self.config.lost_after_ms * ms {
                    self.state = SessionState::Handshaking;
                    self.in_flight = None;
                    self.queue.clear();
                    self.configured = false;
                    self.handshake_sent_ns = None;
                    out.push(SessionOutput::Event(SessionEvent::Lost));
                    out.extend(self.poll(now_ns));
                    return out;
                }
                if now_ns.saturating_sub(self.last_heartbeat_ns) >= self.config.heartbeat_interval_ms * ms {
                    let (_, bytes) = self.encode(Request::Heartbeat);
                    out.extend(bytes.map(SessionOutput::Send));
                    self.last_heartbeat_ns = now_ns;
                }
                self.pump(now_ns, &mut out);
            }
        }
        out
    }

    /// Sends the next queued command, or resends the one in flight when its time is up.
    fn pump(&mut self, now_ns: u64, out: &mut Vec<SessionOutput>) {
        let retry_ns = self.config.retry_after_ms * 1_000_000;
        if let Some(f) = self.in_flight {
            if now_ns.saturating_sub(f.sent_ns) < retry_ns {
                return;
            }
            if f.sends >= self.config.max_sends {
                out.push(SessionOutput::Event(SessionEvent::Unanswered { command: f.request.id() }));
                self.in_flight = None;
            } else {
                if let Ok(bytes) = ControlFrame::request(f.seq, f.request).encode() {
                    out.push(SessionOutput::Send(bytes));
                }
                self.in_flight = Some(InFlight { sent_ns: now_ns, sends: f.sends + 1, ..f });
                return;
            }
        }
        if let Some(request) = self.queue.pop_front() {
            let (seq, bytes) = self.encode(request);
            out.extend(bytes.map(SessionOutput::Send));
            self.in_flight = Some(InFlight { request, seq, sent_ns: now_ns, sends: 1 });
        } else if !self.configured && self.state == SessionState::Connected {
            self.configured = true;
            out.push(SessionOutput::Event(SessionEvent::Configured));
        }
    }

    /// A control frame from this device.
    pub fn handle(&mut self, now_ns: u64, frame: &ControlFrame) -> Vec<SessionOutput> {
        let mut out = Vec::new();
        match frame.body {
            Body::Message(crate::control::Message::AbnormalStatus { status }) => {
                out.push(SessionOutput::Event(SessionEvent::AbnormalStatus { status: StatusWord::from_raw(status) }));
            }
            Body::Message(_) | Body::Request(_) => {}
            Body::Response(response) => {
                self.last_ack_ns = now_ns;
                match (self.state, response) {
                    (SessionState::Handshaking, Response::Ret { id: CommandId::Handshake, ret }) => {
                        if ret == 0 {
                            self.state = SessionState::Connected;
                            self.queue = self.setup_commands();
                            self.last_heartbeat_ns = now_ns;
                            out.push(SessionOutput::Event(SessionEvent::Connected));
                            self.pump(now_ns, &mut out);
                        } else {
                            out.push(SessionOutput::Event(SessionEvent::Refused {
                                command: CommandId::Handshake,
                                ret,
                            }));
                        }
                    }
                    (SessionState::Connected, Response::Heartbeat { work_state, status, .. }) => {
                        out.push(SessionOutput::Event(SessionEvent::Heartbeat {
                            work_state,
                            status: StatusWord::from_raw(status),
                        }));
                    }
                    (SessionState::Connected, response) => {
                        let matches_flight =
                            self.in_flight.is_some_and(|f| f.seq == frame.seq && f.request.id() == response.id());
                        if matches_flight {
                            self.in_flight = None;
                            if let Response::QueryDeviceInfo { firmware, ret: 0 } = response {
                                out.push(SessionOutput::Event(SessionEvent::DeviceInfo { firmware }));
                            }
                            if response.ret() != 0 {
                                out.push(SessionOutput::Event(SessionEvent::Refused {
                                    command: response.id(),
                                    ret: response.ret(),
                                }));
                            } else {
                                out.push(SessionOutput::Event(SessionEvent::Acked {
                                    command: response.id(),
                                    response,
                                }));
                            }
                            self.pump(now_ns, &mut out);
                        }
                    }
                    _ => {}
                }
            }
        }
        out
    }

    /// Stops sampling (if this session started it) and says goodbye; the frames to send now.
    /// The session is closed after.
    pub fn close(&mut self) -> Vec<Vec<u8>> {
        let mut frames = Vec::new();
        if self.state == SessionState::Connected {
            let stop =
                (self.config.configure && self.config.start_sampling).then_some(Request::Sampling { start: false });
            for request in stop.into_iter().chain([Request::Disconnect]) {
                let (_, bytes) = self.encode(request);
                frames.extend(bytes);
            }
        }
        self.state = SessionState::Closed;
        frames
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: u64 = 1_000_000;

    fn session() -> DeviceSession {
        let host = HostEndpoint { ip: Ipv4Addr::LOCALHOST, cmd_port: 55501, data_port: 56001, imu_port: 56001 };
        DeviceSession::new(None, host, SessionConfig::default())
    }

    fn sent(out: &[SessionOutput]) -> Vec<ControlFrame> {
        out.iter()
            .filter_map(|o| match o {
                SessionOutput::Send(b) => ControlFrame::decode(b).ok(),
                SessionOutput::Event(_) => None,
            })
            .collect()
    }

    fn ack(seq: u16, response: Response) -> ControlFrame {
        ControlFrame::response(seq, response)
    }

    /// Plays the device: acknowledges everything sent, successfully.
    fn answer(s: &mut DeviceSession, now: u64, frames: Vec<ControlFrame>) -> Vec<SessionOutput> {
        let mut out = Vec::new();
        for f in frames {
            let Body::Request(r) = f.body else { continue };
            let response = match r {
                Request::QueryDeviceInfo => Response::QueryDeviceInfo { ret: 0, firmware: [1, 2, 3, 4] },
                Request::Heartbeat => Response::Heartbeat { ret: 0, work_state: 1, feature: 0, status: 1 << 14 },
                other => Response::Ret { id: other.id(), ret: 0 },
            };
            out.extend(s.handle(now, &ack(f.seq, response)));
        }
        out
    }

    #[test]
    fn connects_configures_and_heartbeats() {
        let mut s = session();
        let first = sent(&s.poll(0));
        assert_eq!(first.len(), 1);
        assert_eq!(first[0].id(), CommandId::Handshake);
        let mut out = answer(&mut s, MS, first);
        // Each acknowledged command releases the next one.
        let mut ids = Vec::new();
        for _ in 0..10 {
            let frames = sent(&out);
            if frames.is_empty() {
                break;
            }
            ids.extend(frames.iter().map(|f| f.id()));
            out = answer(&mut s, 2 * MS, frames);
        }
        assert_eq!(
            ids,
            vec![CommandId::QueryDeviceInfo, CommandId::CoordinateSystem, CommandId::SetImuPush, CommandId::Sampling]
        );
        assert!(out.contains(&SessionOutput::Event(SessionEvent::Configured)));
        assert_eq!(s.state(), SessionState::Connected);
        let hb = sent(&s.poll(801 * MS));
        assert_eq!(hb.iter().map(|f| f.id()).collect::<Vec<_>>(), vec![CommandId::Heartbeat]);
        assert!(sent(&s.poll(900 * MS)).is_empty());
    }

    #[test]
    fn silence_for_three_seconds_means_lost_and_a_new_handshake() {
        let mut s = session();
        let hs = sent(&s.poll(0));
        answer(&mut s, 0, hs);
        let out = s.poll(2_999 * MS);
        assert!(!out.contains(&SessionOutput::Event(SessionEvent::Lost)));
        let out = s.poll(3_000 * MS);
        assert!(out.contains(&SessionOutput::Event(SessionEvent::Lost)));
        assert_eq!(sent(&out).iter().map(|f| f.id()).collect::<Vec<_>>(), vec![CommandId::Handshake]);
        assert_eq!(s.state(), SessionState::Handshaking);
    }

    #[test]
    fn unanswered_commands_are_retried_then_reported() {
        let mut s = session();
        let hs = sent(&s.poll(0));
        let out = answer(&mut s, 0, hs);
        let query = sent(&out);
        assert_eq!(query[0].id(), CommandId::QueryDeviceInfo);
        let mut resends = 0;
        let mut gave_up = false;
        for t in 1..=30u64 {
            let now = t * 100 * MS;
            // Keep the device alive with heartbeat ACKs only.
            let o = s.poll(now);
            resends += sent(&o).iter().filter(|f| f.seq == query[0].seq).count();
            gave_up |=
                o.contains(&SessionOutput::Event(SessionEvent::Unanswered { command: CommandId::QueryDeviceInfo }));
            s.handle(now, &ack(0, Response::Heartbeat { ret: 0, work_state: 1, feature: 0, status: 0 }));
        }
        assert_eq!(resends, 3);
        assert!(gave_up);
    }

    #[test]
    fn refusals_are_reported_and_setup_goes_on() {
        let mut s = session();
        let hs = sent(&s.poll(0));
        let out = answer(&mut s, 0, hs);
        let q = sent(&out);
        let out = s.handle(MS, &ack(q[0].seq, Response::Ret { id: CommandId::QueryDeviceInfo, ret: 1 }));
        assert!(
            out.contains(&SessionOutput::Event(SessionEvent::Refused { command: CommandId::QueryDeviceInfo, ret: 1 }))
        );
        assert_eq!(sent(&out).first().map(|f| f.id()), Some(CommandId::CoordinateSystem));
    }

    #[test]
    fn close_stops_sampling_and_disconnects() {
        let mut s = session();
        let hs = sent(&s.poll(0));
        answer(&mut s, 0, hs);
        let frames: Vec<CommandId> =
            s.close().iter().filter_map(|b| ControlFrame::decode(b).ok()).map(|f| f.id()).collect();
        assert_eq!(frames, vec![CommandId::Sampling, CommandId::Disconnect]);
        assert!(s.poll(10_000 * MS).is_empty());
    }
}
