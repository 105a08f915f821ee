//! slcan on a byte stream: a USB-serial adapter (CANable, Lawicel CANUSB...) through
//! tokio-serial, or any other stream (a pty) for tests.

use crate::bus::{BusEvent, BusStats, CanBus};
use crate::error::{CanError, Result};
use crate::frame::CanFrame;
use crate::slcan::bitrate;
use crate::slcan::codec::{Command, Reply};
use crate::slcan::host::{HostItem, SlcanHost};
use serde::{Deserialize, Serialize};
use starc_time::Stamp;
use std::collections::VecDeque;
use std::time::Duration;
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};

/// How to open an slcan adapter.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SlcanOptions {
    /// CAN bitrate in bit/s, one of [`bitrate::BITRATES`].
    pub bitrate: u32,
    /// Open with `L` (receive only, no ACKs on the bus) instead of `O`.
    pub listen_only: bool,
    /// Ask for `Z1` millisecond stamps on received frames.
    pub timestamps: bool,
    /// How long to wait for each reply while opening.
    pub reply_timeout_ms: u64,
    /// Wait for CR/BEL after each opening command. Off only when the other end is a host
    /// program rather than an adapter (python-can on a pty pair answers nothing).
    pub expect_replies: bool,
    /// Serial line speed; USB CDC adapters ignore it.
    pub serial_baud: u32,
}

impl Default for SlcanOptions {
    fn default() -> Self {
        Self {
            bitrate: 1_000_000,
            listen_only: false,
            timestamps: false,
            reply_timeout_ms: 500,
            expect_replies: true,
            serial_baud: 115_200,
        }
    }
}

/// An slcan adapter on a byte stream.
pub struct SlcanBus<S> {
    io: S,
    host: SlcanHost,
    queue: VecDeque<HostItem>,
    buf: Vec<u8>,
}

/// The serial-port flavour, the production path for slcan adapters.
pub type SlcanSerial = SlcanBus<tokio_serial::SerialStream>;

impl SlcanSerial {
    /// Opens the serial device at `path` and the CAN channel behind it.
    pub async fn open_serial(path: &str, options: &SlcanOptions) -> Result<Self> {
        use tokio_serial::SerialPortBuilderExt;
        let io = tokio_serial::new(path, options.serial_baud)
            .open_native_async()
            .map_err(|e| CanError::io(format!("opening {path}"), std::io::Error::other(e)))?;
        SlcanBus::open(io, options).await
    }
}

impl<S: AsyncRead + AsyncWrite + Unpin + Send> SlcanBus<S> {
    /// Takes an open byte stream to an adapter: flushes it, sets the bitrate, opens the channel.
    pub async fn open(io: S, options: &SlcanOptions) -> Result<Self> {
        let code = bitrate::code_for(options.bitrate)?;
        let mut bus = Self { io, host: SlcanHost::new(), queue: VecDeque::new(), buf: vec![0; 4096] };
        // Three CRs end whatever half command the adapter holds; then it must be closed to take
        // a bitrate (closing a closed adapter is refused with BEL, which we ignore).
        bus.write(&[b'\r'; 3]).await?;
        bus.drain(Duration::from_millis(30)).await?;
        bus.write(&Command::Close.to_bytes()).await?;
        bus.drain(Duration::from_millis(30)).await?;
        let mut opening = vec![Command::Bitrate(code)];
        if options.timestamps {
            opening.push(Command::Timestamps(true));
        }
        opening.push(if options.listen_only { Command::ListenOnly } else { Command::Open });
        for command in opening {
            bus.write(&command.to_bytes()).await?;
            if options.expect_replies {
                bus.expect_ok(command, options.reply_timeout_ms).await?;
            }
        }
        bus.host.set_open(true);
        tracing::debug!(bitrate = options.bitrate, "slcan: channel open");
        Ok(bus)
    }

    async fn write(&mut self, bytes: &[u8]) -> Result<()> {
        self.io.write_all(bytes).await.map_err(|e| CanError::io("slcan write", e))?;
        self.io.flush().await.map_err(|e| CanError::io("slcan flush", e))
    }

    /// Reads and drops whatever arrives for `duration` (replies to the flush, frames left over
    /// from an earlier session), however busy the line is.
    async fn drain(&mut self, duration: Duration) -> Result<()> {
        let deadline = tokio::time::Instant::now() + duration;
        while let Ok(read) = tokio::time::timeout_at(deadline, self.io.read(&mut self.buf)).await {
            let n = read.map_err(|e| CanError::io("slcan read", e))?;
            if n == 0 {
                return Err(CanError::Closed);
            }
            self.take(n);
        }
        self.queue.clear();
        Ok(())
    }

    fn take(&mut self, n: usize) {
        let now = Stamp::host_now();
        let bytes = self.buf.get(..n).unwrap_or(&[]);
        self.host.receive(bytes, now, &mut self.queue);
    }

    async fn expect_ok(&mut self, command: Command, timeout_ms: u64) -> Result<()> {
        let text = String::from_utf8_lossy(&command.to_bytes()).trim_end().to_string();
        let deadline = tokio::time::Instant::now() + Duration::from_millis(timeout_ms);
        loop {
            let reply = self.queue.iter().position(|i| matches!(i, HostItem::Reply(_)));
            if let Some(at) = reply {
                match self.queue.remove(at) {
                    Some(HostItem::Reply(Reply::Ok)) => return Ok(()),
                    Some(HostItem::Reply(Reply::Error)) => return Err(CanError::Refused { command: text }),
                    _ => continue,
                }
            }
            match tokio::time::timeout_at(deadline, self.io.read(&mut self.buf)).await {
                Err(_) => return Err(CanError::NoReply { command: text, timeout_ms }),
                Ok(Err(e)) => return Err(CanError::io("slcan read", e)),
                Ok(Ok(0)) => return Err(CanError::Closed),
                Ok(Ok(n)) => self.take(n),
            }
        }
    }

