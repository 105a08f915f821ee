//! What may stop the base: the command watchdog (not latched), latched faults (motor feedback
//! lost, drive faults, emergencies, bus errors) that only an operator clears, and the emergency
//! stop input.

use serde::Serialize;
use starc_can::BusFault;
use starc_time::Stamp;

/// A reason to stop, latched until [`Safety::clear`].
#[derive(Clone, Debug, PartialEq, Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Fault {
    /// No feedback frame (C620) or TPDO (CiA 402) from a motor for too long.
    FeedbackTimeout { wheel: usize, motor: u8, silent_ms: u64 },
    /// A CANopen node's heartbeat stopped.
    HeartbeatTimeout { wheel: usize, node: u8, silent_ms: u64 },
    /// A CANopen node restarted (boot-up heartbeat) while it was driving.
    NodeRebooted { wheel: usize, node: u8 },
    /// A CANopen EMCY message with a non-zero error code.
    Emergency { wheel: usize, node: u8, code: u16, register: u8, meaning: String },
    /// The CiA 402 statusword says Fault.
    DriveFault { wheel: usize, node: u8, statusword: u16 },
    /// A CANopen node could not be brought up (SDO abort, timeout, unexpected state).
    Setup { wheel: usize, node: u8, reason: String },
    /// The CAN adapter or controller reported an error.
    Bus { fault: BusFault },
    /// The emergency stop input was asserted.
    EmergencyStop,
    /// A frame could not be handed to the CAN transport within the send time-out (adapter
    /// stalled, serial port blocked, kernel queue full): commands may not be reaching the motors.
    SendTimeout { timeout_ms: u64 },
}

impl Fault {
    /// Whether two faults are the same condition of the same part, whatever their details (an
    /// error frame's counters, how long a motor was silent, an EMCY's text): a repeat of a
    /// latched fault is counted against it, it does not add another.
    pub fn same_kind(&self, other: &Fault) -> bool {
        use Fault::*;
        match (self, other) {
            (FeedbackTimeout { wheel: a, .. }, FeedbackTimeout { wheel: b, .. })
            | (HeartbeatTimeout { wheel: a, .. }, HeartbeatTimeout { wheel: b, .. })
            | (NodeRebooted { wheel: a, .. }, NodeRebooted { wheel: b, .. })
            | (DriveFault { wheel: a, .. }, DriveFault { wheel: b, .. })
            | (Setup { wheel: a, .. }, Setup { wheel: b, .. }) => a == b,
            (Emergency { wheel: a, code: c, .. }, Emergency { wheel: b, code: d, .. }) => a == b && c == d,
            (Bus { fault: a }, Bus { fault: b }) => bus_kind(a) == bus_kind(b),
            (EmergencyStop, EmergencyStop) | (SendTimeout { .. }, SendTimeout { .. }) => true,
            _ => false,
        }
    }
}

/// A bus fault's kind: an error frame's class (`CAN_ERR_*` bits) counts, its details do not.
fn bus_kind(f: &BusFault) -> (u8, u32) {
    match f {
        BusFault::SlcanFlags { .. } => (0, 0),
        BusFault::TransmitRefused => (1, 0),
        BusFault::ErrorFrame { class, .. } => (2, *class),
    }
}

impl std::fmt::Display for Fault {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::FeedbackTimeout { wheel, motor, silent_ms } => {
                write!(f, "wheel {wheel} (motor {motor}): no feedback for {silent_ms} ms")
            }
            Self::HeartbeatTimeout { wheel, node, silent_ms } => {
                write!(f, "wheel {wheel} (node {node}): no heartbeat for {silent_ms} ms")
            }
            Self::NodeRebooted { wheel, node } => write!(f, "wheel {wheel} (node {node}): node rebooted"),
            Self::Emergency { wheel, node, code, register, meaning } => {
                write!(f, "wheel {wheel} (node {node}): EMCY {code:#06x} ({meaning}), error register {register:#04x}")
            }
            Self::DriveFault { wheel, node, statusword } => {
                write!(f, "wheel {wheel} (node {node}): drive fault, statusword {statusword:#06x}")
            }
            Self::Setup { wheel, node, reason } => write!(f, "wheel {wheel} (node {node}): setup failed: {reason}"),
            Self::Bus { fault } => write!(f, "CAN bus: {fault:?}"),
            Self::EmergencyStop => write!(f, "emergency stop"),
            Self::SendTimeout { timeout_ms } => write!(f, "CAN transport: a frame took over {timeout_ms} ms to send"),
        }
    }
}

/// How the motors are to be driven this tick.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum DriveMode {
    /// Follow the commanded twist.
    Run,
    /// The watchdog fired: hold zero velocity under control.
    Brake,
    /// A latched fault or the emergency stop: zero current (C620) / quick stop or zero velocity
    /// (CiA 402), setpoints reset.
    Halt,
}

/// Safety state of one base.
#[derive(Clone, Debug)]
pub struct Safety {
    watchdog_ns: u64,
    last_command: Option<Stamp>,
    watchdog_tripped: bool,
    estop_pressed: bool,
    latched: Vec<Fault>,
    /// How often each latched fault came again since it was latched.
    repeats: Vec<u64>,
}

/// Why a clear was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ClearRefused {
    EmergencyStopPressed,
}

impl Safety {
    pub fn new(watchdog_ms: u64) -> Self {
        Self {
            watchdog_ns: watchdog_ms.saturating_mul(1_000_000),
            last_command: None,
            watchdog_tripped: false,
            estop_pressed: false,
            latched: Vec::new(),
            repeats: Vec::new(),
        }
    }

