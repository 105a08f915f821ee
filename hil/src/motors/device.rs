//! The whole mock, sans-IO: an slcan adapter on a bus of C620 ESCs or CiA 402 drives, with
//! faults. Host bytes and device time in; bytes for the host out.

use crate::motors::adapter::{AdapterStats, SlcanAdapter};
use crate::motors::c620::MockC620;
use crate::motors::cia402::{DriveStats, MockDrive};
use crate::motors::faults::{at_ns, MotorFaultConfig, MotorFaultStats};
use crate::rng::SplitMix64;
use serde::{Deserialize, Serialize};
use starc_can::slcan::StatusFlags;
use starc_can::CanFrame;

/// Which motor controllers are on the bus.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MockProtocol {
    #[default]
    C620,
    Cia402,
}

impl std::str::FromStr for MockProtocol {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "c620" => Ok(Self::C620),
            "cia402" => Ok(Self::Cia402),
            other => Err(format!("{other:?}: expected c620 or cia402")),
        }
    }
}

#[derive(Debug)]
enum Controllers {
    C620(MockC620),
    Cia402(Vec<MockDrive>),
}

/// Counters of a run.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct MotorsStats {
    pub adapter: AdapterStats,
    pub faults: MotorFaultStats,
    /// C620: current command frames seen.
    pub c620_commands: u64,
    /// CiA 402: per node.
    pub drives: Vec<(u8, DriveStats)>,
    /// Bytes for the host that did not fit the pty (nobody reading).
    pub overflow_bytes: u64,
}

/// Settings of the sans-IO device.
#[derive(Clone, Debug, PartialEq)]
pub struct DeviceSettings {
    pub protocol: MockProtocol,
    pub ids: Vec<u8>,
    pub feedback_hz: f64,
    pub tau_s: f64,
    pub seed: u64,
    pub faults: MotorFaultConfig,
}

pub struct MotorsDevice {
    adapter: SlcanAdapter,
    controllers: Controllers,
    faults: MotorFaultConfig,
    rng: SplitMix64,
    fault_stats: MotorFaultStats,
    motor_fault_done: bool,
    motor_fault_id: Option<u8>,
    bus: Vec<CanFrame>,
}

impl MotorsDevice {
    pub fn new(s: &DeviceSettings) -> Self {
        let controllers = match s.protocol {
            MockProtocol::C620 => Controllers::C620(MockC620::new(&s.ids, s.feedback_hz, s.tau_s)),
            MockProtocol::Cia402 => Controllers::Cia402(s.ids.iter().map(|&n| MockDrive::new(n, s.tau_s)).collect()),
        };
        Self {
            adapter: SlcanAdapter::new(),
            controllers,
            faults: s.faults.clone(),
            rng: SplitMix64::new(s.seed ^ 0xC0FF_EE00_CAFE_F00D),
            fault_stats: MotorFaultStats::default(),
            motor_fault_done: false,
            motor_fault_id: s.faults.motor_fault_id.or(s.ids.first().copied()),
            bus: Vec::new(),
        }
    }

    /// Bytes from the host at `now_ns`; appends what goes back.
    pub fn on_host_bytes(&mut self, bytes: &[u8], now_ns: u64, to_host: &mut Vec<u8>) {
        let mut replies = Vec::new();
        let mut frames = Vec::new();
        self.adapter.on_host_bytes(bytes, &mut replies, &mut frames);
        if !self.silent(now_ns) {
            to_host.extend_from_slice(&replies);
        }
        for f in frames {
            self.deliver(&f, now_ns);
        }
        self.flush_bus(now_ns, to_host);
    }

    /// Everything due by `now_ns`: motors, feedback, heartbeats, injected faults.
    pub fn poll(&mut self, now_ns: u64, to_host: &mut Vec<u8>) {
        if !self.motor_fault_done && at_ns(self.faults.motor_fault_after_s).is_some_and(|t| now_ns >= t) {
            self.motor_fault_done = true;
            self.fault_stats.motor_faults += 1;
            let id = self.motor_fault_id;
            match &mut self.controllers {
                Controllers::C620(c) => {
                    if let Some(id) = id {
                        c.kill(id);
                    }
                }
                Controllers::Cia402(drives) => {
                    for d in drives.iter_mut().filter(|d| Some(d.node()) == id) {
                        d.inject_fault(0, &mut self.bus);
                    }
                }
            }
        }
        if at_ns(self.faults.bus_error_after_s).is_some_and(|t| now_ns >= t) {
            self.adapter.flags = StatusFlags(StatusFlags::BUS_ERROR | StatusFlags::ERROR_WARNING);
        }
        match &mut self.controllers {
            Controllers::C620(c) => c.poll(now_ns, &mut self.bus),
            Controllers::Cia402(drives) => drives.iter_mut().for_each(|d| d.poll(now_ns, &mut self.bus)),
        }
        self.flush_bus(now_ns, to_host);
    }

    /// A frame from the host onto the bus: every controller sees it and may answer.
    fn deliver(&mut self, frame: &CanFrame, now_ns: u64) {
        match &mut self.controllers {
            Controllers::C620(c) => c.on_frame(frame),
            Controllers::Cia402(drives) => drives.iter_mut().for_each(|d| d.on_frame(frame, now_ns, &mut self.bus)),
        }
    }

