//! A mock CiA 402 drive (profile velocity), sans-IO: an object dictionary served by expedited
//! SDO, NMT with boot-up and heartbeats, PDOs built from the mapping objects, the power state
//! machine driven by the controlword, EMCY on faults, and a first-order motor.
//!
//! The drive side of a lost host: the consumer heartbeat (0x1016:01, CiA 301) watches the
//! host's heartbeat once it has heard one; when it is silent longer than the configured time
//! the drive sends EMCY 0x8130 (heartbeat error) and takes its abort connection option
//! (0x6007, CiA 402): 1 fault, 2 disable voltage, 3 quick stop (target velocity zeroed, the
//! motor brakes). The RPDO deadline (0x1400:05, CiA 301's event timer of a receive PDO) does
//! the same when commands stop while the drive is enabled: EMCY 0x8250 (RPDO timeout) and
//! 0x6007. Every state change is logged with the drive's time (`tracing`, target
//! `starc_hil::motors::cia402`) and the times that matter are kept in [`DriveStats`].

use crate::motors::dynamics::FirstOrder;
use starc_base::cia402::drive::{abort_connection, controlword, object, DriveState};
use starc_base::cia402::emcy::Emergency;
use starc_base::cia402::nmt::{heartbeat_frame, parse_consumer_heartbeat_entry, NmtCommand, NmtState};
use starc_base::cia402::sdo::{abort, Address, SdoRequest, SdoResponse, Value};
use starc_can::{CanFrame, CanId};
use std::collections::BTreeMap;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Access {
    Ro,
    Rw,
}

#[derive(Clone, Copy, Debug)]
struct Entry {
    value: u32,
    size: u8,
    access: Access,
}

/// Device type 0x1000 of a CiA 402 servo drive.
pub const DEVICE_TYPE: u32 = 0x0002_0192;
/// Supported modes (0x6502): profile velocity only.
pub const SUPPORTED_MODES: u32 = 0x0000_0004;

fn dictionary(node: u8) -> BTreeMap<Address, Entry> {
    let n = u32::from(node);
    let ro = |value, size| Entry { value, size, access: Access::Ro };
    let rw = |value, size| Entry { value, size, access: Access::Rw };
    let a = Address::new;
    BTreeMap::from([
        (a(0x1000, 0), ro(DEVICE_TYPE, 4)),
        (a(0x1001, 0), ro(0, 1)),
        // One consumer heartbeat entry, unused (0) until the host writes it.
        (a(0x1016, 0), ro(1, 1)),
        (a(0x1016, 1), rw(0, 4)),
        (a(0x1017, 0), rw(0, 2)),
        (a(0x1018, 0), ro(4, 1)),
        (a(0x1018, 1), ro(0x0053_5443, 4)),
        (a(0x1018, 2), ro(0x0402, 4)),
        (a(0x1018, 3), ro(1, 4)),
        (a(0x1018, 4), ro(u32::from(node), 4)),
        (a(0x1400, 0), ro(5, 1)),
        (a(0x1400, 1), rw(0x200 + n, 4)),
        (a(0x1400, 2), rw(0xFF, 1)),
        // The RPDO deadline (ms), off (0) until the host writes it.
        (a(0x1400, 5), rw(0, 2)),
        (a(0x1600, 0), rw(2, 1)),
        (a(0x1600, 1), rw(0x6040_0010, 4)),
        (a(0x1600, 2), rw(0x60FF_0020, 4)),
        (a(0x1600, 3), rw(0, 4)),
        (a(0x1600, 4), rw(0, 4)),
        (a(0x1800, 0), ro(5, 1)),
        (a(0x1800, 1), rw(0x180 + n, 4)),
        (a(0x1800, 2), rw(0xFF, 1)),
        (a(0x1800, 3), rw(0, 2)),
        (a(0x1800, 5), rw(0, 2)),
        (a(0x1A00, 0), rw(2, 1)),
        (a(0x1A00, 1), rw(0x6041_0010, 4)),
        (a(0x1A00, 2), rw(0x606C_0020, 4)),
        (a(0x1A00, 3), rw(0, 4)),
        (a(0x1A00, 4), rw(0, 4)),
        // CiA 402's default abort connection option: fault signal.
        (a(0x6007, 0), rw(u32::from(abort_connection::FAULT as u16), 2)),
        (a(0x6040, 0), rw(0, 2)),
        (a(0x6041, 0), ro(u32::from(DriveState::SwitchOnDisabled.statusword()), 2)),
        (a(0x6060, 0), rw(0, 1)),
        (a(0x6061, 0), ro(0, 1)),
        (a(0x606C, 0), ro(0, 4)),
        (a(0x60FF, 0), rw(0, 4)),
        (a(0x6502, 0), ro(SUPPORTED_MODES, 4)),
    ])
}

