//! The robot's base in the loop: the base driver (`starc_base::Base`) on the host side, its
//! frames as slcan bytes to the mock adapter and motor controllers
//! (`starc_hil::motors::MotorsDevice`), their feedback back the same way, all on the
//! simulator's clock in 1 ms steps. The bytes are the ones a serial line to an slcan adapter
//! would carry; only the pty between them is left out, so a run gives the same result every
//! time it is run.

use crate::{EvalError, Result};
use starc_base::config::Protocol;
use starc_base::{Base, BaseConfig, BaseStatus, Twist};
use starc_can::slcan::{Command, HostItem, SlcanHost};
use starc_can::CanFrame;
use starc_hil::motors::device::DeviceSettings;
use starc_hil::motors::{MockProtocol, MotorFaultConfig, MotorsDevice, MotorsStats};
use starc_pipeline::lio::Clock;
use starc_time::Stamp;
use std::collections::VecDeque;

/// One motor step.
pub const STEP_NS: u64 = 1_000_000;
/// The controllers' feedback rate and their motors' time constant (the mock's defaults).
const FEEDBACK_HZ: f64 = 1000.0;
const MOTOR_TAU_S: f64 = 0.05;

/// Frames the host sent and received, and what the adapter and motors counted.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct BusCounts {
    pub frames_sent: u64,
    pub feedback_frames: u64,
    pub motors: MotorsStats,
}

/// See the module's documentation.
pub struct BaseInTheLoop {
    base: Base,
    host: SlcanHost,
    device: MotorsDevice,
    items: VecDeque<HostItem>,
    to_host: Vec<u8>,
    control_period_ns: u64,
    next_tick_ns: u64,
    /// Wheel controllers' ids in the kinematics' order, and whether each turns the other way.
    wheels: Vec<(u8, bool)>,
    /// Drive units per wheel rad/s (CiA 402); the C620s report the wheel's rad/s.
    units_per_rad_s: Option<f64>,
    frames_sent: u64,
    feedback_frames: u64,
}

impl BaseInTheLoop {
    /// The base `cfg` describes, its controllers simulated; the adapter is opened at once
    /// (`S8`, `O`).
    pub fn new(cfg: BaseConfig, seed: u64) -> Result<Self> {
        let bad = |e: starc_base::BaseError| EvalError::Input(format!("base: {e}"));
        let (protocol, units_per_rad_s) = match cfg.motors.protocol {
            Protocol::C620 => (MockProtocol::C620, None),
            Protocol::Cia402 => (MockProtocol::Cia402, Some(cfg.motors.cia402.units_per_rad_s)),
        };
        let wheels: Vec<(u8, bool)> = cfg.motors.wheels.iter().map(|w| (w.id, w.invert)).collect();
        let device = MotorsDevice::new(&DeviceSettings {
            protocol,
            ids: wheels.iter().map(|w| w.0).collect(),
            feedback_hz: FEEDBACK_HZ,
            tau_s: MOTOR_TAU_S,
            seed,
            faults: MotorFaultConfig::default(),
        });
        let control_period_ns = cfg.control_period_ms.max(1) * 1_000_000;
        let mut me = Self {
            base: Base::new(cfg).map_err(bad)?,
            host: SlcanHost::new(),
            device,
            items: VecDeque::new(),
            to_host: Vec::new(),
            control_period_ns,
            next_tick_ns: 0,
            wheels,
            units_per_rad_s,
            frames_sent: 0,
            feedback_frames: 0,
        };
        let mut opening = Vec::new();
        Command::Bitrate(8).encode(&mut opening);
        Command::Open.encode(&mut opening);
        me.device.on_host_bytes(&opening, 0, &mut me.to_host);
        me.host.set_open(true);
        Ok(me)
    }

    /// A velocity command from the host at `now_ns` (PTP).
    pub fn command(&mut self, twist: Twist, now_ns: u64) {
        self.base.command(twist, Stamp::new(now_ns, Clock::Ptp));
    }

    /// The millisecond from `sim_ns` (the simulator's clock; `ptp_ns` the same instant on the
    /// host's): the motors advance and report, the host takes their bytes, and ticks when a
    /// control period is due. The feedback frames the host received are appended to `frames`.
    pub fn step(&mut self, sim_ns: u64, ptp_ns: u64, frames: &mut Vec<CanFrame>) {
        self.device.poll(sim_ns, &mut self.to_host);
        let now = Stamp::new(ptp_ns, Clock::Ptp);
        self.host.receive(&self.to_host, now, &mut self.items);
        self.to_host.clear();
        while let Some(item) = self.items.pop_front() {
            if let HostItem::Event(event) = item {
                if let starc_can::BusEvent::Frame(rx) = &event {
                    self.feedback_frames += 1;
                    frames.push(rx.frame);
                }
                self.base.handle(&event);
            }
        }
        if sim_ns >= self.next_tick_ns {
            self.next_tick_ns = sim_ns + self.control_period_ns;
            let mut out = Vec::new();
            self.base.tick(now, &mut out);
            let mut bytes = Vec::new();
            for f in &out {
                Command::Transmit(*f).encode(&mut bytes);
                self.host.count_sent();
            }
            self.frames_sent += out.len() as u64;
            self.device.on_host_bytes(&bytes, sim_ns, &mut self.to_host);
        }
    }

    /// How fast each wheel really turns (rad/s, the kinematics' order and sign).
    pub fn true_wheel_rad_s(&self) -> Vec<f64> {
        let speeds = self.device.true_speeds();
        self.wheels
            .iter()
            .map(|&(id, invert)| {
                let raw = speeds.iter().find(|s| s.0 == id).map_or(0.0, |s| s.1);
                let rad_s = self.units_per_rad_s.map_or(raw, |u| raw / u);
                if invert {
                    -rad_s
                } else {
                    rad_s
                }
            })
            .collect()
    }

    pub fn status(&self) -> BaseStatus {
        self.base.status()
    }

    pub fn counts(&self) -> BusCounts {
        BusCounts { frames_sent: self.frames_sent, feedback_frames: self.feedback_frames, motors: self.device.stats() }
    }
}
