//! One CiA 402 drive seen from the host, sans-IO: frames and time in, frames and faults out.
//!
//! Bring-up: NMT pre-operational; heartbeat producer time (0x1017); the consumer heartbeat time
//! of the host's heartbeat (0x1016:01) and the abort connection option (0x6007), so that the
//! drive stops by itself when the host goes silent; the RPDO deadline (0x1400:05), so that it
//! also stops when the host's commands stop; optionally the PDO mapping
//! (RPDO1 = controlword + target velocity, TPDO1 = statusword + actual velocity, event-timer
//! driven); 0x6060 = 3 (profile velocity) checked in 0x6061; target velocity 0; fault reset and
//! disable voltage, and the enable sequence 6 / 7 / 0x0F with the statusword read back after
//! each step; NMT start.
//! Then RPDO1 every control period, TPDO1 and heartbeats watched, EMCY decoded.

use crate::cia402::drive::{abort_connection, controlword, object, DriveState, PROFILE_VELOCITY_MODE};
use crate::cia402::emcy::Emergency;
use crate::cia402::nmt::{consumer_heartbeat_entry, parse_heartbeat, NmtCommand, NmtState};
use crate::cia402::pdo::{VelocityCommand, VelocityStatus, RPDO1_BASE, RPDO1_MAPPING, TPDO1_BASE, TPDO1_MAPPING};
use crate::cia402::sdo::{abort_meaning, Address, SdoRequest, SdoResponse, Value};
use crate::motor::{elapsed_ms, MotorPhase, WheelState};
use crate::safety::{DriveMode, Fault};
use serde::{Deserialize, Serialize};
use starc_can::CanFrame;
use starc_time::Stamp;

/// CiA 402 settings from the config file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Cia402Config {
    /// Drive velocity units (0x60FF, 0x606C) per wheel rad/s: 9.5493 for rpm, counts/rev / 2 pi
    /// for encoder counts per second. Include any gearbox.
    pub units_per_rad_s: f64,
    /// Heartbeat producer time written to each node (0x1017).
    pub heartbeat_ms: u16,
    /// A node whose heartbeat is silent this long is faulted.
    pub heartbeat_timeout_ms: u64,
    pub sdo_timeout_ms: u64,
    /// SDO attempts beyond the first before a node is faulted.
    pub sdo_retries: u8,
    /// How long each step of the enable sequence may take.
    pub state_timeout_ms: u64,
    /// Write the PDO mapping the driver expects; off when the drives are configured already.
    pub configure_pdos: bool,
    /// TPDO1 event timer written to 0x1800:05.
    pub tpdo_period_ms: u16,
    /// The host's own CANopen node id: its heartbeat goes out on 0x700 + this id. Must not be
    /// a wheel's node id.
    pub host_node_id: u8,
    /// How often the host sends its heartbeat (producer time).
    pub host_heartbeat_ms: u16,
    /// Written to each drive's 0x1016:01: the drive acts on 0x6007 when the host's heartbeat is
    /// silent this long. Longer than `host_heartbeat_ms` (two periods and more rides out a late
    /// or lost heartbeat); it bounds how long a drive runs on after the host dies.
    pub consumer_heartbeat_ms: u16,
    /// Written to each drive's 0x6007: 1 fault, 2 disable voltage (coast), 3 quick stop (brake
    /// on the quick-stop ramp), negative: the manufacturer's. 0 (no action) is refused.
    pub abort_connection_option: i16,
    /// Written to each drive's RPDO1 event timer (0x1400:05), which a receive PDO uses as its
    /// deadline (CiA 301): a drive that gets no command for this long takes 0x6007 too. A
    /// heartbeat on the host's id proves only that something produces it (a CANopen master
    /// daemon can, beside this program), so this is what stops a drive whose commands stop
    /// while the heartbeat goes on. 0: not written (a drive without deadline monitoring).
    pub rpdo_deadline_ms: u16,
}

