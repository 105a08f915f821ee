//! A slave port: picks the best master from its Announces, measures offset and mean path delay
//! by the two-step end-to-end exchange (Sync + Follow_Up, Delay_Req + Delay_Resp), and reports
//! them. By default it measures only; with `adjust_clock` it also emits servo actions.
//!
//! offset = (t2 - t1 - c_sync) - delay, delay = ((t2 - t1 - c_sync) + (t4 - t3 - c_resp)) / 2,
//! with t1/t4 on the master's clock, t2/t3 on ours, c_* the correction fields; offset > 0 means
//! the local clock is ahead of the master.

use super::actions::{log_interval, Action, Timer, TxTag};
use super::bmca::ForeignMasters;
use crate::config::{LocalTimescale, SlaveConfig};
use crate::message::{Announce, Body, Flags, Header, Message, MessageType, PortIdentity, PtpTimestamp};
use crate::servo::{FreqEstimator, PiServo, ServoState};
use std::collections::VecDeque;
use std::time::Duration;

/// The port state, in 1588's words.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SlaveState {
    /// No qualified master.
    Listening,
    /// A master is chosen; no offset yet (waiting for a path delay).
    Uncalibrated,
    /// Offsets are flowing.
    Slave,
}

/// One measurement, made at each completed Sync once a path delay is known.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SlaveSample {
    pub master: PortIdentity,
    /// Local clock minus master clock (UTC-corrected when the master sends PTP time).
    pub offset_ns: i64,
    /// Filtered mean path delay.
    pub path_delay_ns: i64,
    /// Frequency error of the local clock against the master (ppb, positive: local fast).
    /// Measure-only: the slope of the offsets; steering: the servo's output.
    pub freq_ppb: f64,
    pub state: ServoState,
    /// The local receive time of the Sync (t2).
    pub local_ns: u64,
    /// The TAI-UTC seconds taken off the master's time (0 for an ARB-timescale master).
    pub utc_offset_s: i16,
}

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SlaveStats {
    pub syncs: u64,
    pub follow_ups: u64,
    pub delay_reqs: u64,
    pub delay_resps: u64,
    pub samples: u64,
    pub bad_messages: u64,
    pub tx_timestamps_missed: u64,
    pub master_changes: u64,
    /// Delay samples below zero (timestamp asymmetry; they still enter the median).
    pub negative_delays: u64,
}

#[derive(Clone, Copy, Debug)]
struct PendingSync {
    seq: u16,
    t2: i128,
    correction_ns: i128,
}

#[derive(Clone, Copy, Debug)]
struct SyncPair {
    /// t1 on the local timescale.
    t1: i128,
    t2: i128,
    correction_ns: i128,
}

#[derive(Clone, Copy, Debug)]
struct PendingDelayReq {
    seq: u16,
    t3: Option<i128>,
    /// t4 on the local timescale and the Delay_Resp correction, if it came before t3.
    resp: Option<(i128, i128)>,
}

pub struct Slave {
    cfg: SlaveConfig,
    port: PortIdentity,
    masters: ForeignMasters,
    selected: Option<PortIdentity>,
    state: SlaveState,
    pending_sync: Option<PendingSync>,
    early_follow_up: Option<(u16, PtpTimestamp, i128)>,
    last_pair: Option<SyncPair>,
    log_sync_interval: i8,
    delay_req: Option<PendingDelayReq>,
    delay_seq: u16,
    log_delay_req_interval: i8,
    delays: VecDeque<i64>,
    mean_delay_ns: Option<i64>,
    freq: FreqEstimator,
    servo: PiServo,
    latest: Option<SlaveSample>,
    stats: SlaveStats,
    rng: u64,
}

