//! The node against a scripted drive that answers SDOs like a CiA 402 device.

use super::*;
use crate::cia402::sdo::abort;
use starc_time::Clock;

fn at_ms(ms: u64) -> Stamp {
    Stamp::new(ms * 1_000_000, Clock::Host)
}

/// Just enough of a drive: SDO answers, a controlword-driven state, TPDO1 on demand.
struct Drive {
    node: u8,
    state: DriveState,
    refuse: Option<Address>,
    stuck_in_fault: bool,
}

impl Drive {
    fn answer(&mut self, frame: &CanFrame) -> Option<CanFrame> {
        let (node, req) = SdoRequest::parse(frame).ok()?;
        if node != self.node {
            return None;
        }
        let resp = match req {
            SdoRequest::Download { at, .. } | SdoRequest::Upload { at } if Some(at) == self.refuse => {
                SdoResponse::Abort { at, code: abort::NO_OBJECT }
            }
            SdoRequest::Download { at, value } => {
                if at.index == object::CONTROLWORD {
                    self.state = match (self.state, value.raw as u16) {
                        (DriveState::Fault, controlword::FAULT_RESET) if !self.stuck_in_fault => {
                            DriveState::SwitchOnDisabled
                        }
                        (DriveState::Fault, _) => DriveState::Fault,
                        (_, controlword::DISABLE_VOLTAGE) => DriveState::SwitchOnDisabled,
                        (DriveState::SwitchOnDisabled, controlword::SHUTDOWN) => DriveState::ReadyToSwitchOn,
                        (DriveState::ReadyToSwitchOn, controlword::SWITCH_ON) => DriveState::SwitchedOn,
                        (DriveState::SwitchedOn, controlword::ENABLE_OPERATION) => DriveState::OperationEnabled,
                        (s, _) => s,
                    };
                }
                SdoResponse::Downloaded { at }
            }
            SdoRequest::Upload { at } => {
                let value = match at.index {
                    object::MODES_DISPLAY => Value::i8(3),
                    object::STATUSWORD => Value::u16(self.state.statusword()),
                    _ => Value::u32(0),
                };
                SdoResponse::Uploaded { at, value }
            }
            SdoRequest::Abort { .. } => return None,
        };
        resp.to_frame(self.node).ok()
    }
}

/// Runs node and drive against each other for `ms` milliseconds, one tick per ms.
fn run(n: &mut Cia402Node, d: &mut Drive, from_ms: u64, ms: u64, faults: &mut Vec<Fault>) -> Vec<CanFrame> {
    let mut sent = Vec::new();
    for t in from_ms..from_ms + ms {
        let mut out = Vec::new();
        n.tick(at_ms(t), DriveMode::Run, 2.0, &mut out, faults);
        for f in out {
            sent.push(f);
            if let Some(reply) = d.answer(&f) {
                n.handle_frame(&reply, at_ms(t), faults);
            }
        }
        if t % 10 == 0 {
            let hb = crate::cia402::nmt::heartbeat_frame(d.node, NmtState::Operational).ok();
            if let Some(hb) = hb {
                n.handle_frame(&hb, at_ms(t), faults);
            }
            let status = VelocityStatus { statusword: d.state.statusword(), actual_velocity: 19 };
            if let Ok(f) = status.to_frame(d.node) {
                n.handle_frame(&f, at_ms(t), faults);
            }
        }
    }
    sent
}

fn drive(node: u8) -> Drive {
    Drive { node, state: DriveState::Fault, refuse: None, stuck_in_fault: false }
}

