//! The CiA 402 drives of one base.

use crate::cia402::nmt::HeartbeatProducer;
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
    /// The host's heartbeat, which every drive's consumer heartbeat (0x1016) watches.
    heartbeat: HeartbeatProducer,
}

impl Cia402Group {
    /// `nodes`: (node id 1-127, inverted) per wheel, in kinematics order.
    pub fn new(config: Cia402Config, nodes: &[(u8, bool)], feedback_timeout_ms: u64) -> Result<Self> {
        config.validate()?;
        if nodes.iter().any(|(n, _)| *n == config.host_node_id) {
            return Err(BaseError::config(
                "motors.cia402.host_node_id",
                format!("{} is also a wheel's node id", config.host_node_id),
            ));
        }
        let heartbeat = HeartbeatProducer::new(config.host_node_id, config.host_heartbeat_ms);
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
        Ok(Self { nodes: out, started: false, heartbeat })
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
        // First in the period's frames, and in every mode (a halted host is still alive): the
        // drives must hear it whatever else the tick sends.
        self.heartbeat.poll(now, out);
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

    /// Host heartbeats sent.
    pub fn heartbeats_sent(&self) -> u64 {
        self.heartbeat.sent
    }

    pub fn malformed(&self) -> u64 {
        self.nodes.iter().map(|n| n.malformed).sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use starc_time::Clock;

    #[test]
    fn the_host_heartbeat_leads_every_period_it_is_due_in_every_mode() -> Result<()> {
        let config = Cia402Config { host_node_id: 0x70, host_heartbeat_ms: 50, ..Cia402Config::default() };
        let mut g = Cia402Group::new(config, &[(1, false), (2, false)], 100)?;
        let mut faults = Vec::new();
        let mut beats = Vec::new();
        for (i, t) in (0..300u64).step_by(10).enumerate() {
            let mode = [DriveMode::Run, DriveMode::Brake, DriveMode::Halt][i % 3];
            let mut out = Vec::new();
            g.tick(Stamp::new(t * 1_000_000, Clock::Host), mode, &[1.0, 1.0], &mut out, &mut faults);
            if out.first().is_some_and(|f| f.to_string() == "770#05") {
                beats.push(t);
            }
            assert!(out.iter().skip(1).all(|f| f.id().raw() != 0x770), "one heartbeat per period");
        }
        assert_eq!(beats, vec![0, 50, 100, 150, 200, 250]);
        assert_eq!(g.heartbeats_sent(), 6);
        Ok(())
    }

    #[test]
    fn the_host_node_id_cannot_be_a_wheel() {
        let config = Cia402Config { host_node_id: 2, ..Cia402Config::default() };
        assert!(Cia402Group::new(config, &[(1, false), (2, false)], 100).is_err());
    }
}
