//! The slcan adapter a mock plays, sans-IO: host bytes in, replies and bus frames out; bus
//! frames in, lines for the host out (only while the channel is open).

use starc_can::slcan::{bitrate, Command, Line, LineSplitter, Reply, StatusFlags};
use starc_can::CanFrame;

/// Counters of the adapter.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct AdapterStats {
    pub commands: u64,
    pub refused: u64,
    pub frames_from_host: u64,
    pub frames_to_host: u64,
}

#[derive(Debug)]
pub struct SlcanAdapter {
    splitter: LineSplitter,
    lines: Vec<Line>,
    open: bool,
    listen_only: bool,
    bitrate: Option<u32>,
    timestamps: bool,
    /// Bits the next `F` reports (a real adapter clears them on read; ours keep what the
    /// fault injector sets).
    pub flags: StatusFlags,
    pub stats: AdapterStats,
}

impl Default for SlcanAdapter {
    fn default() -> Self {
        Self::new()
    }
}

impl SlcanAdapter {
    pub fn new() -> Self {
        Self {
            splitter: LineSplitter::new(),
            lines: Vec::new(),
            open: false,
            listen_only: false,
            bitrate: None,
            timestamps: false,
            flags: StatusFlags::default(),
            stats: AdapterStats::default(),
        }
    }

    pub fn is_open(&self) -> bool {
        self.open
    }

    pub fn bitrate(&self) -> Option<u32> {
        self.bitrate
    }

    /// Bytes from the host; replies go to `to_host`, transmitted frames to `to_bus`.
    pub fn on_host_bytes(&mut self, bytes: &[u8], to_host: &mut Vec<u8>, to_bus: &mut Vec<CanFrame>) {
        self.splitter.push(bytes, &mut self.lines);
        let lines: Vec<Line> = self.lines.drain(..).collect();
        for line in lines {
            let reply = match line {
                Line::Text(text) => match Command::decode(&text) {
                    Ok(cmd) => self.execute(cmd, to_bus),
                    Err(e) => {
                        tracing::debug!("mock slcan adapter: {e}");
                        Reply::Error
                    }
                },
                Line::Bell | Line::Overlong => Reply::Error,
            };
            if reply == Reply::Error {
                self.stats.refused += 1;
            }
            reply.encode(to_host);
        }
    }

    fn execute(&mut self, cmd: Command, to_bus: &mut Vec<CanFrame>) -> Reply {
        self.stats.commands += 1;
        match cmd {
            Command::Empty => Reply::Ok,
            Command::Bitrate(code) if !self.open => {
                self.bitrate = bitrate::bitrate_of(code);
                Reply::Ok
            }
            Command::Open | Command::ListenOnly if !self.open && self.bitrate.is_some() => {
                self.open = true;
                self.listen_only = cmd == Command::ListenOnly;
                Reply::Ok
            }
            Command::Close if self.open => {
                self.open = false;
                Reply::Ok
            }
            Command::Transmit(frame) if self.open && !self.listen_only => {
                self.stats.frames_from_host += 1;
                to_bus.push(frame);
                Reply::TxAck { extended: frame.id().is_extended() }
            }
            Command::Status if self.open => Reply::Status(self.flags),
            Command::Version => Reply::Version { hardware: 0x10, software: 0x01 },
            Command::SerialNumber => Reply::SerialNumber(*b"STRC"),
            Command::Timestamps(on) if !self.open => {
                self.timestamps = on;
                Reply::Ok
            }
            _ => Reply::Error,
        }
    }

    /// A frame from the bus at device time `now_ms`; appended for the host when open.
    pub fn to_host(&mut self, frame: &CanFrame, now_ms: u64, to_host: &mut Vec<u8>) -> bool {
        if !self.open {
            return false;
        }
        let stamp_ms = self.timestamps.then_some((now_ms % 60_000) as u16);
        Reply::Frame { frame: *frame, stamp_ms }.encode(to_host);
        self.stats.frames_to_host += 1;
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn opens_like_a_lawicel_adapter() {
        let mut a = SlcanAdapter::new();
        let (mut host, mut bus) = (Vec::new(), Vec::new());
        a.on_host_bytes(b"O\rS8\rZ1\rO\rO\rt2008000102030405060700\r", &mut host, &mut bus);
        // O before a bitrate: BEL; S8 ok; Z1 ok; O ok; second O: BEL; transmit: z.
        assert_eq!(host, b"\x07\r\r\r\x07\x07");
        assert_eq!(a.bitrate(), Some(1_000_000));
        assert!(a.is_open());
        assert_eq!(a.stats.refused, 3, "O before S8, a second O, a frame longer than its DLC");
        assert!(bus.is_empty());
        host.clear();
        a.on_host_bytes(b"t200401020304\rF\r", &mut host, &mut bus);
        assert_eq!(host, b"z\rF00\r");
        assert_eq!(bus.len(), 1);
        host.clear();
        let f = CanFrame::standard(0x201, &[1, 2]).unwrap_or_else(|e| panic!("{e}"));
        assert!(a.to_host(&f, 61_234, &mut host));
        assert_eq!(host, b"t2012010204D2\r");
    }
}
