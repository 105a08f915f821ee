//! The CiA 402 drives of one base.

use crate::cia402::node::{Cia402Config, Cia402Node};
use crate::error::{BaseError, Result};
use crate::motor::WheelState;
use crate::safety::{DriveMode, Fault};
use starc_can::CanFrame;
use starc_time::Stamp;

#[derive(Clone, Debug)]
pub struct Cia402Group {
    nodes: Vec<Cia402Node>,
    started: bool,
}

impl Cia402Group {
    /// `nodes`: (node id 1-127, inverted) per wheel, in kinematics order.
    pub fn new(config: Cia402Config, nodes: &[(u8, bool)], feedback_timeout_ms: u64) -> Result<Self> {
        config.validate()?;
        let mut out = Vec::new();
        for (i, &(node, invert)) in nodes.iter().enumerate() {
            if !(1..=127).contains(&node) {
                return Err(BaseError::config("motors.wheels.id", format!("CANopen node id {node} is not 1-127")));
            }
            if nodes.iter().filter(|(n, _)| *n == node).count() > 1 {
                return Err(BaseError::config("motors.wheels.id", format!("node id {node} used twice")));
            }
            out.push(Cia402Node::new(i, node, invert, config.clone(), feedback_timeout_ms));
        }
        Ok(Self { nodes: out, started: false })
    }

    pub fn handle_frame(&mut self, frame: &CanFrame, now: Stamp, faults: &mut Vec<Fault>) -> bool {
        self.nodes.iter_mut().any(|n| n.handle_frame(frame, now, faults))
    }

    pub fn tick(
        &mut self,
        now: Stamp,
        mode: DriveMode,
        targets: &[f64],
        out: &mut Vec<CanFrame>,
        faults: &mut Vec<Fault>,
    ) {
        if !self.started {
            self.started = true;
            self.nodes.iter_mut().for_each(|n| n.start(now));
        }
        for (i, n) in self.nodes.iter_mut().enumerate() {
            n.tick(now, mode, targets.get(i).copied().unwrap_or(0.0), out, faults);
        }
    }

    /// Operator clear: every node goes through fault reset and the enable sequence again.
    pub fn clear(&mut self, now: Stamp) {
        self.nodes.iter_mut().for_each(|n| n.start(now));
    }

    pub fn ready(&self) -> bool {
        self.nodes.iter().all(Cia402Node::is_running)
    }

    pub fn measured(&self, now: Stamp) -> Option<Vec<f64>> {
        self.nodes.iter().map(|n| n.measured(now)).collect()
    }

    pub fn wheel_states(&self) -> Vec<WheelState> {
        self.nodes.iter().map(Cia402Node::wheel_state).collect()
    }

    pub fn halt_frames(&self) -> Vec<CanFrame> {
        self.nodes.iter().filter_map(Cia402Node::halt_frame).collect()
    }

    pub fn malformed(&self) -> u64 {
        self.nodes.iter().map(|n| n.malformed).sum()
    }
}