/// Counters of one drive.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct DriveStats {
    pub sdo_requests: u64,
    pub sdo_aborts: u64,
    pub rpdos: u64,
    pub tpdos: u64,
    pub heartbeats: u64,
    pub emcys: u64,
    pub nmt: u64,
    /// Heartbeats heard from the node the consumer heartbeat watches (the host).
    pub host_heartbeats: u64,
    /// Drive time (ns) of the last of them.
    pub last_host_heartbeat_ns: Option<u64>,
    /// Consumer heartbeat time-outs: the host fell silent and 0x6007 was applied.
    pub consumer_timeouts: u64,
    /// Drive time of the last time-out.
    pub heartbeat_lost_ns: Option<u64>,
    /// RPDO deadline misses: no command for the time in 0x1400:05 while enabled, 0x6007 applied.
    pub rpdo_timeouts: u64,
    /// Drive time of the last RPDO, and of the last miss.
    pub last_rpdo_ns: Option<u64>,
    pub rpdo_missed_ns: Option<u64>,
    /// Drive time of the last change out of Operation Enabled: when the drive stopped driving.
    pub left_enabled_ns: Option<u64>,
    /// The state and actual velocity (drive units) now.
    pub state: Option<DriveState>,
    pub actual_velocity: i32,
}

/// One drive.
#[derive(Clone, Debug)]
pub struct MockDrive {
    node: u8,
    od: BTreeMap<Address, Entry>,
    nmt: NmtState,
    state: DriveState,
    last_controlword: u16,
    motor: FirstOrder,
    last_step_ns: Option<u64>,
    next_heartbeat_ns: u64,
    next_tpdo_ns: u64,
    booted: bool,
    /// The drive's time of the frame or poll being handled (for the log and the stats).
    now_ns: u64,
    /// The consumer heartbeat runs: a heartbeat of the watched node was heard since 0x1016 was
    /// written or since the last time-out (CiA 301: monitoring starts with the first one).
    consumer_armed: bool,
    /// The injected fault stays until this many fault resets have been tried (0: clears at once).
    fault_sticky_resets: u32,
    pub stats: DriveStats,
}

impl MockDrive {
    pub fn new(node: u8, tau_s: f64) -> Self {
        Self {
            node,
            od: dictionary(node),
            nmt: NmtState::BootUp,
            state: DriveState::SwitchOnDisabled,
            last_controlword: 0,
            motor: FirstOrder::new(tau_s),
            last_step_ns: None,
            next_heartbeat_ns: 0,
            next_tpdo_ns: 0,
            booted: false,
            now_ns: 0,
            consumer_armed: false,
            fault_sticky_resets: 0,
            stats: DriveStats { state: Some(DriveState::SwitchOnDisabled), ..DriveStats::default() },
        }
    }

    pub fn node(&self) -> u8 {
        self.node
    }

    pub fn state(&self) -> DriveState {
        self.state
    }

    pub fn nmt(&self) -> NmtState {
        self.nmt
    }

    /// Actual velocity in drive units.
    pub fn velocity(&self) -> f64 {
        self.motor.value
    }

    fn get(&self, index: u16) -> u32 {
        self.get_at(Address::new(index, 0))
    }

    fn get_at(&self, at: Address) -> u32 {
        self.od.get(&at).map(|e| e.value).unwrap_or(0)
    }

    fn set(&mut self, index: u16, value: u32) {
        if let Some(e) = self.od.get_mut(&Address::new(index, 0)) {
            e.value = value;
        }
    }

    fn set_state(&mut self, s: DriveState) {
        if s != self.state {
            tracing::info!(
                node = self.node,
                t_ms = self.now_ns as f64 * 1e-6,
                "drive state {:?} -> {:?}",
                self.state,
                s
            );
            if self.state == DriveState::OperationEnabled {
                self.stats.left_enabled_ns = Some(self.now_ns);
            }
        }
        self.state = s;
        self.stats.state = Some(s);
        self.set(object::STATUSWORD, u32::from(s.statusword()));
    }

