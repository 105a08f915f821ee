//! Either transport behind one type, for programs that pick it from a config file.

use crate::bus::{BusEvent, BusStats, CanBus};
use crate::error::Result;
use crate::frame::CanFrame;
use crate::slcan::SlcanSerial;
use crate::socketcan::SocketCanBus;

pub enum AnyBus {
    SocketCan(SocketCanBus),
    Slcan(SlcanSerial),
}

impl CanBus for AnyBus {
    async fn send(&mut self, frame: &CanFrame) -> Result<()> {
        match self {
            Self::SocketCan(b) => b.send(frame).await,
            Self::Slcan(b) => b.send(frame).await,
        }
    }

    async fn recv(&mut self) -> Result<BusEvent> {
        match self {
            Self::SocketCan(b) => b.recv().await,
            Self::Slcan(b) => b.recv().await,
        }
    }

    async fn request_status(&mut self) -> Result<()> {
        match self {
            Self::SocketCan(b) => b.request_status().await,
            Self::Slcan(b) => b.request_status().await,
        }
    }

    fn stats(&self) -> BusStats {
        match self {
            Self::SocketCan(b) => b.stats(),
            Self::Slcan(b) => b.stats(),
        }
    }
}