    /// A velocity command arrived.
    pub fn commanded(&mut self, now: Stamp) {
        self.last_command = Some(now);
        self.watchdog_tripped = false;
    }

    /// Latches `fault` unless one of its kind is latched already (then counts the repeat, so an
    /// error-frame storm holds one entry, not one per frame); true when it is new.
    pub fn latch(&mut self, fault: Fault) -> bool {
        if let Some(i) = self.latched.iter().position(|f| f.same_kind(&fault)) {
            if let Some(n) = self.repeats.get_mut(i) {
                *n = n.saturating_add(1);
            }
            return false;
        }
        self.latched.push(fault);
        self.repeats.push(0);
        true
    }

    /// How often each latched fault (in [`Self::latched`]'s order) came again.
    pub fn repeats(&self) -> &[u64] {
        &self.repeats
    }

    /// The emergency stop input; pressing it latches [`Fault::EmergencyStop`].
    pub fn set_estop(&mut self, pressed: bool) -> bool {
        self.estop_pressed = pressed;
        pressed && self.latch(Fault::EmergencyStop)
    }

    /// Operator clear: drops every latched fault, unless the emergency stop is still pressed.
    pub fn clear(&mut self) -> Result<Vec<Fault>, ClearRefused> {
        if self.estop_pressed {
            return Err(ClearRefused::EmergencyStopPressed);
        }
        self.repeats.clear();
        Ok(std::mem::take(&mut self.latched))
    }

    /// The mode for this tick, and whether the watchdog just fired.
    pub fn mode(&mut self, now: Stamp) -> (DriveMode, bool) {
        if self.estop_pressed || !self.latched.is_empty() {
            return (DriveMode::Halt, false);
        }
        let stale = match self.last_command {
            None => true,
            Some(t) => now.since(t).is_none_or(|dt| dt < 0 || dt as u64 > self.watchdog_ns),
        };
        if stale {
            let first = !self.watchdog_tripped && self.last_command.is_some();
            self.watchdog_tripped = true;
            return (DriveMode::Brake, first);
        }
        (DriveMode::Run, false)
    }

    pub fn latched(&self) -> &[Fault] {
        &self.latched
    }

    pub fn estop_pressed(&self) -> bool {
        self.estop_pressed
    }

    pub fn watchdog_tripped(&self) -> bool {
        self.watchdog_tripped
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use starc_time::Clock;

    fn at_ms(ms: u64) -> Stamp {
        Stamp::new(ms * 1_000_000, Clock::Host)
    }

    #[test]
    fn watchdog_brakes_and_a_new_command_resumes() {
        let mut s = Safety::new(200);
        assert_eq!(s.mode(at_ms(0)), (DriveMode::Brake, false), "no command yet");
        s.commanded(at_ms(10));
        assert_eq!(s.mode(at_ms(200)), (DriveMode::Run, false));
        assert_eq!(s.mode(at_ms(211)), (DriveMode::Brake, true));
        assert_eq!(s.mode(at_ms(300)), (DriveMode::Brake, false), "reported once");
        s.commanded(at_ms(301));
        assert_eq!(s.mode(at_ms(302)), (DriveMode::Run, false));
    }

    #[test]
    fn faults_latch_until_cleared_and_estop_blocks_clear() {
        let mut s = Safety::new(200);
        s.commanded(at_ms(0));
        let f = Fault::FeedbackTimeout { wheel: 0, motor: 1, silent_ms: 120 };
        assert!(s.latch(f.clone()));
        assert!(!s.latch(f.clone()));
        s.commanded(at_ms(1));
        assert_eq!(s.mode(at_ms(2)).0, DriveMode::Halt);
        assert_eq!(s.clear(), Ok(vec![f]));
        assert_eq!(s.mode(at_ms(3)).0, DriveMode::Run);
        assert!(s.set_estop(true));
        assert_eq!(s.clear(), Err(ClearRefused::EmergencyStopPressed));
        assert!(!s.set_estop(false));
        assert_eq!(s.mode(at_ms(4)).0, DriveMode::Halt, "released is not cleared");
        assert_eq!(s.clear(), Ok(vec![Fault::EmergencyStop]));
    }

    #[test]
    fn an_error_frame_storm_latches_one_fault_and_counts_the_rest() {
        let mut safety = Safety::new(200);
        for i in 0..10_000u32 {
            let data = [(i % 256) as u8, (i / 256) as u8, 0, 0, 0, 0, 0, 0];
            safety.latch(Fault::Bus { fault: BusFault::ErrorFrame { class: 0x4, data } });
        }
        // Another class, another wheel's timeout, and the same wheel's timeout with another length.
        assert!(safety.latch(Fault::Bus { fault: BusFault::ErrorFrame { class: 0x40, data: [0; 8] } }));
        assert!(safety.latch(Fault::FeedbackTimeout { wheel: 0, motor: 1, silent_ms: 120 }));
        assert!(safety.latch(Fault::FeedbackTimeout { wheel: 1, motor: 2, silent_ms: 120 }));
        assert!(!safety.latch(Fault::FeedbackTimeout { wheel: 0, motor: 1, silent_ms: 900 }));
        assert_eq!(safety.latched().len(), 4);
        assert_eq!(safety.repeats(), &[9_999, 0, 1, 0]);
        assert_eq!(safety.clear().map(|f| f.len()), Ok(4));
        assert!(safety.repeats().is_empty());
    }
}