    /// The node and time (ms) the consumer heartbeat watches; `None` when unused.
    fn consumer(&self) -> Option<(u8, u16)> {
        let entry = self.od.get(&Address::new(object::CONSUMER_HEARTBEAT, 1)).map(|e| e.value)?;
        let (node, time_ms) = parse_consumer_heartbeat_entry(entry);
        (node != 0 && time_ms != 0).then_some((node, time_ms))
    }

    /// The host is gone: EMCY 0x8130 and the abort connection option (0x6007).
    fn host_lost(&mut self, silent_ms: f64, out: &mut Vec<CanFrame>) {
        self.consumer_armed = false;
        self.stats.consumer_timeouts += 1;
        self.stats.heartbeat_lost_ns = Some(self.now_ns);
        self.connection_lost("host heartbeat", silent_ms, 0x8130, out);
    }

    /// The host's commands stopped while enabled: EMCY 0x8250 and 0x6007. Monitoring starts
    /// again with the next RPDO.
    fn rpdo_missed(&mut self, silent_ms: f64, out: &mut Vec<CanFrame>) {
        self.stats.last_rpdo_ns = None;
        self.stats.rpdo_timeouts += 1;
        self.stats.rpdo_missed_ns = Some(self.now_ns);
        self.connection_lost("RPDO", silent_ms, 0x8250, out);
    }

    /// EMCY `code` and the abort connection option (0x6007).
    fn connection_lost(&mut self, what: &str, silent_ms: f64, code: u16, out: &mut Vec<CanFrame>) {
        let option = self.get(object::ABORT_CONNECTION_OPTION) as u16 as i16;
        tracing::warn!(
            node = self.node,
            t_ms = self.now_ns as f64 * 1e-6,
            "{what} silent for {silent_ms:.1} ms: abort connection option {option}"
        );
        self.set(object::ERROR_REGISTER, 0x11);
        self.emcy(code, 0x11, out);
        match option {
            abort_connection::FAULT if !matches!(self.state, DriveState::Fault | DriveState::FaultReactionActive) => {
                self.set(object::TARGET_VELOCITY, 0);
                self.set_state(DriveState::Fault);
            }
            abort_connection::DISABLE_VOLTAGE => {
                self.set(object::TARGET_VELOCITY, 0);
                self.on_controlword(controlword::DISABLE_VOLTAGE, out);
            }
            abort_connection::QUICK_STOP => {
                // Zeroed so that re-enabling cannot resume the old speed.
                self.set(object::TARGET_VELOCITY, 0);
                self.on_controlword(controlword::QUICK_STOP, out);
            }
            // No action, or a manufacturer's code this mock does not have.
            _ => {}
        }
    }

    /// Injects a motor fault: state Fault, EMCY 0x2310 (continuous over-current).
    pub fn inject_fault(&mut self, sticky_resets: u32, out: &mut Vec<CanFrame>) {
        self.fault_sticky_resets = sticky_resets;
        self.set_state(DriveState::Fault);
        self.set(object::ERROR_REGISTER, 0x03);
        self.emcy(0x2310, 0x03, out);
    }

    fn emcy(&mut self, code: u16, register: u8, out: &mut Vec<CanFrame>) {
        if let Ok(f) = (Emergency { node: self.node, code, register, vendor: [0; 5] }).to_frame() {
            self.stats.emcys += 1;
            out.push(f);
        }
    }

    fn on_controlword(&mut self, cw: u16, out: &mut Vec<CanFrame>) {
        let rising_reset = cw & 0x80 != 0 && self.last_controlword & 0x80 == 0;
        self.last_controlword = cw;
        use DriveState::*;
        let next = match self.state {
            Fault if rising_reset => {
                if self.fault_sticky_resets > 0 {
                    self.fault_sticky_resets -= 1;
                    Fault
                } else {
                    self.set(object::ERROR_REGISTER, 0);
                    self.emcy(0, 0, out);
                    SwitchOnDisabled
                }
            }
            Fault | FaultReactionActive | NotReadyToSwitchOn => self.state,
            s if cw & 0x82 == 0x00 => {
                // Disable voltage (also what 0x80 means outside Fault).
                let _ = s;
                SwitchOnDisabled
            }
            OperationEnabled if cw & 0x86 == 0x02 => QuickStopActive,
            ReadyToSwitchOn | SwitchedOn if cw & 0x86 == 0x02 => SwitchOnDisabled,
            SwitchOnDisabled | SwitchedOn | OperationEnabled if cw & 0x87 == 0x06 => ReadyToSwitchOn,
            ReadyToSwitchOn | OperationEnabled if cw & 0x8F == 0x07 => SwitchedOn,
            ReadyToSwitchOn | SwitchedOn | QuickStopActive if cw & 0x8F == 0x0F => OperationEnabled,
            s => s,
        };
        self.set_state(next);
    }

