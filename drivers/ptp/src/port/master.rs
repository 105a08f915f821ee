//! A grandmaster port: Announce and two-step Sync + Follow_Up on timers, Delay_Resp for every
//! Delay_Req (end-to-end delay mechanism). It never listens to other masters (grandmaster-only):
//! a Livox LiDAR is a slave-only clock, and on the robot's LiDAR NIC we are the only master.

use super::actions::{log_interval, Action, Timer, TxTag};
use crate::config::{LocalTimescale, MasterConfig};
use crate::message::{
    Announce, Body, ClockQuality, Correction, Flags, Header, Message, MessageType, PortIdentity, PtpTimestamp,
};

/// What the master has done so far.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct MasterStats {
    pub announces: u64,
    pub syncs: u64,
    pub follow_ups: u64,
    pub delay_resps: u64,
    /// Sync sends whose transmit timestamp never came (no Follow_Up went out for them).
    pub tx_timestamps_missed: u64,
    /// Datagrams that did not parse.
    pub bad_messages: u64,
    /// Announces from another master on our domain (there should be none).
    pub foreign_announces: u64,
    /// The last requester answered.
    pub last_client: Option<PortIdentity>,
}

pub struct Master {
    cfg: MasterConfig,
    port: PortIdentity,
    sync_seq: u16,
    announce_seq: u16,
    /// The Sync whose transmit timestamp we wait for.
    pending_sync: Option<u16>,
    stats: MasterStats,
}

impl Master {
    pub fn new(cfg: MasterConfig, port: PortIdentity) -> Self {
        Self { cfg, port, sync_seq: 0, announce_seq: 0, pending_sync: None, stats: MasterStats::default() }
    }

    pub fn port_identity(&self) -> PortIdentity {
        self.port
    }

    pub fn stats(&self) -> MasterStats {
        self.stats
    }

    /// The first timers: an Announce and a Sync right away.
    pub fn start(&mut self) -> Vec<Action> {
        vec![
            Action::ArmTimer { timer: Timer::Announce, after: std::time::Duration::ZERO },
            Action::ArmTimer { timer: Timer::Sync, after: std::time::Duration::ZERO },
        ]
    }

    /// Local timestamp (ns) to the PTP time on the wire.
    fn to_ptp(&self, local_ns: u64) -> PtpTimestamp {
        let shift = match (self.cfg.ptp_timescale, self.cfg.local_timescale) {
            (true, LocalTimescale::Utc) => self.cfg.utc_offset_s as i128 * 1_000_000_000,
            _ => 0,
        };
        PtpTimestamp::from_ns(local_ns as i128 + shift).unwrap_or_default()
    }

    fn flags(&self, two_step: bool) -> Flags {
        // timeTraceable stays off: our time is the host's clock, not traceable, and a ptp4l
        // slave that sees it set with utcOffsetValid would write the kernel's TAI offset.
        Flags::default()
            .with(Flags::TWO_STEP, two_step)
            .with(Flags::PTP_TIMESCALE, self.cfg.ptp_timescale)
            .with(Flags::UTC_OFFSET_VALID, self.cfg.ptp_timescale)
    }

    fn header(&self, message_type: MessageType, sequence_id: u16, log: i8) -> Header {
        let mut h = Header::new(message_type, self.cfg.domain, self.port, sequence_id);
        h.log_interval = log;
        h
    }

    fn encode(message: &Message) -> Option<Vec<u8>> {
        message.encode().ok()
    }

