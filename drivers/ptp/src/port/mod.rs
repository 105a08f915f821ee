//! The port state machines, sans-IO: datagrams, timestamps and timer expiries in, [`Action`]s out.
//! Time is plain u64 nanoseconds on the port's local timescale (CLOCK_REALTIME for software
//! timestamps); the transport supplies it.

mod actions;
pub mod bmca;
mod master;
mod slave;

pub use actions::{log_interval, Action, Timer, TxTag};
pub use master::{Master, MasterStats};
pub use slave::{Slave, SlaveSample, SlaveState, SlaveStats};

/// Either role, behind one interface for the transport. One exists per process, so the size
/// difference between the variants costs nothing worth a box.
#[allow(clippy::large_enum_variant)]
pub enum Port {
    Master(Master),
    Slave(Slave),
}

impl Port {
    pub fn start(&mut self) -> Vec<Action> {
        match self {
            Port::Master(m) => m.start(),
            Port::Slave(s) => s.start(),
        }
    }

    /// A datagram that arrived on the event port (319), with its receive timestamp.
    pub fn handle_event(&mut self, bytes: &[u8], rx_ns: u64) -> Vec<Action> {
        match self {
            Port::Master(m) => m.handle_event(bytes, rx_ns),
            Port::Slave(s) => s.handle_event(bytes, rx_ns),
        }
    }

    /// A datagram that arrived on the general port (320).
    pub fn handle_general(&mut self, bytes: &[u8], rx_ns: u64) -> Vec<Action> {
        match self {
            Port::Master(m) => m.handle_general(bytes, rx_ns),
            Port::Slave(s) => s.handle_general(bytes, rx_ns),
        }
    }

    pub fn handle_timer(&mut self, timer: Timer, now_ns: u64) -> Vec<Action> {
        match self {
            Port::Master(m) => m.handle_timer(timer, now_ns),
            Port::Slave(s) => s.handle_timer(timer, now_ns),
        }
    }

    pub fn handle_tx_timestamp(&mut self, tag: TxTag, tx_ns: u64) -> Vec<Action> {
        match self {
            Port::Master(m) => m.handle_tx_timestamp(tag, tx_ns),
            Port::Slave(s) => s.handle_tx_timestamp(tag, tx_ns),
        }
    }
}

#[cfg(test)]
mod tests;