    /// Closes the channel (`C`); the adapter stays configured.
    pub async fn close(mut self) -> Result<S> {
        self.host.set_open(false);
        self.write(&Command::Close.to_bytes()).await?;
        Ok(self.io)
    }
}

impl<S: AsyncRead + AsyncWrite + Unpin + Send> CanBus for SlcanBus<S> {
    async fn send(&mut self, frame: &CanFrame) -> Result<()> {
        self.write(&Command::Transmit(*frame).to_bytes()).await?;
        self.host.count_sent();
        Ok(())
    }

    async fn recv(&mut self) -> Result<BusEvent> {
        loop {
            while let Some(item) = self.queue.pop_front() {
                if let HostItem::Event(e) = item {
                    return Ok(e);
                }
            }
            // Cancel-safe: a read either completes (and its bytes are decoded right here,
            // before the next await) or reads nothing.
            let n = self.io.read(&mut self.buf).await.map_err(|e| CanError::io("slcan read", e))?;
            if n == 0 {
                return Err(CanError::Closed);
            }
            self.take(n);
        }
    }

    async fn request_status(&mut self) -> Result<()> {
        self.write(&Command::Status.to_bytes()).await
    }

    fn stats(&self) -> BusStats {
        self.host.stats()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bus::BusFault;
    use crate::slcan::lines::{Line, LineSplitter};

    /// A scripted adapter on the far end of an in-memory pipe.
    async fn adapter(mut io: tokio::io::DuplexStream, refuse_open: bool) -> Vec<Command> {
        let mut seen = Vec::new();
        let mut splitter = LineSplitter::new();
        let mut lines = Vec::new();
        let mut buf = [0u8; 256];
        while let Ok(n) = io.read(&mut buf).await {
            if n == 0 {
                break;
            }
            splitter.push(buf.get(..n).unwrap_or(&[]), &mut lines);
            for line in lines.drain(..) {
                let Line::Text(text) = line else { continue };
                let Ok(cmd) = Command::decode(&text) else { continue };
                seen.push(cmd);
                let reply: &[u8] = match cmd {
                    Command::Open if refuse_open => b"\x07",
                    Command::Transmit(_) => b"z\r",
                    Command::Status => b"F80\r",
                    _ => b"\r",
                };
                if io.write_all(reply).await.is_err() {
                    return seen;
                }
                if matches!(cmd, Command::Open) && !refuse_open {
                    let _ = io.write_all(b"t5813600102\r").await;
                }
            }
        }
        seen
    }

    #[tokio::test]
    async fn opens_sends_receives_and_polls_status() -> Result<()> {
        let (ours, theirs) = tokio::io::duplex(4096);
        let far = tokio::spawn(adapter(theirs, false));
        let options = SlcanOptions { bitrate: 500_000, timestamps: true, ..SlcanOptions::default() };
        let mut bus = SlcanBus::open(ours, &options).await?;
        match bus.recv().await? {
            BusEvent::Frame(rx) => assert_eq!(rx.frame.to_string(), "581#600102"),
            other => panic!("{other:?}"),
        }
        bus.send(&CanFrame::standard(0x601, &[0x40, 0x41, 0x60, 0, 0, 0, 0, 0])?).await?;
        bus.request_status().await?;
        match bus.recv().await? {
            BusEvent::Fault { fault: BusFault::SlcanFlags { flags }, .. } => assert_eq!(flags.0, 0x80),
            other => panic!("{other:?}"),
        }
        assert_eq!(bus.stats().tx_acks, 1);
        drop(bus.close().await?);
        let seen = far.await.map_err(|e| CanError::io("join", std::io::Error::other(e)))?;
        let after_flush: Vec<Command> = seen.into_iter().filter(|c| *c != Command::Empty).collect();
        assert_eq!(
            after_flush.get(..4),
            Some(&[Command::Close, Command::Bitrate(6), Command::Timestamps(true), Command::Open][..])
        );
        Ok(())
    }

    #[tokio::test]
    async fn a_refused_open_is_an_error() {
        let (ours, theirs) = tokio::io::duplex(4096);
        let _far = tokio::spawn(adapter(theirs, true));
        let r = SlcanBus::open(ours, &SlcanOptions::default()).await;
        assert!(matches!(r, Err(CanError::Refused { ref command }) if command == "O"), "{:?}", r.err());
    }

    #[tokio::test]
    async fn silence_is_an_error_unless_no_replies_are_expected() -> Result<()> {
        let (ours, _theirs) = tokio::io::duplex(4096);
        let options = SlcanOptions { reply_timeout_ms: 50, ..SlcanOptions::default() };
        assert!(matches!(SlcanBus::open(ours, &options).await, Err(CanError::NoReply { .. })));
        let (ours, _theirs) = tokio::io::duplex(4096);
        let quiet = SlcanOptions { expect_replies: false, ..options };
        SlcanBus::open(ours, &quiet).await?;
        Ok(())
    }

    #[test]
    fn unsupported_bitrate_is_refused_before_any_io() {
        let rt = tokio::runtime::Builder::new_current_thread().enable_all().build();
        let Ok(rt) = rt else { return };
        let (ours, _theirs) = tokio::io::duplex(64);
        let r = rt.block_on(SlcanBus::open(ours, &SlcanOptions { bitrate: 750_000, ..SlcanOptions::default() }));
        assert!(matches!(r, Err(CanError::UnsupportedBitrate(750_000))));
    }
}
