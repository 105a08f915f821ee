//! The base controller, sans-IO: velocity commands, CAN frames, bus faults, the emergency stop
//! and time in; CAN frames, events and a status out. Per control period: the safety decides the
//! mode, the limiter ramps the commanded twist, the kinematics turns it into wheel rates (scaled
//! under the wheel limit), the motor protocol turns those into frames, and the measured wheel
//! rates feed the odometry.

use crate::config::BaseConfig;
use crate::error::Result;
use crate::kinematics::{Kinematics, Twist};
use crate::limits::TwistLimiter;
use crate::motor::WheelState;
use crate::motors::Motors;
use crate::odometry::{Odometry, OdometrySample};
use crate::safety::{ClearRefused, DriveMode, Fault, Safety};
use serde::Serialize;
use starc_can::{BusEvent, CanFrame};
use starc_time::Stamp;

/// Something worth telling the operator.
#[derive(Clone, Debug, PartialEq, Serialize)]
#[serde(tag = "event", rename_all = "snake_case")]
pub enum BaseEvent {
    /// A fault was latched; the base is halted until [`Base::clear_faults`].
    Fault {
        fault: Fault,
        stamp: Stamp,
    },
    /// The operator cleared these faults.
    Cleared {
        faults: Vec<Fault>,
        stamp: Stamp,
    },
    /// No command for the watchdog period: braking to zero.
    WatchdogTripped {
        stamp: Stamp,
    },
    EmergencyStop {
        pressed: bool,
        stamp: Stamp,
    },
}

/// A snapshot for status displays.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct BaseStatus {
    pub stamp: Option<Stamp>,
    pub mode: DriveMode,
    /// Every motor enabled and reporting.
    pub ready: bool,
    pub estop_pressed: bool,
    pub watchdog_tripped: bool,
    pub faults: Vec<Fault>,
    /// The twist asked for last, and the ramped setpoint being driven.
    pub commanded: Twist,
    pub setpoint: Twist,
    pub wheels: Vec<WheelState>,
    pub odometry: Option<OdometrySample>,
    /// Frames from our motors that did not parse.
    pub malformed_frames: u64,
    /// CANopen heartbeats the host has sent (CiA 402; 0 for C620).
    pub host_heartbeats: u64,
}

pub struct Base {
    config: BaseConfig,
    kinematics: Kinematics,
    motors: Motors,
    safety: Safety,
    limiter: TwistLimiter,
    odometry: Odometry,
    commanded: Twist,
    mode: DriveMode,
    last_tick: Option<Stamp>,
    events: Vec<BaseEvent>,
    faults: Vec<Fault>,
}

impl Base {
    pub fn new(config: BaseConfig) -> Result<Self> {
        config.validate()?;
        let kinematics = Kinematics::new(&config.kinematics)?;
        let motors = Motors::new(&config)?;
        Ok(Self {
            safety: Safety::new(config.watchdog_ms),
            limiter: TwistLimiter::new(config.limits.clone()),
            kinematics,
            motors,
            odometry: Odometry::new(),
            commanded: Twist::ZERO,
            mode: DriveMode::Brake,
            last_tick: None,
            events: Vec::new(),
            faults: Vec::new(),
            config,
        })
    }

    pub fn config(&self) -> &BaseConfig {
        &self.config
    }

    /// A velocity command (feeds the watchdog).
    pub fn command(&mut self, twist: Twist, now: Stamp) {
        self.commanded = if twist.is_finite() { twist } else { Twist::ZERO };
        self.safety.commanded(now);
    }

    /// The emergency stop input.
    pub fn set_estop(&mut self, pressed: bool, now: Stamp) {
        if pressed != self.safety.estop_pressed() {
            self.events.push(BaseEvent::EmergencyStop { pressed, stamp: now });
        }
        if self.safety.set_estop(pressed) {
            self.events.push(BaseEvent::Fault { fault: Fault::EmergencyStop, stamp: now });
        }
    }

