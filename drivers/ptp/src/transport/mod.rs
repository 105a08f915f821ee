//! UDP/IPv4 transport with kernel timestamps: the only part of the crate that touches sockets
//! (and, behind an explicit option, a clock).

mod adjust;
mod iface;
mod run;
mod socket;
mod timestamping;

pub use adjust::{AdjustTarget, ClockAdjuster};
pub use iface::Interface;
pub use run::{run_port, TransportStats};
pub use socket::{PtpSockets, TransportConfig};
pub use timestamping::{realtime_ns, KernelStamps, TimestampMode};
