//! The host side of slcan, sans-IO: adapter bytes and their receive time in, frames, faults and
//! command replies out.

use crate::bus::{BusEvent, BusFault, BusStats, RxFrame};
use crate::slcan::codec::Reply;
use crate::slcan::lines::{Line, LineSplitter};
use crate::slcan::timestamp::StampUnwrapper;
use starc_time::Stamp;
use std::collections::VecDeque;

/// One decoded item of the adapter's stream.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum HostItem {
    /// A frame or a fault, for the driver.
    Event(BusEvent),
    /// The answer to a command (ok, error, version...), for whoever waits for it.
    Reply(Reply),
}

/// Decodes what an adapter sends.
#[derive(Debug, Default)]
pub struct SlcanHost {
    splitter: LineSplitter,
    unwrapper: StampUnwrapper,
    lines: Vec<Line>,
    /// After `O`: a BEL is a refused transmit, CR and `z`/`Z` are transmit acks.
    open: bool,
    stats: BusStats,
}

impl SlcanHost {
    pub fn new() -> Self {
        Self::default()
    }

    /// From now on replies are taken as answers to transmits.
    pub fn set_open(&mut self, open: bool) {
        self.open = open;
    }

    pub fn stats(&self) -> BusStats {
        self.stats
    }

    pub fn count_sent(&mut self) {
        self.stats.frames_sent += 1;
    }

    /// Feeds bytes received at `host`; decoded items are appended to `out`.
    pub fn receive(&mut self, bytes: &[u8], host: Stamp, out: &mut VecDeque<HostItem>) {
        self.splitter.push(bytes, &mut self.lines);
        for line in self.lines.drain(..) {
            let reply = match Reply::decode(&line) {
                Ok(r) => r,
                Err(e) => {
                    self.stats.malformed += 1;
                    tracing::debug!("slcan: dropped {e}");
                    continue;
                }
            };
            match reply {
                Reply::Frame { frame, stamp_ms } => {
                    self.stats.frames_received += 1;
                    let device = stamp_ms.map(|ms| self.unwrapper.unwrap(ms));
                    out.push_back(HostItem::Event(BusEvent::Frame(RxFrame { frame, host, device })));
                }
                Reply::Status(flags) => {
                    if !flags.is_clear() {
                        self.stats.faults += 1;
                        out.push_back(HostItem::Event(BusEvent::Fault { fault: BusFault::SlcanFlags { flags }, host }));
                    }
                    out.push_back(HostItem::Reply(reply));
                }
                Reply::Error if self.open => {
                    self.stats.faults += 1;
                    out.push_back(HostItem::Event(BusEvent::Fault { fault: BusFault::TransmitRefused, host }));
                }
                Reply::TxAck { .. } | Reply::Ok if self.open => self.stats.tx_acks += 1,
                other => out.push_back(HostItem::Reply(other)),
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::slcan::StatusFlags;
    use starc_time::Clock;

    #[test]
    fn frames_faults_and_garbage() {
        let mut h = SlcanHost::new();
        let mut out = VecDeque::new();
        let t = Stamp::new(5, Clock::Host);
        h.receive(b"\r", t, &mut out);
        assert_eq!(out.pop_front(), Some(HostItem::Reply(Reply::Ok)));
        h.set_open(true);
        h.receive(b"z\r\x07t2012ABCD0010\r\xff\xfeq\rF84\rF00\r", t, &mut out);
        let kinds: Vec<HostItem> = out.drain(..).collect();
        assert!(matches!(
            kinds.first(),
            Some(HostItem::Event(BusEvent::Fault { fault: BusFault::TransmitRefused, .. }))
        ));
        match kinds.get(1) {
            Some(HostItem::Event(BusEvent::Frame(rx))) => {
                assert_eq!(rx.frame.data(), &[0xAB, 0xCD]);
                assert_eq!(rx.device.map(|d| d.ns), Some(16_000_000));
                assert_eq!(rx.host, t);
            }
            other => panic!("{other:?}"),
        }
        assert!(matches!(
            kinds.get(2),
            Some(HostItem::Event(BusEvent::Fault { fault: BusFault::SlcanFlags { flags: StatusFlags(0x84) }, .. }))
        ));
        assert_eq!(kinds.len(), 5, "{kinds:?}");
        let s = h.stats();
        assert_eq!((s.tx_acks, s.frames_received, s.malformed, s.faults), (1, 1, 1, 2));
    }
}