    fn write(&mut self, at: Address, value: Value, out: &mut Vec<CanFrame>) -> Result<(), u32> {
        let Some(entry) = self.od.get(&at).copied() else {
            let index_known = self.od.keys().any(|k| k.index == at.index);
            return Err(if index_known { abort::NO_SUBINDEX } else { abort::NO_OBJECT });
        };
        if entry.access == Access::Ro {
            return Err(abort::READ_ONLY);
        }
        if value.size != entry.size {
            return Err(if value.size > entry.size { abort::LENGTH_TOO_HIGH } else { abort::LENGTH_TOO_LOW });
        }
        if at.index == object::MODES_OF_OPERATION {
            let mode = value.as_i32();
            if mode != 0 && mode != 3 {
                return Err(abort::INVALID_VALUE);
            }
            self.set(object::MODES_DISPLAY, value.raw);
        }
        if let Some(e) = self.od.get_mut(&at) {
            e.value = value.raw;
        }
        if at.index == object::CONSUMER_HEARTBEAT {
            // A new entry starts monitoring afresh, with the next heartbeat heard.
            self.consumer_armed = false;
        }
        if at.index == object::RPDO1_COMM {
            // So does a new deadline, with the next RPDO.
            self.stats.last_rpdo_ns = None;
        }
        if at.index == object::CONTROLWORD {
            self.on_controlword(value.raw as u16, out);
        }
        Ok(())
    }

    fn mapping(&self, map_index: u16) -> Vec<(Address, u8)> {
        let count = self.od.get(&Address::new(map_index, 0)).map(|e| e.value).unwrap_or(0).min(8);
        (1..=count as u8)
            .filter_map(|sub| self.od.get(&Address::new(map_index, sub)))
            .map(|e| (Address::new((e.value >> 16) as u16, (e.value >> 8) as u8), (e.value & 0xFF) as u8 / 8))
            .collect()
    }

    fn cob(&self, comm_index: u16) -> Option<u16> {
        let v = self.od.get(&Address::new(comm_index, 1)).map(|e| e.value)?;
        (v & 0x8000_0000 == 0).then_some((v & 0x7FF) as u16)
    }

    /// A frame on the bus at drive time `now_ns`; answers are appended to `out`.
    pub fn on_frame(&mut self, frame: &CanFrame, now_ns: u64, out: &mut Vec<CanFrame>) {
        self.now_ns = now_ns;
        let CanId::Standard(id) = frame.id() else { return };
        // Heartbeats are consumed in every NMT state, stopped included (CiA 301).
        if let Some((node, _)) = self.consumer() {
            if id == 0x700 + u16::from(node) && !frame.data().is_empty() {
                self.stats.host_heartbeats += 1;
                self.stats.last_host_heartbeat_ns = Some(now_ns);
                self.consumer_armed = true;
                return;
            }
        }
        if id == 0 {
            if let Ok((cmd, target)) = NmtCommand::parse(frame) {
                if target == 0 || target == self.node {
                    self.stats.nmt += 1;
                    self.on_nmt(cmd, out);
                }
            }
            return;
        }
        if self.nmt == NmtState::Stopped {
            return;
        }
        if id == 0x600 + u16::from(self.node) {
            self.on_sdo(frame, out);
        } else if self.nmt == NmtState::Operational && Some(id) == self.cob(object::RPDO1_COMM) {
            self.on_rpdo(frame.data(), out);
        }
    }

    fn on_nmt(&mut self, cmd: NmtCommand, out: &mut Vec<CanFrame>) {
        // PDOs exist only in Operational: the RPDO deadline starts again with the first RPDO
        // after any NMT command (CiA 301).
        self.stats.last_rpdo_ns = None;
        match cmd {
            NmtCommand::Start => self.nmt = NmtState::Operational,
            NmtCommand::Stop => self.nmt = NmtState::Stopped,
            NmtCommand::EnterPreOperational => self.nmt = NmtState::PreOperational,
            NmtCommand::ResetNode | NmtCommand::ResetCommunication => {
                if cmd == NmtCommand::ResetNode {
                    self.od = dictionary(self.node);
                    self.set_state(DriveState::SwitchOnDisabled);
                }
                self.boot(out);
            }
        }
    }

    fn boot(&mut self, out: &mut Vec<CanFrame>) {
        self.booted = true;
        if let Ok(f) = heartbeat_frame(self.node, NmtState::BootUp) {
            out.push(f);
        }
        self.nmt = NmtState::PreOperational;
    }