    pub fn handle_timer(&mut self, timer: Timer, now_ns: u64) -> Vec<Action> {
        match timer {
            Timer::Announce => {
                let mut h = self.header(MessageType::Announce, self.announce_seq, self.cfg.log_announce_interval);
                self.announce_seq = self.announce_seq.wrapping_add(1);
                h.flags = self.flags(false);
                let body = Body::Announce(Announce {
                    origin: self.to_ptp(now_ns),
                    current_utc_offset: self.cfg.utc_offset_s,
                    reserved: 0,
                    gm_priority1: self.cfg.priority1,
                    gm_quality: ClockQuality {
                        clock_class: self.cfg.clock_class,
                        clock_accuracy: self.cfg.clock_accuracy,
                        offset_scaled_log_variance: self.cfg.offset_scaled_log_variance,
                    },
                    gm_priority2: self.cfg.priority2,
                    gm_identity: self.port.clock,
                    steps_removed: 0,
                    time_source: self.cfg.time_source,
                });
                self.stats.announces += 1;
                let mut out: Vec<Action> = Self::encode(&Message { header: h, body })
                    .map(|data| Action::SendGeneral { data })
                    .into_iter()
                    .collect();
                out.push(Action::ArmTimer { timer, after: log_interval(self.cfg.log_announce_interval) });
                out
            }
            Timer::Sync => {
                if self.pending_sync.take().is_some() {
                    self.stats.tx_timestamps_missed += 1;
                }
                let seq = self.sync_seq;
                self.sync_seq = self.sync_seq.wrapping_add(1);
                let mut h = self.header(MessageType::Sync, seq, self.cfg.log_sync_interval);
                h.flags = self.flags(true);
                // Two-step: the origin here is only approximate; the Follow_Up carries the
                // transmit timestamp.
                let body = Body::Sync { origin: self.to_ptp(now_ns) };
                let mut out = Vec::with_capacity(2);
                if let Some(data) = Self::encode(&Message { header: h, body }) {
                    self.pending_sync = Some(seq);
                    self.stats.syncs += 1;
                    out.push(Action::SendEvent { data, tag: TxTag::Sync { sequence_id: seq } });
                }
                out.push(Action::ArmTimer { timer, after: log_interval(self.cfg.log_sync_interval) });
                out
            }
            Timer::DelayReq | Timer::AnnounceReceipt => Vec::new(),
        }
    }

    /// The transmit timestamp of a Sync: send its Follow_Up.
    pub fn handle_tx_timestamp(&mut self, tag: TxTag, tx_ns: u64) -> Vec<Action> {
        let TxTag::Sync { sequence_id } = tag else { return Vec::new() };
        if self.pending_sync != Some(sequence_id) {
            return Vec::new();
        }
        self.pending_sync = None;
        let mut h = self.header(MessageType::FollowUp, sequence_id, self.cfg.log_sync_interval);
        h.flags = self.flags(false);
        let body = Body::FollowUp { precise_origin: self.to_ptp(tx_ns) };
        match Self::encode(&Message { header: h, body }) {
            Some(data) => {
                self.stats.follow_ups += 1;
                vec![Action::SendGeneral { data }]
            }
            None => Vec::new(),
        }
    }

    /// A datagram on the event port: answer Delay_Req with Delay_Resp.
    pub fn handle_event(&mut self, bytes: &[u8], rx_ns: u64) -> Vec<Action> {
        let message = match Message::parse(bytes) {
            Ok(m) => m,
            Err(_) => {
                self.stats.bad_messages += 1;
                return Vec::new();
            }
        };
        if message.header.domain != self.cfg.domain || message.header.source == self.port {
            return Vec::new();
        }
        let Body::DelayReq { .. } = message.body else { return Vec::new() };
        let mut h =
            self.header(MessageType::DelayResp, message.header.sequence_id, self.cfg.log_min_delay_req_interval);
        h.flags = self.flags(false);
        // 1588-2008 11.3.2: the Delay_Req's correction (residence times on the way) goes back.
        h.correction = Correction(message.header.correction.0);
        let body = Body::DelayResp { receive: self.to_ptp(rx_ns), requesting: message.header.source };
        match Self::encode(&Message { header: h, body }) {
            Some(data) => {
                self.stats.delay_resps += 1;
                self.stats.last_client = Some(message.header.source);
                vec![Action::SendGeneral { data }]
            }
            None => Vec::new(),
        }
    }

    /// A datagram on the general port: only counted (grandmaster-only port).
    pub fn handle_general(&mut self, bytes: &[u8], _rx_ns: u64) -> Vec<Action> {
        match Message::parse(bytes) {
            Ok(m) if m.header.message_type == MessageType::Announce && m.header.source != self.port => {
                if m.header.domain == self.cfg.domain {
                    self.stats.foreign_announces += 1;
                }
            }
            Ok(_) => {}
            Err(_) => self.stats.bad_messages += 1,
        }
        Vec::new()
    }
}