impl Default for Cia402Config {
    fn default() -> Self {
        Self {
            units_per_rad_s: 60.0 / std::f64::consts::TAU,
            heartbeat_ms: 100,
            heartbeat_timeout_ms: 350,
            sdo_timeout_ms: 100,
            sdo_retries: 2,
            state_timeout_ms: 500,
            configure_pdos: true,
            tpdo_period_ms: 10,
            host_node_id: 127,
            // 50 / 150 ms: a drive stops within 150 ms (plus its own reaction) of the host's last
            // heartbeat, inside the 200 ms budget, and two heartbeats may be late or lost first.
            host_heartbeat_ms: 50,
            consumer_heartbeat_ms: 150,
            abort_connection_option: abort_connection::QUICK_STOP,
            // Ten 10 ms control periods: a few late commands ride through, a hung loop does not.
            rpdo_deadline_ms: 100,
        }
    }
}

impl Cia402Config {
    pub fn validate(&self) -> crate::Result<()> {
        if !(self.units_per_rad_s.is_finite() && self.units_per_rad_s > 0.0) {
            return Err(crate::BaseError::config("motors.cia402.units_per_rad_s", "must be > 0"));
        }
        if self.heartbeat_ms == 0 || self.heartbeat_timeout_ms <= u64::from(self.heartbeat_ms) {
            return Err(crate::BaseError::config(
                "motors.cia402.heartbeat_timeout_ms",
                "must be longer than a non-zero heartbeat_ms",
            ));
        }
        if self.sdo_timeout_ms == 0 || self.tpdo_period_ms == 0 {
            return Err(crate::BaseError::config("motors.cia402", "sdo_timeout_ms and tpdo_period_ms must be > 0"));
        }
        if !(1..=127).contains(&self.host_node_id) {
            return Err(crate::BaseError::config("motors.cia402.host_node_id", "must be 1-127"));
        }
        if self.host_heartbeat_ms == 0 || self.consumer_heartbeat_ms <= self.host_heartbeat_ms {
            return Err(crate::BaseError::config(
                "motors.cia402.consumer_heartbeat_ms",
                "must be longer than a non-zero host_heartbeat_ms",
            ));
        }
        if self.abort_connection_option == abort_connection::NO_ACTION {
            return Err(crate::BaseError::config(
                "motors.cia402.abort_connection_option",
                "0 (no action) would leave a drive running when the host dies; use 3 (quick stop)",
            ));
        }
        Ok(())
    }
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Step {
    Nmt(NmtCommand),
    Write(Address, Value),
    ExpectValue(Address, i32),
    ExpectState(DriveState),
}

fn setup_steps(node: u8, c: &Cia402Config) -> Vec<Step> {
    let a = Address::new;
    let cw = |v| Step::Write(a(object::CONTROLWORD, 0), Value::u16(v));
    let mut steps = vec![
        Step::Nmt(NmtCommand::EnterPreOperational),
        Step::Write(a(object::HEARTBEAT_PRODUCER, 0), Value::u16(c.heartbeat_ms)),
        // Before anything can enable the drive: from here on a silent host stops it.
        Step::Write(
            a(object::CONSUMER_HEARTBEAT, 1),
            Value::u32(consumer_heartbeat_entry(c.host_node_id, c.consumer_heartbeat_ms)),
        ),
        Step::Write(a(object::ABORT_CONNECTION_OPTION, 0), Value::i16(c.abort_connection_option)),
    ];
    if c.rpdo_deadline_ms > 0 {
        steps.push(Step::Write(a(object::RPDO1_COMM, 5), Value::u16(c.rpdo_deadline_ms)));
    }
    if c.configure_pdos {
        let rpdo_cob = u32::from(RPDO1_BASE) + u32::from(node);
        let tpdo_cob = u32::from(TPDO1_BASE) + u32::from(node);
        let invalid = 0x8000_0000;
        steps.extend([
            Step::Write(a(object::RPDO1_COMM, 1), Value::u32(rpdo_cob | invalid)),
            Step::Write(a(object::RPDO1_MAP, 0), Value::u8(0)),
            Step::Write(a(object::RPDO1_MAP, 1), Value::u32(RPDO1_MAPPING[0])),
            Step::Write(a(object::RPDO1_MAP, 2), Value::u32(RPDO1_MAPPING[1])),
            Step::Write(a(object::RPDO1_MAP, 0), Value::u8(2)),
            Step::Write(a(object::RPDO1_COMM, 2), Value::u8(0xFF)),
            Step::Write(a(object::RPDO1_COMM, 1), Value::u32(rpdo_cob)),
            Step::Write(a(object::TPDO1_COMM, 1), Value::u32(tpdo_cob | invalid)),
            Step::Write(a(object::TPDO1_MAP, 0), Value::u8(0)),
            Step::Write(a(object::TPDO1_MAP, 1), Value::u32(TPDO1_MAPPING[0])),
            Step::Write(a(object::TPDO1_MAP, 2), Value::u32(TPDO1_MAPPING[1])),
            Step::Write(a(object::TPDO1_MAP, 0), Value::u8(2)),
            Step::Write(a(object::TPDO1_COMM, 2), Value::u8(0xFF)),
            Step::Write(a(object::TPDO1_COMM, 5), Value::u16(c.tpdo_period_ms)),
            Step::Write(a(object::TPDO1_COMM, 1), Value::u32(tpdo_cob)),
        ]);
    }
    steps.extend([
        Step::Write(a(object::MODES_OF_OPERATION, 0), Value::i8(PROFILE_VELOCITY_MODE)),
        Step::ExpectValue(a(object::MODES_DISPLAY, 0), i32::from(PROFILE_VELOCITY_MODE)),
        Step::Write(a(object::TARGET_VELOCITY, 0), Value::i32(0)),
        // Fault reset acts only in Fault (rising edge of bit 7); disable voltage then brings any
        // other state (quick stop active, enabled...) to switch-on disabled.
        cw(controlword::FAULT_RESET),
        cw(controlword::DISABLE_VOLTAGE),
        Step::ExpectState(DriveState::SwitchOnDisabled),
        cw(controlword::SHUTDOWN),
        Step::ExpectState(DriveState::ReadyToSwitchOn),
        cw(controlword::SWITCH_ON),
        Step::ExpectState(DriveState::SwitchedOn),
        cw(controlword::ENABLE_OPERATION),
        Step::ExpectState(DriveState::OperationEnabled),
        Step::Nmt(NmtCommand::Start),
    ]);
    steps
}

#[derive(Clone, Copy, Debug, PartialEq)]
struct Pending {
    request: SdoRequest,
    sent: Stamp,
    tries: u8,
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Phase {
    Setup { step: usize, since: Stamp },
    Running,
    Faulted,
}

/// One drive.
#[derive(Clone, Debug)]
pub struct Cia402Node {
    wheel: usize,
    node: u8,
    sign: f64,
    config: Cia402Config,
    feedback_timeout_ms: u64,
    steps: Vec<Step>,
    phase: Phase,
    pending: Option<Pending>,
    started: bool,
    last_heartbeat: Option<Stamp>,
    heartbeat_watch: Option<Stamp>,
    nmt_state: Option<NmtState>,
    running_since: Option<Stamp>,
    reported_silence: bool,
    reported_heartbeat: bool,
    state: WheelState,
    /// Frames of ours that did not parse.
    pub malformed: u64,
}

impl Cia402Node {
    pub fn new(wheel: usize, node: u8, invert: bool, config: Cia402Config, feedback_timeout_ms: u64) -> Self {
        let steps = setup_steps(node, &config);
        Self {
            wheel,
            node,
            sign: if invert { -1.0 } else { 1.0 },
            config,
            feedback_timeout_ms,
            steps,
            phase: Phase::Faulted,
            pending: None,
            started: false,
            last_heartbeat: None,
            heartbeat_watch: None,
            nmt_state: None,
            running_since: None,
            reported_silence: false,
            reported_heartbeat: false,
            state: WheelState::new(wheel, node),
            malformed: 0,
        }
    }

