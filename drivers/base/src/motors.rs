//! The motor protocols behind one interface, chosen by the config.

use crate::c620::C620Group;
use crate::cia402::Cia402Group;
use crate::config::{BaseConfig, Protocol};
use crate::error::Result;
use crate::motor::WheelState;
use crate::safety::{DriveMode, Fault};
use starc_can::CanFrame;
use starc_time::Stamp;

#[derive(Clone, Debug)]
pub enum Motors {
    C620(C620Group),
    Cia402(Cia402Group),
}

impl Motors {
    pub fn new(config: &BaseConfig) -> Result<Self> {
        let ids = config.motor_ids();
        let timeout = config.motors.feedback_timeout_ms;
        Ok(match config.motors.protocol {
            Protocol::C620 => Self::C620(C620Group::new(config.motors.c620.clone(), &ids, timeout)?),
            Protocol::Cia402 => Self::Cia402(Cia402Group::new(config.motors.cia402.clone(), &ids, timeout)?),
        })
    }

    pub fn handle_frame(&mut self, frame: &CanFrame, now: Stamp, faults: &mut Vec<Fault>) -> bool {
        match self {
            Self::C620(g) => g.handle_frame(frame, now),
            Self::Cia402(g) => g.handle_frame(frame, now, faults),
        }
    }

    pub fn tick(
        &mut self,
        now: Stamp,
        mode: DriveMode,
        targets: &[f64],
        out: &mut Vec<CanFrame>,
        faults: &mut Vec<Fault>,
    ) {
        match self {
            Self::C620(g) => g.tick(now, mode, targets, out, faults),
            Self::Cia402(g) => g.tick(now, mode, targets, out, faults),
        }
    }

    pub fn clear(&mut self, now: Stamp) {
        match self {
            Self::C620(g) => g.clear(),
            Self::Cia402(g) => g.clear(now),
        }
    }

    /// Ready to take velocity commands (C620: always; CiA 402: every node enabled).
    pub fn ready(&self) -> bool {
        match self {
            Self::C620(_) => true,
            Self::Cia402(g) => g.ready(),
        }
    }

    pub fn measured(&self, now: Stamp) -> Option<Vec<f64>> {
        match self {
            Self::C620(g) => g.measured(now),
            Self::Cia402(g) => g.measured(now),
        }
    }

    pub fn wheel_states(&self) -> Vec<WheelState> {
        match self {
            Self::C620(g) => g.wheel_states(),
            Self::Cia402(g) => g.wheel_states(),
        }
    }

    pub fn halt_frames(&self) -> Vec<CanFrame> {
        match self {
            Self::C620(g) => g.halt_frames(),
            Self::Cia402(g) => g.halt_frames(),
        }
    }

    /// Host heartbeats sent (CiA 402 only: the C620 has no such thing).
    pub fn heartbeats_sent(&self) -> u64 {
        match self {
            Self::C620(_) => 0,
            Self::Cia402(g) => g.heartbeats_sent(),
        }
    }

    pub fn malformed(&self) -> u64 {
        match self {
            Self::C620(g) => g.malformed,
            Self::Cia402(g) => g.malformed(),
        }
    }
}
