//! What a port asks its transport to do.

use std::time::Duration;

/// The timers a port arms; the transport calls `handle_timer` when one expires.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Timer {
    /// Master: send the next Announce.
    Announce,
    /// Master: send the next Sync.
    Sync,
    /// Slave: send the next Delay_Req.
    DelayReq,
    /// Slave: the selected master has gone quiet.
    AnnounceReceipt,
}

/// Which event message a transmit timestamp belongs to.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum TxTag {
    Sync { sequence_id: u16 },
    DelayReq { sequence_id: u16 },
}

/// One thing for the transport to do.
#[derive(Clone, Debug, PartialEq)]
pub enum Action {
    /// Send on the event port (319); report the transmit timestamp with `handle_tx_timestamp`.
    SendEvent { data: Vec<u8>, tag: TxTag },
    /// Send on the general port (320).
    SendGeneral { data: Vec<u8> },
    /// Call `handle_timer(timer, ..)` after `after` (replaces an armed timer of the same kind).
    ArmTimer { timer: Timer, after: Duration },
    /// Slave with `adjust_clock` only: step the local clock by `offset_ns`.
    StepClock { offset_ns: i64 },
    /// Slave with `adjust_clock` only: run the local clock `ppb` faster than nominal (absolute,
    /// not cumulative).
    SetFrequency { ppb: f64 },
}

/// 2^log_interval seconds, as PTP's logMessageInterval fields spell intervals.
pub fn log_interval(log2_s: i8) -> Duration {
    let clamped = log2_s.clamp(-10, 10) as i32;
    Duration::from_secs_f64(2f64.powi(clamped))
}
