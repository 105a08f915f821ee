//! The transport trait: every CAN transport (SocketCAN, slcan on a serial port) sends frames and
//! hands back what it receives, time-stamped, so drivers never know which one they run on.

use crate::error::Result;
use crate::frame::CanFrame;
use crate::slcan::StatusFlags;
use starc_time::Stamp;
use std::future::Future;

/// A frame as received.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RxFrame {
    pub frame: CanFrame,
    /// Host realtime clock when the transport got it (the kernel's receive time on SocketCAN).
    pub host: Stamp,
    /// The adapter's own clock, when it stamps frames (slcan `Z1`; unwrapped, `Clock::Device`).
    pub device: Option<Stamp>,
}

/// What went wrong on the bus itself (as opposed to the host side of the transport).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case", tag = "kind")]
pub enum BusFault {
    /// An slcan adapter's `F` reply with bits set.
    SlcanFlags { flags: StatusFlags },
    /// The adapter answered BEL to a transmit request: the frame did not go out.
    TransmitRefused,
    /// A SocketCAN error frame: `class` is the `CAN_ERR_*` mask of the id, `data` the details.
    ErrorFrame { class: u32, data: [u8; 8] },
}

/// One thing received.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BusEvent {
    Frame(RxFrame),
    Fault { fault: BusFault, host: Stamp },
}

/// Counters every transport keeps.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct BusStats {
    pub frames_sent: u64,
    pub frames_received: u64,
    /// Received lines or frames that made no sense (garbage on a serial line, unknown replies).
    pub malformed: u64,
    pub faults: u64,
    /// Transmit acknowledgements (`z`/`Z`) from an slcan adapter.
    pub tx_acks: u64,
}

/// A CAN bus: send frames, receive frames and faults.
///
/// `recv` must be cancel-safe (it is used in `tokio::select!` next to timers); `send` need not be.
pub trait CanBus: Send {
    /// Queues one frame for transmission.
    fn send(&mut self, frame: &CanFrame) -> impl Future<Output = Result<()>> + Send;

    /// The next frame or bus fault.
    fn recv(&mut self) -> impl Future<Output = Result<BusEvent>> + Send;

    /// Asks the adapter for its error status where that must be polled (slcan `F`); the answer
    /// arrives through `recv` as a [`BusEvent::Fault`] when a bit is set. SocketCAN reports
    /// errors by itself, so the default does nothing.
    fn request_status(&mut self) -> impl Future<Output = Result<()>> + Send {
        std::future::ready(Ok(()))
    }

    fn stats(&self) -> BusStats;
}