    pub fn node(&self) -> u8 {
        self.node
    }

    pub fn is_running(&self) -> bool {
        self.phase == Phase::Running
    }

    pub fn nmt_state(&self) -> Option<NmtState> {
        self.nmt_state
    }

    /// (Re)starts the bring-up from the first step.
    pub fn start(&mut self, now: Stamp) {
        self.phase = Phase::Setup { step: 0, since: now };
        self.pending = None;
        self.heartbeat_watch = None;
        self.running_since = None;
        self.reported_silence = false;
        self.reported_heartbeat = false;
        self.state.phase = MotorPhase::Starting;
    }

    fn fail(&mut self, fault: Fault, faults: &mut Vec<Fault>) {
        tracing::warn!("{fault}");
        faults.push(fault);
        self.phase = Phase::Faulted;
        self.pending = None;
        self.state.phase = MotorPhase::Faulted;
    }

    fn setup_fault(&mut self, reason: String, faults: &mut Vec<Fault>) {
        let fault = Fault::Setup { wheel: self.wheel, node: self.node, reason };
        self.fail(fault, faults);
    }

    fn advance(&mut self, now: Stamp) {
        self.pending = None;
        if let Phase::Setup { step, .. } = self.phase {
            let next = step + 1;
            if next >= self.steps.len() {
                self.phase = Phase::Running;
                self.running_since = Some(now);
                self.state.phase = MotorPhase::Running;
                tracing::info!(node = self.node, "CiA 402 node enabled");
            } else {
                self.phase = Phase::Setup { step: next, since: now };
            }
        }
    }