#[test]
fn brings_a_faulted_drive_up_and_drives_it() {
    let mut n = Cia402Node::new(0, 3, true, Cia402Config::default(), 100);
    let mut d = drive(3);
    let mut faults = Vec::new();
    n.start(at_ms(0));
    let sent = run(&mut n, &mut d, 0, 200, &mut faults);
    assert!(faults.is_empty(), "{faults:?}");
    assert!(n.is_running());
    assert_eq!(d.state, DriveState::OperationEnabled);
    assert_eq!(sent.first().map(|f| f.to_string()), Some("000#8003".to_string()));
    assert!(sent.iter().any(|f| f.to_string() == "000#0103"), "NMT start");
    // Controlwords in order: fault reset, disable voltage, 6, 7, 0x0F.
    let cws: Vec<u16> = sent
        .iter()
        .filter_map(|f| match SdoRequest::parse(f) {
            Ok((_, SdoRequest::Download { at, value })) if at.index == object::CONTROLWORD => Some(value.raw as u16),
            _ => None,
        })
        .collect();
    assert_eq!(cws, vec![0x80, 0x00, 0x06, 0x07, 0x0F]);
    // Running: RPDO1 with the inverted target in rpm (2 rad/s = 19.1 rpm).
    let last = sent.last().and_then(|f| VelocityCommand::parse(f).ok());
    assert_eq!(last, Some((3, VelocityCommand { controlword: 0x0F, target_velocity: -19 })));
    let m = n.measured(at_ms(199)).unwrap_or(0.0);
    assert!((m + 19.0 / (60.0 / std::f64::consts::TAU)).abs() < 1e-9, "{m}");
}

#[test]
fn an_sdo_abort_fails_setup_with_its_meaning() {
    let mut n = Cia402Node::new(1, 4, false, Cia402Config::default(), 100);
    let mut d = Drive { refuse: Some(Address::new(object::MODES_OF_OPERATION, 0)), ..drive(4) };
    let mut faults = Vec::new();
    n.start(at_ms(0));
    run(&mut n, &mut d, 0, 100, &mut faults);
    assert_eq!(faults.len(), 1, "{faults:?}");
    let text = faults.first().map(|f| f.to_string()).unwrap_or_default();
    assert!(text.contains("0x06020000") && text.contains("object does not exist") && text.contains("0x6060"), "{text}");
    assert!(!n.is_running());
}

#[test]
fn a_drive_stuck_in_fault_times_out_and_silence_is_noticed() {
    let mut n = Cia402Node::new(0, 5, false, Cia402Config::default(), 100);
    let mut d = Drive { stuck_in_fault: true, ..drive(5) };
    let mut faults = Vec::new();
    n.start(at_ms(0));
    run(&mut n, &mut d, 0, 800, &mut faults);
    assert!(matches!(faults.as_slice(), [Fault::Setup { reason, .. }] if reason.contains("Fault")), "{faults:?}");

    // A healthy drive that goes quiet after enabling: heartbeat and feedback time-outs.
    let mut n = Cia402Node::new(0, 6, false, Cia402Config::default(), 100);
    let mut d = drive(6);
    let mut faults = Vec::new();
    n.start(at_ms(0));
    run(&mut n, &mut d, 0, 200, &mut faults);
    assert!(n.is_running());
    for t in 200..700 {
        n.tick(at_ms(t), DriveMode::Run, 0.0, &mut Vec::new(), &mut faults);
    }
    // Feedback (100 ms) goes first, the heartbeat (350 ms) follows; each is reported once.
    assert!(
        matches!(faults.as_slice(), [Fault::FeedbackTimeout { motor: 6, .. }, Fault::HeartbeatTimeout { node: 6, .. }]),
        "{faults:?}"
    );
}

#[test]
fn emcy_and_a_faulted_statusword_stop_the_node() {
    let mut n = Cia402Node::new(2, 7, false, Cia402Config::default(), 100);
    let mut d = drive(7);
    let mut faults = Vec::new();
    n.start(at_ms(0));
    run(&mut n, &mut d, 0, 200, &mut faults);
    let emcy = Emergency { node: 7, code: 0x2310, register: 0x03, vendor: [0; 5] };
    assert!(emcy.to_frame().is_ok_and(|f| n.handle_frame(&f, at_ms(201), &mut faults)));
    assert!(matches!(faults.as_slice(), [Fault::Emergency { code: 0x2310, node: 7, wheel: 2, .. }]), "{faults:?}");
    let mut out = Vec::new();
    n.tick(at_ms(202), DriveMode::Run, 3.0, &mut out, &mut faults);
    assert_eq!(
        out.first().and_then(|f| VelocityCommand::parse(f).ok()).map(|(_, c)| c.controlword),
        Some(controlword::QUICK_STOP)
    );

    let mut n = Cia402Node::new(0, 8, false, Cia402Config::default(), 100);
    let mut d = drive(8);
    let mut faults = Vec::new();
    n.start(at_ms(0));
    run(&mut n, &mut d, 0, 200, &mut faults);
    d.state = DriveState::Fault;
    run(&mut n, &mut d, 200, 20, &mut faults);
    assert!(matches!(faults.first(), Some(Fault::DriveFault { node: 8, .. })), "{faults:?}");
}