    fn on_sdo(&mut self, frame: &CanFrame, out: &mut Vec<CanFrame>) {
        self.stats.sdo_requests += 1;
        let reply = match SdoRequest::parse(frame) {
            Ok((_, SdoRequest::Upload { at })) => match self.od.get(&at) {
                Some(e) => SdoResponse::Uploaded { at, value: Value { raw: e.value, size: e.size } },
                None => {
                    let known = self.od.keys().any(|k| k.index == at.index);
                    SdoResponse::Abort { at, code: if known { abort::NO_SUBINDEX } else { abort::NO_OBJECT } }
                }
            },
            Ok((_, SdoRequest::Download { at, value })) => match self.write(at, value, out) {
                Ok(()) => SdoResponse::Downloaded { at },
                Err(code) => SdoResponse::Abort { at, code },
            },
            Ok((_, SdoRequest::Abort { .. })) => return,
            Err(_) => {
                let d = frame.data();
                let at = Address::new(
                    u16::from_le_bytes([d.get(1).copied().unwrap_or(0), d.get(2).copied().unwrap_or(0)]),
                    d.get(3).copied().unwrap_or(0),
                );
                SdoResponse::Abort { at, code: abort::BAD_COMMAND }
            }
        };
        if matches!(reply, SdoResponse::Abort { .. }) {
            self.stats.sdo_aborts += 1;
        }
        if let Ok(f) = reply.to_frame(self.node) {
            out.push(f);
        }
    }

    fn on_rpdo(&mut self, data: &[u8], out: &mut Vec<CanFrame>) {
        self.stats.rpdos += 1;
        self.stats.last_rpdo_ns = Some(self.now_ns);
        let mut at = 0usize;
        for (addr, size) in self.mapping(object::RPDO1_MAP) {
            let Some(bytes) = data.get(at..at + usize::from(size)) else { return };
            at += usize::from(size);
            let mut raw = [0u8; 4];
            if let Some(r) = raw.get_mut(..bytes.len()) {
                r.copy_from_slice(bytes);
            }
            let value = Value { raw: u32::from_le_bytes(raw), size };
            if let Err(code) = self.write(addr, value, out) {
                tracing::debug!(node = self.node, "RPDO write to {addr} refused: {code:#x}");
            }
        }
    }

    fn tpdo(&mut self) -> Option<CanFrame> {
        let cob = self.cob(object::TPDO1_COMM)?;
        let mut data = Vec::with_capacity(8);
        for (addr, size) in self.mapping(object::TPDO1_MAP) {
            let v = self.od.get(&addr).map(|e| e.value).unwrap_or(0).to_le_bytes();
            data.extend_from_slice(v.get(..usize::from(size).min(4))?);
        }
        if data.len() > 8 {
            return None;
        }
        CanFrame::standard(cob, &data).ok()
    }

