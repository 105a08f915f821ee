//! SocketCAN: the production transport (candleLight/gs_usb adapters, slcand-attached serial
//! adapters, on-board controllers). Receive times are the kernel's (`SO_TIMESTAMPNS`); error
//! frames are switched on and arrive as [`BusFault::ErrorFrame`].

use crate::bus::{BusEvent, BusFault, BusStats, CanBus, RxFrame};
use crate::error::{CanError, Result};
use crate::frame::{CanFrame, CanId};
use socketcan::{EmbeddedFrame, ExtendedId, Id, SocketOptions, StandardId};
use starc_time::{Clock, Stamp};
use std::time::{SystemTime, UNIX_EPOCH};

/// A raw CAN socket bound to one interface (`can0`).
pub struct SocketCanBus {
    socket: socketcan::tokio::CanSocket,
    interface: String,
    stats: BusStats,
}

impl SocketCanBus {
    /// Opens `interface`; fails cleanly when the interface or AF_CAN itself is missing.
    pub fn open(interface: &str) -> Result<Self> {
        let context = || format!("opening CAN interface {interface}");
        let socket = socketcan::tokio::CanSocket::open(interface).map_err(|e| CanError::io(context(), e))?;
        socket.set_recv_timestamp(true).map_err(|e| CanError::io(context(), e))?;
        socket.set_error_filter_accept_all().map_err(|e| CanError::io(context(), e))?;
        Ok(Self { socket, interface: interface.to_string(), stats: BusStats::default() })
    }

    pub fn interface(&self) -> &str {
        &self.interface
    }
}

fn to_socketcan(frame: &CanFrame) -> Option<socketcan::CanFrame> {
    let id: Id = match frame.id() {
        CanId::Standard(id) => StandardId::new(id)?.into(),
        CanId::Extended(id) => ExtendedId::new(id)?.into(),
    };
    if frame.is_remote() {
        socketcan::CanFrame::new_remote(id, usize::from(frame.dlc()))
    } else {
        socketcan::CanFrame::new(id, frame.data())
    }
}

fn from_id(id: Id) -> Result<CanId> {
    match id {
        Id::Standard(s) => CanId::standard(s.as_raw()),
        Id::Extended(e) => CanId::extended(e.as_raw()),
    }
}

fn stamp(time: SystemTime) -> Stamp {
    let ns = time.duration_since(UNIX_EPOCH).map(|d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX)).unwrap_or(0);
    Stamp::new(ns, Clock::Host)
}

impl CanBus for SocketCanBus {
    async fn send(&mut self, frame: &CanFrame) -> Result<()> {
        let out = to_socketcan(frame).ok_or(CanError::TooMuchData { len: frame.data().len() })?;
        self.socket.write_frame(out).await.map_err(|e| CanError::io(format!("sending on {}", self.interface), e))?;
        self.stats.frames_sent += 1;
        Ok(())
    }

    async fn recv(&mut self) -> Result<BusEvent> {
        loop {
            let (frame, time) = self
                .socket
                .read_frame_with_timestamp()
                .await
                .map_err(|e| CanError::io(format!("receiving on {}", self.interface), e))?;
            let host = stamp(time);
            let ours = match &frame {
                socketcan::CanFrame::Error(err) => {
                    self.stats.faults += 1;
                    let mut data = [0u8; 8];
                    for (slot, b) in data.iter_mut().zip(err.data()) {
                        *slot = *b;
                    }
                    let fault = BusFault::ErrorFrame { class: err.error_bits(), data };
                    return Ok(BusEvent::Fault { fault, host });
                }
                socketcan::CanFrame::Remote(r) => {
                    from_id(r.id()).and_then(|id| CanFrame::remote(id, r.dlc().min(8) as u8))
                }
                socketcan::CanFrame::Data(d) => from_id(d.id()).and_then(|id| CanFrame::new(id, d.data())),
            };
            match ours {
                Ok(frame) => {
                    self.stats.frames_received += 1;
                    return Ok(BusEvent::Frame(RxFrame { frame, host, device: None }));
                }
                Err(e) => {
                    self.stats.malformed += 1;
                    tracing::debug!("{}: dropped {e}", self.interface);
                }
            }
        }
    }

    fn stats(&self) -> BusStats {
        self.stats
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test]
    async fn a_missing_interface_is_a_clean_error() {
        // This machine and CI have no AF_CAN at all; a real robot without can7 fails the same way.
        match SocketCanBus::open("can7") {
            Err(CanError::Io { context, .. }) => assert!(context.contains("can7")),
            Err(other) => panic!("unexpected error {other}"),
            Ok(_) => panic!("can7 exists here?"),
        }
    }

    #[test]
    fn frames_convert_both_ways() -> Result<()> {
        let ours = CanFrame::standard(0x1FF, &[1, 2, 3])?;
        let theirs = to_socketcan(&ours).ok_or(CanError::Closed)?;
        assert_eq!(from_id(theirs.id())?, ours.id());
        assert_eq!(theirs.data(), ours.data());
        let rtr = CanFrame::remote(CanId::extended(0x18FF_0001)?, 2)?;
        let theirs = to_socketcan(&rtr).ok_or(CanError::Closed)?;
        assert!(theirs.is_remote_frame());
        assert_eq!(from_id(theirs.id())?, rtr.id());
        Ok(())
    }
}