#[test]
fn bring_up_arms_the_consumer_heartbeat_and_the_abort_option_before_enabling() {
    let config = Cia402Config { host_node_id: 100, consumer_heartbeat_ms: 150, ..Cia402Config::default() };
    let mut n = Cia402Node::new(0, 3, false, config, 100);
    let mut d = drive(3);
    let mut faults = Vec::new();
    n.start(at_ms(0));
    let sent = run(&mut n, &mut d, 0, 200, &mut faults);
    assert!(faults.is_empty() && n.is_running(), "{faults:?}");
    let writes: Vec<(Address, Value)> = sent
        .iter()
        .filter_map(|f| match SdoRequest::parse(f) {
            Ok((3, SdoRequest::Download { at, value })) => Some((at, value)),
            _ => None,
        })
        .collect();
    let position = |index: u16, sub: u8| writes.iter().position(|(at, _)| *at == Address::new(index, sub));
    let consumer = position(object::CONSUMER_HEARTBEAT, 1).unwrap_or_else(|| panic!("no 0x1016:01 write"));
    let option = position(object::ABORT_CONNECTION_OPTION, 0).unwrap_or_else(|| panic!("no 0x6007 write"));
    // Host node 100 (0x64) in bits 23-16, 150 ms (0x96) in bits 15-0, a 32-bit value.
    assert_eq!(writes.get(consumer).map(|w| w.1), Some(Value::u32(0x0064_0096)));
    // Quick stop (3), a 16-bit signed value.
    assert_eq!(writes.get(option).map(|w| w.1), Some(Value::i16(3)));
    assert_eq!(
        sent.iter()
            .filter_map(|f| SdoRequest::parse(f).ok())
            .filter(
                |(_, r)| matches!(r, SdoRequest::Download { at, .. } if at.index == object::ABORT_CONNECTION_OPTION)
            )
            .count(),
        1
    );
    let deadline = position(object::RPDO1_COMM, 5).unwrap_or_else(|| panic!("no 0x1400:05 write"));
    assert_eq!(writes.get(deadline).map(|w| w.1), Some(Value::u16(100)));
    // All before the drive can be enabled (the first controlword) or started (NMT start).
    let first_cw = position(object::CONTROLWORD, 0).unwrap_or(usize::MAX);
    assert!(consumer < first_cw && option < first_cw && deadline < first_cw, "{writes:?}");
    let nmt_start = sent.iter().position(|f| f.to_string() == "000#0103").unwrap_or(0);
    let consumer_frame = sent
        .iter()
        .position(|f| matches!(SdoRequest::parse(f), Ok((_, SdoRequest::Download { at, .. })) if at.index == object::CONSUMER_HEARTBEAT))
        .unwrap_or(usize::MAX);
    assert!(consumer_frame < nmt_start);
}

#[test]
fn a_drive_without_a_consumer_heartbeat_is_never_enabled() {
    let mut n = Cia402Node::new(0, 4, false, Cia402Config::default(), 100);
    let mut d = Drive { refuse: Some(Address::new(object::CONSUMER_HEARTBEAT, 1)), ..drive(4) };
    let mut faults = Vec::new();
    n.start(at_ms(0));
    let sent = run(&mut n, &mut d, 0, 200, &mut faults);
    let text = faults.first().map(|f| f.to_string()).unwrap_or_default();
    assert!(text.contains("0x1016:01"), "{faults:?}");
    assert!(!n.is_running());
    assert!(!sent.iter().any(|f| f.to_string() == "000#0104"), "NMT start sent");
    assert_ne!(d.state, DriveState::OperationEnabled);
}

#[test]
fn config_refuses_a_heartbeat_that_cannot_protect() {
    let ok = Cia402Config::default();
    assert!(ok.validate().is_ok());
    for bad in [
        Cia402Config { consumer_heartbeat_ms: 50, ..ok.clone() },
        Cia402Config { host_heartbeat_ms: 0, ..ok.clone() },
        Cia402Config { host_node_id: 0, ..ok.clone() },
        Cia402Config { host_node_id: 128, ..ok.clone() },
        Cia402Config { abort_connection_option: 0, ..ok.clone() },
    ] {
        assert!(bad.validate().is_err(), "{bad:?}");
    }
}