    fn silent(&self, now_ns: u64) -> bool {
        at_ns(self.faults.silence_after_s).is_some_and(|t| now_ns >= t)
    }

    fn flush_bus(&mut self, now_ns: u64, to_host: &mut Vec<u8>) {
        let frames: Vec<CanFrame> = self.bus.drain(..).collect();
        for f in frames {
            // The same draws for every frame: a fault on frame k depends on the seed and k only.
            let (u_drop, u_garbage, junk) = (self.rng.next_f64(), self.rng.next_f64(), self.rng.next_u64());
            if self.silent(now_ns) {
                self.fault_stats.silenced_lines += 1;
                continue;
            }
            if u_drop < self.faults.drop {
                self.fault_stats.dropped += 1;
                continue;
            }
            if u_garbage < self.faults.garbage && self.adapter.is_open() {
                self.fault_stats.garbage_bursts += 1;
                let mut r = SplitMix64::new(junk);
                for _ in 0..1 + r.below(8) {
                    // Anything but CR and BEL: junk spoils the line it precedes, as line noise does.
                    let b = match r.below(256) as u8 {
                        b'\r' | 0x07 => b'?',
                        b => b,
                    };
                    to_host.push(b);
                }
            }
            self.adapter.to_host(&f, now_ns / 1_000_000, to_host);
        }
    }

    pub fn stats(&self) -> MotorsStats {
        let (c620_commands, drives) = match &self.controllers {
            Controllers::C620(c) => (c.commands, Vec::new()),
            Controllers::Cia402(d) => (0, d.iter().map(|d| (d.node(), d.stats)).collect()),
        };
        MotorsStats { adapter: self.adapter.stats, faults: self.fault_stats, c620_commands, drives, overflow_bytes: 0 }
    }

    pub fn is_open(&self) -> bool {
        self.adapter.is_open()
    }

    /// Each controller's id and its motor's true speed: output-shaft rad/s for the C620s
    /// (after the gearbox), drive units for CiA 402 (as its `0x606C` reports them). For the
    /// simulator, which moves the base as the motors really turn.
    pub fn true_speeds(&self) -> Vec<(u8, f64)> {
        match &self.controllers {
            Controllers::C620(c) => c.speeds(),
            Controllers::Cia402(drives) => drives.iter().map(|d| (d.node(), d.velocity())).collect(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use starc_can::slcan::{Line, LineSplitter, Reply};

    fn settings(protocol: MockProtocol, faults: MotorFaultConfig) -> DeviceSettings {
        DeviceSettings { protocol, ids: vec![1, 2], feedback_hz: 1000.0, tau_s: 0.05, seed: 3, faults }
    }

    fn replies(bytes: &[u8]) -> (Vec<Reply>, usize) {
        let mut lines = Vec::new();
        LineSplitter::new().push(bytes, &mut lines);
        let bad = lines.iter().filter(|l| Reply::decode(l).is_err()).count();
        (lines.iter().filter_map(|l: &Line| Reply::decode(l).ok()).collect(), bad)
    }

    #[test]
    fn feedback_only_while_open_and_faults_apply() {
        let faults = MotorFaultConfig {
            drop: 0.2,
            garbage: 0.1,
            motor_fault_after_s: Some(0.05),
            silence_after_s: Some(0.09),
            ..Default::default()
        };
        let mut d = MotorsDevice::new(&settings(MockProtocol::C620, faults));
        let mut out = Vec::new();
        d.poll(0, &mut out);
        assert!(out.is_empty(), "closed adapter sends nothing");
        d.on_host_bytes(b"S8\rO\r", 1_000_000, &mut out);
        assert_eq!(out, b"\r\r");
        out.clear();
        for ms in 2..100u64 {
            d.poll(ms * 1_000_000, &mut out);
        }
        let (frames, bad) = replies(&out);
        let s = d.stats();
        assert!(s.faults.dropped > 0 && s.faults.garbage_bursts > 0 && s.faults.motor_faults == 1, "{s:?}");
        assert!(bad > 0 && bad as u64 <= s.faults.garbage_bursts, "{bad} {s:?}");
        // ESC 1 dies at 50 ms: no feedback from 0x201 afterwards; silence from 90 ms.
        let from_1 =
            frames.iter().filter(|r| matches!(r, Reply::Frame { frame, .. } if frame.id().raw() == 0x201)).count();
        let from_2 =
            frames.iter().filter(|r| matches!(r, Reply::Frame { frame, .. } if frame.id().raw() == 0x202)).count();
        assert!(from_1 < 50 && from_2 > 55, "{from_1} {from_2}");
        assert!(s.faults.silenced_lines > 0);
    }

    #[test]
    fn bus_errors_show_in_f() {
        let faults = MotorFaultConfig { bus_error_after_s: Some(0.01), ..Default::default() };
        let mut d = MotorsDevice::new(&settings(MockProtocol::Cia402, faults));
        let mut out = Vec::new();
        d.on_host_bytes(b"S8\rO\rF\r", 0, &mut out);
        d.poll(20_000_000, &mut out);
        d.on_host_bytes(b"F\r", 20_000_000, &mut out);
        let (r, _) = replies(&out);
        let flags: Vec<u8> = r.iter().filter_map(|x| if let Reply::Status(f) = x { Some(f.0) } else { None }).collect();
        assert_eq!(flags, vec![0x00, 0x84]);
    }
}