    /// Takes a frame if it belongs to this node.
    pub fn handle_frame(&mut self, frame: &CanFrame, now: Stamp, faults: &mut Vec<Fault>) -> bool {
        if frame.id().is_extended() {
            return false;
        }
        let id = frame.id().raw();
        let n = u32::from(self.node);
        if id == 0x580 + n {
            match SdoResponse::parse(frame) {
                Ok((_, resp)) => self.on_sdo(resp, now, faults),
                Err(e) => self.count_malformed(&e),
            }
        } else if id == u32::from(TPDO1_BASE) + n {
            match VelocityStatus::parse(frame) {
                Ok((_, s)) => self.on_status(s, now, faults),
                Err(e) => self.count_malformed(&e),
            }
        } else if id == 0x700 + n {
            match parse_heartbeat(frame) {
                Ok((_, state)) => self.on_heartbeat(state, now, faults),
                Err(e) => self.count_malformed(&e),
            }
        } else if id == 0x80 + n {
            match Emergency::parse(frame) {
                Ok(e) if e.is_reset() => tracing::info!(node = self.node, "EMCY: error reset"),
                Ok(e) => {
                    let fault = Fault::Emergency {
                        wheel: self.wheel,
                        node: self.node,
                        code: e.code,
                        register: e.register,
                        meaning: e.meaning().to_string(),
                    };
                    self.fail(fault, faults);
                }
                Err(e) => self.count_malformed(&e),
            }
        } else {
            return false;
        }
        true
    }

    fn count_malformed(&mut self, e: &crate::BaseError) {
        self.malformed += 1;
        tracing::debug!(node = self.node, "{e}");
    }