impl Slave {
    pub fn new(cfg: SlaveConfig, port: PortIdentity) -> Self {
        Self {
            freq: FreqEstimator::new(cfg.freq_window),
            servo: PiServo::new(cfg.servo.clone()),
            log_delay_req_interval: cfg.log_min_delay_req_interval,
            rng: cfg.seed | 1,
            cfg,
            port,
            masters: ForeignMasters::default(),
            selected: None,
            state: SlaveState::Listening,
            pending_sync: None,
            early_follow_up: None,
            last_pair: None,
            log_sync_interval: 0,
            delay_req: None,
            delay_seq: 0,
            delays: VecDeque::new(),
            mean_delay_ns: None,
            latest: None,
            stats: SlaveStats::default(),
        }
    }

    pub fn port_identity(&self) -> PortIdentity {
        self.port
    }
    pub fn state(&self) -> SlaveState {
        self.state
    }
    pub fn stats(&self) -> SlaveStats {
        self.stats
    }
    pub fn selected_master(&self) -> Option<PortIdentity> {
        self.selected
    }
    /// The newest measurement.
    pub fn latest(&self) -> Option<SlaveSample> {
        self.latest
    }
    pub fn mean_path_delay_ns(&self) -> Option<i64> {
        self.mean_delay_ns
    }

    /// Nothing to do until an Announce arrives.
    pub fn start(&mut self) -> Vec<Action> {
        Vec::new()
    }

    fn selected_announce(&self) -> Option<(Announce, Flags)> {
        let port = self.selected?;
        self.masters.get(&port).map(|m| (m.announce, m.flags))
    }

    /// The master's PTP time, in ns on our local timescale.
    fn master_to_local(&self, t: PtpTimestamp) -> (i128, i16) {
        let utc = match (self.selected_announce(), self.cfg.local_timescale) {
            (Some((a, flags)), LocalTimescale::Utc) if flags.ptp_timescale() => {
                if flags.utc_offset_valid() {
                    a.current_utc_offset
                } else {
                    self.cfg.default_utc_offset_s
                }
            }
            _ => 0,
        };
        (t.total_ns() - utc as i128 * 1_000_000_000, utc)
    }

    fn random_unit(&mut self) -> f64 {
        // xorshift64*: deterministic per seed, which keeps the port testable.
        self.rng ^= self.rng >> 12;
        self.rng ^= self.rng << 25;
        self.rng ^= self.rng >> 27;
        (self.rng.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 11) as f64 / (1u64 << 53) as f64
    }

    fn delay_req_after(&mut self) -> Duration {
        log_interval(self.log_delay_req_interval).mul_f64(0.5 + self.random_unit())
    }

    fn reset_measurement(&mut self) {
        self.pending_sync = None;
        self.early_follow_up = None;
        self.last_pair = None;
        self.delay_req = None;
        self.delays.clear();
        self.mean_delay_ns = None;
        self.freq.reset();
        self.servo.reset();
        self.latest = None;
    }

    /// Re-runs the choice of master; returns timers to arm when it changed.
    fn reselect(&mut self) -> Vec<Action> {
        let best = self.masters.best().map(|m| m.port);
        if best == self.selected {
            return Vec::new();
        }
        self.selected = best;
        self.stats.master_changes += 1;
        self.reset_measurement();
        self.log_delay_req_interval = self.cfg.log_min_delay_req_interval;
        match best {
            Some(_) => {
                self.state = SlaveState::Uncalibrated;
                let after = self.delay_req_after();
                vec![Action::ArmTimer { timer: Timer::DelayReq, after }]
            }
            None => {
                self.state = SlaveState::Listening;
                Vec::new()
            }
        }
    }

    fn parse(&mut self, bytes: &[u8]) -> Option<Message> {
        match Message::parse(bytes) {
            Ok(m) if m.header.domain == self.cfg.domain && m.header.source != self.port => Some(m),
            Ok(_) => None,
            Err(_) => {
                self.stats.bad_messages += 1;
                None
            }
        }
    }

    fn is_selected_sender(&self, h: &Header) -> bool {
        self.selected == Some(h.source)
    }