    /// Operator clear of every latched fault (refused while the emergency stop is pressed).
    /// The motors are brought up again (CiA 402: fault reset and enable sequence).
    pub fn clear_faults(&mut self, now: Stamp) -> std::result::Result<Vec<Fault>, ClearRefused> {
        let cleared = self.safety.clear()?;
        self.motors.clear(now);
        self.limiter.reset();
        self.commanded = Twist::ZERO;
        self.events.push(BaseEvent::Cleared { faults: cleared.clone(), stamp: now });
        Ok(cleared)
    }

    /// Something from the bus.
    pub fn handle(&mut self, event: &BusEvent) {
        match event {
            BusEvent::Frame(rx) => {
                self.motors.handle_frame(&rx.frame, rx.host, &mut self.faults);
                self.latch_new(rx.host);
            }
            BusEvent::Fault { fault, host } => {
                tracing::warn!("CAN bus fault: {fault:?}");
                if self.config.stop_on_bus_fault {
                    self.faults.push(Fault::Bus { fault: *fault });
                    self.latch_new(*host);
                }
            }
        }
    }

    /// The transport did not take a frame within `timeout_ms`: latched, so the base halts until
    /// the operator clears it.
    pub fn send_timed_out(&mut self, timeout_ms: u64, now: Stamp) {
        tracing::warn!("CAN send timed out after {timeout_ms} ms");
        self.faults.push(Fault::SendTimeout { timeout_ms });
        self.latch_new(now);
    }

    fn latch_new(&mut self, now: Stamp) {
        for fault in self.faults.drain(..) {
            if self.safety.latch(fault.clone()) {
                self.events.push(BaseEvent::Fault { fault, stamp: now });
            }
        }
    }

    /// One control period: appends the frames to send.
    pub fn tick(&mut self, now: Stamp, out: &mut Vec<CanFrame>) {
        let dt_s = self.last_tick.and_then(|t| now.since(t)).map(|ns| ns.max(0) as f64 * 1e-9).unwrap_or(0.0);
        self.last_tick = Some(now);
        let (mut mode, tripped) = self.safety.mode(now);
        if tripped {
            self.events.push(BaseEvent::WatchdogTripped { stamp: now });
        }
        if !self.motors.ready() && mode == DriveMode::Run {
            mode = DriveMode::Brake;
        }
        let setpoint = match mode {
            DriveMode::Run => self.limiter.step(self.commanded, dt_s),
            DriveMode::Brake => self.limiter.step(Twist::ZERO, dt_s),
            DriveMode::Halt => {
                self.limiter.reset();
                Twist::ZERO
            }
        };
        let mut wheels = self.kinematics.wheel_rates(setpoint);
        self.limiter.limit_wheels(&mut wheels);
        self.motors.tick(now, mode, &wheels, out, &mut self.faults);
        self.latch_new(now);
        self.mode = mode;
        if let Some(measured) = self.motors.measured(now) {
            self.odometry.update(&self.kinematics, &measured, now);
        }
    }

    /// Events since the last call.
    pub fn drain_events(&mut self) -> Vec<BaseEvent> {
        std::mem::take(&mut self.events)
    }

    pub fn status(&self) -> BaseStatus {
        BaseStatus {
            stamp: self.last_tick,
            mode: self.mode,
            ready: self.motors.ready()
                && self.motors.measured(self.last_tick.unwrap_or(Stamp::new(0, starc_time::Clock::Host))).is_some(),
            estop_pressed: self.safety.estop_pressed(),
            watchdog_tripped: self.safety.watchdog_tripped(),
            faults: self.safety.latched().to_vec(),
            commanded: self.commanded,
            setpoint: self.limiter.setpoint(),
            wheels: self.motors.wheel_states(),
            odometry: self.odometry.last(),
            malformed_frames: self.motors.malformed(),
            host_heartbeats: self.motors.heartbeats_sent(),
        }
    }

    /// Frames that stop every motor, for shutdown.
    pub fn halt_frames(&self) -> Vec<CanFrame> {
        self.motors.halt_frames()
    }
}

#[cfg(test)]
pub(crate) mod tests;