    fn on_sdo(&mut self, resp: SdoResponse, now: Stamp, faults: &mut Vec<Fault>) {
        let Some(pending) = self.pending else { return };
        let Phase::Setup { step, since } = self.phase else { return };
        let expected_at = match pending.request {
            SdoRequest::Download { at, .. } | SdoRequest::Upload { at } | SdoRequest::Abort { at, .. } => at,
        };
        match resp {
            SdoResponse::Abort { at, code } if at == expected_at => {
                self.setup_fault(format!("SDO abort {code:#010x} ({}) on {at}", abort_meaning(code)), faults);
            }
            SdoResponse::Downloaded { at } if at == expected_at => {
                if at.index == object::HEARTBEAT_PRODUCER {
                    self.heartbeat_watch = Some(now);
                }
                self.advance(now);
            }
            SdoResponse::Uploaded { at, value } if at == expected_at => match self.steps.get(step) {
                Some(Step::ExpectValue(_, want)) => {
                    if value.as_i32() == *want {
                        self.advance(now);
                    } else {
                        self.setup_fault(format!("{at} reads {}, expected {want}", value.as_i32()), faults);
                    }
                }
                Some(Step::ExpectState(want)) => {
                    let sw = value.raw as u16;
                    self.state.statusword = Some(sw);
                    let got = DriveState::from_statusword(sw);
                    if got == Some(*want) {
                        self.advance(now);
                    } else if elapsed_ms(now, since) > self.config.state_timeout_ms {
                        self.setup_fault(format!("statusword {sw:#06x} ({got:?}), expected {want:?}"), faults);
                    } else {
                        // Read again on the next tick: drives take a few ms per transition.
                        self.pending = None;
                    }
                }
                _ => self.advance(now),
            },
            _ => tracing::debug!(node = self.node, "SDO response {resp:?} for another request"),
        }
    }

    fn on_status(&mut self, s: VelocityStatus, now: Stamp, faults: &mut Vec<Fault>) {
        self.state.statusword = Some(s.statusword);
        self.state.measured_rad_s = Some(self.sign * f64::from(s.actual_velocity) / self.config.units_per_rad_s);
        self.state.last_feedback = Some(now);
        let faulted = matches!(
            DriveState::from_statusword(s.statusword),
            Some(DriveState::Fault | DriveState::FaultReactionActive)
        );
        if faulted && self.phase == Phase::Running {
            let fault = Fault::DriveFault { wheel: self.wheel, node: self.node, statusword: s.statusword };
            self.fail(fault, faults);
        }
    }

    fn on_heartbeat(&mut self, state: NmtState, now: Stamp, faults: &mut Vec<Fault>) {
        self.last_heartbeat = Some(now);
        self.nmt_state = Some(state);
        if state == NmtState::BootUp && self.started && self.phase == Phase::Running {
            self.fail(Fault::NodeRebooted { wheel: self.wheel, node: self.node }, faults);
        }
    }

    /// One control period.
    pub fn tick(
        &mut self,
        now: Stamp,
        mode: DriveMode,
        target_rad_s: f64,
        out: &mut Vec<CanFrame>,
        faults: &mut Vec<Fault>,
    ) {
        self.watch(now, faults);
        match self.phase {
            Phase::Setup { step, .. } => self.run_setup(step, now, out, faults),
            Phase::Running => {
                let (cw, target) = match mode {
                    DriveMode::Run => (controlword::ENABLE_OPERATION, target_rad_s),
                    DriveMode::Brake => (controlword::ENABLE_OPERATION, 0.0),
                    DriveMode::Halt => (controlword::QUICK_STOP, 0.0),
                };
                self.state.target_rad_s = target;
                let units = (self.sign * target * self.config.units_per_rad_s).round();
                let velocity =
                    if units.is_finite() { units.clamp(f64::from(i32::MIN), f64::from(i32::MAX)) as i32 } else { 0 };
                self.push(VelocityCommand { controlword: cw, target_velocity: velocity }.to_frame(self.node), out);
            }
            Phase::Faulted => {
                self.state.target_rad_s = 0.0;
                if self.started {
                    let stop = VelocityCommand { controlword: controlword::QUICK_STOP, target_velocity: 0 };
                    self.push(stop.to_frame(self.node), out);
                }
            }
        }
    }