    /// A datagram on the event port (Sync), with its receive timestamp.
    pub fn handle_event(&mut self, bytes: &[u8], rx_ns: u64) -> Vec<Action> {
        let Some(m) = self.parse(bytes) else { return Vec::new() };
        let Body::Sync { origin } = m.body else { return Vec::new() };
        if !self.is_selected_sender(&m.header) {
            return Vec::new();
        }
        self.stats.syncs += 1;
        self.log_sync_interval = m.header.log_interval;
        let sync = PendingSync {
            seq: m.header.sequence_id,
            t2: rx_ns as i128,
            correction_ns: m.header.correction.ns() as i128,
        };
        if !m.header.flags.two_step() {
            self.pending_sync = None;
            return self.complete_sync(sync, origin, 0);
        }
        if let Some((seq, precise, corr)) = self.early_follow_up.take() {
            if seq == sync.seq {
                return self.complete_sync(sync, precise, corr);
            }
        }
        self.pending_sync = Some(sync);
        Vec::new()
    }

    /// A datagram on the general port (Announce, Follow_Up, Delay_Resp), with its receive time.
    pub fn handle_general(&mut self, bytes: &[u8], rx_ns: u64) -> Vec<Action> {
        let Some(m) = self.parse(bytes) else { return Vec::new() };
        match m.body {
            Body::Announce(a) => {
                if a.steps_removed >= 255 || a.gm_identity == self.port.clock {
                    return Vec::new();
                }
                self.masters.heard(m.header.source, a, m.header.flags, m.header.log_interval, rx_ns);
                self.masters.expire(rx_ns, self.cfg.announce_receipt_timeout);
                let mut out = self.reselect();
                if self.is_selected_sender(&m.header) {
                    let after = log_interval(m.header.log_interval)
                        .saturating_mul(self.cfg.announce_receipt_timeout as u32)
                        .saturating_add(Duration::from_millis(1));
                    out.push(Action::ArmTimer { timer: Timer::AnnounceReceipt, after });
                }
                out
            }
            Body::FollowUp { precise_origin } if self.is_selected_sender(&m.header) => {
                self.stats.follow_ups += 1;
                let corr = m.header.correction.ns() as i128;
                match self.pending_sync {
                    Some(s) if s.seq == m.header.sequence_id => {
                        self.pending_sync = None;
                        self.complete_sync(s, precise_origin, corr)
                    }
                    _ => {
                        self.early_follow_up = Some((m.header.sequence_id, precise_origin, corr));
                        Vec::new()
                    }
                }
            }
            Body::DelayResp { receive, requesting }
                if self.is_selected_sender(&m.header) && requesting == self.port =>
            {
                let Some(mut req) = self.delay_req else { return Vec::new() };
                if req.seq != m.header.sequence_id {
                    return Vec::new();
                }
                self.stats.delay_resps += 1;
                self.log_delay_req_interval = m.header.log_interval.clamp(-7, 6);
                req.resp = Some((self.master_to_local(receive).0, m.header.correction.ns() as i128));
                self.delay_req = Some(req);
                self.try_delay();
                Vec::new()
            }
            _ => Vec::new(),
        }
    }

    pub fn handle_timer(&mut self, timer: Timer, now_ns: u64) -> Vec<Action> {
        match timer {
            Timer::AnnounceReceipt => {
                self.masters.expire(now_ns, self.cfg.announce_receipt_timeout);
                self.reselect()
            }
            Timer::DelayReq => {
                if self.selected.is_none() {
                    return Vec::new();
                }
                if matches!(self.delay_req, Some(PendingDelayReq { t3: None, .. })) {
                    self.stats.tx_timestamps_missed += 1;
                }
                let seq = self.delay_seq;
                self.delay_seq = self.delay_seq.wrapping_add(1);
                let h = Header::new(MessageType::DelayReq, self.cfg.domain, self.port, seq);
                let origin = PtpTimestamp::from_ns(now_ns as i128).unwrap_or_default();
                let mut out = Vec::with_capacity(2);
                if let Ok(data) = (Message { header: h, body: Body::DelayReq { origin } }).encode() {
                    self.delay_req = Some(PendingDelayReq { seq, t3: None, resp: None });
                    self.stats.delay_reqs += 1;
                    out.push(Action::SendEvent { data, tag: TxTag::DelayReq { sequence_id: seq } });
                }
                let after = self.delay_req_after();
                out.push(Action::ArmTimer { timer, after });
                out
            }
            Timer::Announce | Timer::Sync => Vec::new(),
        }
    }