    /// Advances to `now_ns`: boot-up, motor, heartbeat, TPDO.
    pub fn poll(&mut self, now_ns: u64, out: &mut Vec<CanFrame>) {
        self.now_ns = now_ns;
        if !self.booted {
            self.boot(out);
        }
        if let (true, Some((_, time_ms)), Some(last)) =
            (self.consumer_armed, self.consumer(), self.stats.last_host_heartbeat_ns)
        {
            let silent_ns = now_ns.saturating_sub(last);
            if silent_ns > u64::from(time_ms) * 1_000_000 {
                self.host_lost(silent_ns as f64 * 1e-6, out);
            }
        }
        let deadline_ms = u64::from(self.get_at(Address::new(object::RPDO1_COMM, 5)));
        let watching =
            deadline_ms > 0 && self.nmt == NmtState::Operational && self.state == DriveState::OperationEnabled;
        if let (true, Some(last)) = (watching, self.stats.last_rpdo_ns) {
            let silent_ns = now_ns.saturating_sub(last);
            if silent_ns > deadline_ms * 1_000_000 {
                self.rpdo_missed(silent_ns as f64 * 1e-6, out);
            }
        }
        let dt = self.last_step_ns.map(|t| now_ns.saturating_sub(t) as f64 * 1e-9).unwrap_or(0.0);
        self.last_step_ns = Some(now_ns);
        let target = match self.state {
            DriveState::OperationEnabled => f64::from(self.get(object::TARGET_VELOCITY) as i32),
            _ => 0.0,
        };
        // Quick stop and disabled states brake (a drive decelerates on its quick-stop ramp).
        let v = self.motor.step(target, dt);
        self.set(object::VELOCITY_ACTUAL, v.round() as i32 as u32);
        self.stats.actual_velocity = v.round() as i32;

        let hb_ms = u64::from(self.get(object::HEARTBEAT_PRODUCER));
        if hb_ms > 0 && now_ns >= self.next_heartbeat_ns {
            self.next_heartbeat_ns = now_ns + hb_ms * 1_000_000;
            if let Ok(f) = heartbeat_frame(self.node, self.nmt) {
                self.stats.heartbeats += 1;
                out.push(f);
            }
        }
        let event_ms = self.od.get(&Address::new(object::TPDO1_COMM, 5)).map(|e| u64::from(e.value)).unwrap_or(0);
        if self.nmt == NmtState::Operational && event_ms > 0 && now_ns >= self.next_tpdo_ns {
            self.next_tpdo_ns = now_ns + event_ms * 1_000_000;
            if let Some(f) = self.tpdo() {
                self.stats.tpdos += 1;
                out.push(f);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use starc_base::cia402::pdo::{VelocityCommand, VelocityStatus};

    fn sdo(d: &mut MockDrive, req: SdoRequest) -> Option<SdoResponse> {
        let mut out = Vec::new();
        d.on_frame(&req.to_frame(d.node()).ok()?, 0, &mut out);
        out.iter().find_map(|f| SdoResponse::parse(f).ok()).map(|(_, r)| r)
    }

    #[test]
    fn sdo_nmt_enable_and_pdos() {
        let mut d = MockDrive::new(2, 0.05);
        let mut out = Vec::new();
        d.poll(0, &mut out);
        assert_eq!(out.first().map(|f| f.to_string()), Some("702#00".into()), "boot-up");
        let a = Address::new;
        assert_eq!(
            sdo(&mut d, SdoRequest::Upload { at: a(0x1000, 0) }),
            Some(SdoResponse::Uploaded { at: a(0x1000, 0), value: Value::u32(DEVICE_TYPE) })
        );
        assert_eq!(
            sdo(&mut d, SdoRequest::Upload { at: a(0x2000, 0) }),
            Some(SdoResponse::Abort { at: a(0x2000, 0), code: abort::NO_OBJECT })
        );
        assert_eq!(
            sdo(&mut d, SdoRequest::Download { at: a(0x6041, 0), value: Value::u16(0) }),
            Some(SdoResponse::Abort { at: a(0x6041, 0), code: abort::READ_ONLY })
        );
        assert_eq!(
            sdo(&mut d, SdoRequest::Download { at: a(0x6060, 0), value: Value::u16(3) }),
            Some(SdoResponse::Abort { at: a(0x6060, 0), code: abort::LENGTH_TOO_HIGH })
        );
        assert_eq!(
            sdo(&mut d, SdoRequest::Download { at: a(0x6060, 0), value: Value::i8(1) }),
            Some(SdoResponse::Abort { at: a(0x6060, 0), code: abort::INVALID_VALUE })
        );
        for (index, sub, value) in
            [(0x6060u16, 0u8, Value::i8(3)), (0x1017, 0, Value::u16(50)), (0x1800, 5, Value::u16(10))]
        {
            assert_eq!(
                sdo(&mut d, SdoRequest::Download { at: a(index, sub), value }),
                Some(SdoResponse::Downloaded { at: a(index, sub) })
            );
        }
        for cw in [6u16, 7, 0x0F] {
            sdo(&mut d, SdoRequest::Download { at: a(0x6040, 0), value: Value::u16(cw) });
        }
        assert_eq!(d.state(), DriveState::OperationEnabled);
        let mut out = Vec::new();
        d.on_frame(&NmtCommand::Start.to_frame(2).unwrap_or_else(|e| panic!("{e}")), 0, &mut out);
        let rpdo =
            VelocityCommand { controlword: 0x0F, target_velocity: 100 }.to_frame(2).unwrap_or_else(|e| panic!("{e}"));
        d.on_frame(&rpdo, 0, &mut out);
        for ms in 1..=500u64 {
            d.poll(ms * 1_000_000, &mut out);
        }
        let last = out.iter().rev().find_map(|f| VelocityStatus::parse(f).ok()).map(|(_, s)| s);
        assert!(
            matches!(last, Some(s) if s.actual_velocity == 100 && DriveState::is_enabled(s.statusword)),
            "{last:?}"
        );
        assert!((9..=11).contains(&d.stats.heartbeats), "{:?}", d.stats);
        assert!((49..=51).contains(&d.stats.tpdos), "{:?}", d.stats);
        // A fault: EMCY, then a fault reset brings it back to switch-on disabled.
        let mut out = Vec::new();
        d.inject_fault(0, &mut out);
        assert_eq!(out.first().and_then(|f| Emergency::parse(f).ok()).map(|e| e.code), Some(0x2310));
        sdo(&mut d, SdoRequest::Download { at: a(0x6040, 0), value: Value::u16(0x80) });
        assert_eq!(d.state(), DriveState::SwitchOnDisabled);
    }

    /// A drive brought up as the host does it (consumer heartbeat of node 127 at `consumer_ms`
    /// when given, 0x6007 = 3), enabled, started and driving at 300 units; the host heartbeat
    /// every 50 ms until `silent_from_ms`, the drive polled every millisecond up to `until_ms`.
    fn host_goes_silent(consumer_ms: Option<u16>, silent_from_ms: u64, until_ms: u64) -> (MockDrive, Vec<CanFrame>) {
        let mut d = MockDrive::new(5, 0.05);
        d.poll(0, &mut Vec::new()); // boot-up first, as on a real bus
        let a = Address::new;
        let mut writes =
            vec![(a(0x6060, 0), Value::i8(3)), (a(0x1800, 5), Value::u16(10)), (a(0x6007, 0), Value::i16(3))];
        if let Some(ms) = consumer_ms {
            writes.push((a(0x1016, 1), Value::u32(starc_base::cia402::nmt::consumer_heartbeat_entry(127, ms))));
        }
        for (at, value) in writes {
            assert_eq!(sdo(&mut d, SdoRequest::Download { at, value }), Some(SdoResponse::Downloaded { at }));
        }
        for cw in [6u16, 7, 0x0F] {
            sdo(&mut d, SdoRequest::Download { at: a(0x6040, 0), value: Value::u16(cw) });
        }
        let mut out = Vec::new();
        let frame = |r: starc_base::Result<CanFrame>| r.unwrap_or_else(|e| panic!("{e}"));
        d.on_frame(&frame(NmtCommand::Start.to_frame(5)), 0, &mut out);
        d.on_frame(&frame(VelocityCommand { controlword: 0x0F, target_velocity: 300 }.to_frame(5)), 0, &mut out);
        let host_beat = frame(heartbeat_frame(127, NmtState::Operational));
        for ms in 0..=until_ms {
            let now = ms * 1_000_000;
            if ms < silent_from_ms && ms % 50 == 0 {
                d.on_frame(&host_beat, now, &mut out);
            }
            d.poll(now, &mut out);
        }
        (d, out)
    }

    #[test]
    fn a_drive_quick_stops_within_200_ms_of_the_last_host_heartbeat() {
        let (d, out) = host_goes_silent(Some(150), 1001, 1600);
        let s = d.stats;
        // Driving until the host fell silent: 21 heartbeats (0..=1000 ms), no false trip.
        assert_eq!((s.host_heartbeats, s.last_host_heartbeat_ns), (21, Some(1_000_000_000)), "{s:?}");
        assert_eq!(s.consumer_timeouts, 1, "{s:?}");
        assert_eq!(d.state(), DriveState::QuickStopActive);
        let last = s.last_host_heartbeat_ns.unwrap_or(0);
        let stopped = s.left_enabled_ns.unwrap_or(u64::MAX);
        let after_ms = stopped.saturating_sub(last) as f64 * 1e-6;
        assert!(after_ms > 150.0 && after_ms <= 200.0, "stopped {after_ms} ms after the last heartbeat");
        assert_eq!(s.heartbeat_lost_ns, Some(stopped));
        // EMCY 0x8130 (heartbeat error), the target zeroed, and the motor braked to a stop.
        assert!(out.iter().filter_map(|f| Emergency::parse(f).ok()).any(|e| e.node == 5 && e.code == 0x8130));
        assert_eq!(d.get(object::TARGET_VELOCITY), 0);
        assert!(d.velocity().abs() < 1.0, "still turning at {}", d.velocity());
        let last_tpdo = out.iter().rev().find_map(|f| VelocityStatus::parse(f).ok()).map(|(_, s)| s);
        assert!(
            last_tpdo.is_some_and(|t| DriveState::from_statusword(t.statusword) == Some(DriveState::QuickStopActive)),
            "{last_tpdo:?}"
        );
    }

    /// A heartbeat on the host's id goes on (produced elsewhere) while the commands stop at
    /// `hung_from_ms`.
    #[test]
    fn a_drive_quick_stops_when_the_commands_stop_though_the_heartbeat_goes_on() {
        let mut d = MockDrive::new(5, 0.05);
        d.poll(0, &mut Vec::new());
        let a = Address::new;
        let consumer = starc_base::cia402::nmt::consumer_heartbeat_entry(127, 150);
        for (at, value) in [
            (a(0x6060, 0), Value::i8(3)),
            (a(0x6007, 0), Value::i16(3)),
            (a(0x1016, 1), Value::u32(consumer)),
            (a(0x1400, 5), Value::u16(100)),
        ] {
            assert_eq!(sdo(&mut d, SdoRequest::Download { at, value }), Some(SdoResponse::Downloaded { at }));
        }
        for cw in [6u16, 7, 0x0F] {
            sdo(&mut d, SdoRequest::Download { at: a(0x6040, 0), value: Value::u16(cw) });
        }
        let frame = |r: starc_base::Result<CanFrame>| r.unwrap_or_else(|e| panic!("{e}"));
        let mut out = Vec::new();
        d.on_frame(&frame(NmtCommand::Start.to_frame(5)), 0, &mut out);
        let command = frame(VelocityCommand { controlword: 0x0F, target_velocity: 300 }.to_frame(5));
        let host_beat = frame(heartbeat_frame(127, NmtState::Operational));
        let hung_from_ms = 1000;
        for ms in 0..=1600u64 {
            let now = ms * 1_000_000;
            if ms % 50 == 0 {
                d.on_frame(&host_beat, now, &mut out);
            }
            if ms < hung_from_ms && ms % 10 == 0 {
                d.on_frame(&command, now, &mut out);
            }
            d.poll(now, &mut out);
        }
        let s = d.stats;
        assert_eq!((s.consumer_timeouts, s.rpdo_timeouts), (0, 1), "{s:?}");
        assert_eq!(d.state(), DriveState::QuickStopActive);
        let last_command_ns = (hung_from_ms - 10) * 1_000_000;
        let after_ms = s.left_enabled_ns.unwrap_or(u64::MAX).saturating_sub(last_command_ns) as f64 * 1e-6;
        assert!(after_ms > 100.0 && after_ms <= 102.0, "stopped {after_ms} ms after the last command");
        assert!(out.iter().filter_map(|f| Emergency::parse(f).ok()).any(|e| e.node == 5 && e.code == 0x8250));
        assert!(d.velocity().abs() < 1.0, "still turning at {}", d.velocity());
    }

    #[test]
    fn without_a_consumer_heartbeat_the_drive_runs_on_when_the_host_dies() {
        // The failure the host's bring-up exists for: nothing stops this one.
        let (d, _) = host_goes_silent(None, 1001, 1600);
        assert_eq!(d.state(), DriveState::OperationEnabled);
        assert_eq!(d.stats.consumer_timeouts, 0);
        assert!(d.velocity() > 290.0, "{}", d.velocity());
    }

    #[test]
    fn monitoring_starts_with_the_first_heartbeat_and_each_option_acts() {
        // Never a heartbeat: the consumer does not start (CiA 301), the drive keeps running.
        let (d, _) = host_goes_silent(Some(150), 0, 500);
        assert_eq!((d.state(), d.stats.consumer_timeouts), (DriveState::OperationEnabled, 0));
        // 0x6007 = 2 and 1: disable voltage, fault.
        for (option, want) in [(2i16, DriveState::SwitchOnDisabled), (1, DriveState::Fault)] {
            let mut d = MockDrive::new(6, 0.05);
            d.poll(0, &mut Vec::new());
            let a = Address::new;
            for (at, value) in [
                (a(0x6007, 0), Value::i16(option)),
                (a(0x1016, 1), Value::u32(starc_base::cia402::nmt::consumer_heartbeat_entry(127, 100))),
            ] {
                sdo(&mut d, SdoRequest::Download { at, value });
            }
            for cw in [6u16, 7, 0x0F] {
                sdo(&mut d, SdoRequest::Download { at: a(0x6040, 0), value: Value::u16(cw) });
            }
            let mut out = Vec::new();
            let beat = heartbeat_frame(127, NmtState::Operational).unwrap_or_else(|e| panic!("{e}"));
            d.on_frame(&beat, 0, &mut out);
            for ms in 0..=150u64 {
                d.poll(ms * 1_000_000, &mut out);
            }
            assert_eq!(d.state(), want, "option {option}");
        }
    }
}