    fn push(&mut self, frame: crate::Result<CanFrame>, out: &mut Vec<CanFrame>) {
        match frame {
            Ok(f) => out.push(f),
            Err(e) => tracing::warn!(node = self.node, "cannot build a frame: {e}"),
        }
    }

    fn watch(&mut self, now: Stamp, faults: &mut Vec<Fault>) {
        if let Some(since) = self.heartbeat_watch {
            let last = match self.last_heartbeat {
                Some(h) if h.since(since).is_some_and(|d| d >= 0) => h,
                _ => since,
            };
            let silent_ms = elapsed_ms(now, last);
            if silent_ms > self.config.heartbeat_timeout_ms && !self.reported_heartbeat {
                self.reported_heartbeat = true;
                self.fail(Fault::HeartbeatTimeout { wheel: self.wheel, node: self.node, silent_ms }, faults);
                return;
            }
        }
        if let (Phase::Running, Some(since)) = (self.phase, self.running_since) {
            let last = match self.state.last_feedback {
                Some(f) if f.since(since).is_some_and(|d| d >= 0) => f,
                _ => since,
            };
            let silent_ms = elapsed_ms(now, last);
            if silent_ms > self.feedback_timeout_ms && !self.reported_silence {
                self.reported_silence = true;
                self.fail(Fault::FeedbackTimeout { wheel: self.wheel, motor: self.node, silent_ms }, faults);
            }
        }
    }

    fn run_setup(&mut self, step: usize, now: Stamp, out: &mut Vec<CanFrame>, faults: &mut Vec<Fault>) {
        if let Some(p) = self.pending {
            if elapsed_ms(now, p.sent) <= self.config.sdo_timeout_ms {
                return;
            }
            if p.tries > self.config.sdo_retries {
                let at = match p.request {
                    SdoRequest::Download { at, .. } | SdoRequest::Upload { at } | SdoRequest::Abort { at, .. } => at,
                };
                self.setup_fault(format!("no SDO answer for {at} after {} tries", p.tries), faults);
                return;
            }
            self.pending = Some(Pending { sent: now, tries: p.tries + 1, ..p });
            self.push(p.request.to_frame(self.node), out);
            return;
        }
        let Some(&current) = self.steps.get(step) else {
            self.advance(now);
            return;
        };
        let request = match current {
            Step::Nmt(cmd) => {
                self.push(cmd.to_frame(self.node), out);
                if cmd == NmtCommand::Start {
                    self.started = true;
                }
                self.advance(now);
                return;
            }
            Step::Write(at, value) => SdoRequest::Download { at, value },
            Step::ExpectValue(at, _) => SdoRequest::Upload { at },
            // The answer is checked against the state time-out in `on_sdo`.
            Step::ExpectState(_) => SdoRequest::Upload { at: Address::new(object::STATUSWORD, 0) },
        };
        self.pending = Some(Pending { request, sent: now, tries: 1 });
        self.push(request.to_frame(self.node), out);
    }

    pub fn measured(&self, now: Stamp) -> Option<f64> {
        match (self.phase, self.state.measured_rad_s, self.state.last_feedback) {
            (Phase::Running, Some(r), Some(t)) if elapsed_ms(now, t) <= self.feedback_timeout_ms => Some(r),
            _ => None,
        }
    }

    pub fn wheel_state(&self) -> WheelState {
        self.state.clone()
    }

    /// The frames that stop this drive (quick stop, zero velocity).
    pub fn halt_frame(&self) -> Option<CanFrame> {
        if !self.started {
            return None;
        }
        VelocityCommand { controlword: controlword::QUICK_STOP, target_velocity: 0 }.to_frame(self.node).ok()
    }
}

#[cfg(test)]
mod tests;