    /// The transmit timestamp of a Delay_Req (t3).
    pub fn handle_tx_timestamp(&mut self, tag: TxTag, tx_ns: u64) -> Vec<Action> {
        let TxTag::DelayReq { sequence_id } = tag else { return Vec::new() };
        if let Some(req) = self.delay_req.as_mut() {
            if req.seq == sequence_id {
                req.t3 = Some(tx_ns as i128);
                self.try_delay();
            }
        }
        Vec::new()
    }

    /// Once t3 and t4 are both known, one more delay sample.
    fn try_delay(&mut self) {
        let (Some(req), Some(pair)) = (self.delay_req, self.last_pair) else { return };
        let (Some(t3), Some((t4, c_resp))) = (req.t3, req.resp) else { return };
        self.delay_req = None;
        let master_to_slave = pair.t2 - pair.t1 - pair.correction_ns;
        let slave_to_master = t4 - t3 - c_resp;
        let delay = ((master_to_slave + slave_to_master) / 2).clamp(i64::MIN as i128, i64::MAX as i128) as i64;
        if delay < 0 {
            self.stats.negative_delays += 1;
        }
        if self.delays.len() >= self.cfg.delay_filter_length {
            self.delays.pop_front();
        }
        self.delays.push_back(delay);
        let mut sorted: Vec<i64> = self.delays.iter().copied().collect();
        sorted.sort_unstable();
        let n = sorted.len();
        self.mean_delay_ns = match (sorted.get(n / 2), n % 2) {
            (Some(&hi), 0) => sorted.get(n / 2 - 1).map(|&lo| ((lo as i128 + hi as i128) / 2) as i64),
            (Some(&mid), _) => Some(mid),
            (None, _) => None,
        };
    }

    fn complete_sync(&mut self, sync: PendingSync, origin: PtpTimestamp, follow_up_correction: i128) -> Vec<Action> {
        let Some(master) = self.selected else { return Vec::new() };
        let (t1, utc_offset_s) = self.master_to_local(origin);
        let pair = SyncPair { t1, t2: sync.t2, correction_ns: sync.correction_ns + follow_up_correction };
        self.last_pair = Some(pair);
        let raw = (pair.t2 - pair.t1 - pair.correction_ns).clamp(i64::MIN as i128, i64::MAX as i128) as i64;
        self.freq.push(pair.t2, raw);
        let Some(delay) = self.mean_delay_ns else { return Vec::new() };
        let offset = raw.saturating_sub(delay);
        self.state = SlaveState::Slave;
        self.stats.samples += 1;
        let mut out = Vec::new();
        let (freq_ppb, state) = if self.cfg.adjust_clock {
            let s = self.servo.sample(offset, pair.t2, log_interval(self.log_sync_interval).as_secs_f64());
            if let Some(step) = s.step_ns {
                out.push(Action::StepClock { offset_ns: step });
                // Every stored local time is now on a different clock.
                self.last_pair = None;
                self.freq.reset();
            }
            if s.state != ServoState::Unlocked {
                out.push(Action::SetFrequency { ppb: -s.freq_ppb });
            }
            (s.freq_ppb, s.state)
        } else {
            let freq = self.freq.freq_ppb();
            let state = match freq {
                None => ServoState::Unlocked,
                Some(_) if offset.unsigned_abs() > self.cfg.servo.step_threshold_ns.unsigned_abs() => ServoState::Jump,
                Some(_) => ServoState::Locked,
            };
            (freq.unwrap_or(0.0), state)
        };
        self.latest = Some(SlaveSample {
            master,
            offset_ns: offset,
            path_delay_ns: delay,
            freq_ppb,
            state,
            local_ns: u64::try_from(pair.t2).unwrap_or(0),
            utc_offset_s,
        });
        out
    }
}
