//! The port task: reads, decodes, forwards events, sends commands and matches MIP replies.

use crate::decoder::ImuDecoder;
use crate::error::{ImuError, Result};
use crate::mip::{MipCommand, MipReply};
use crate::sample::ImuEvent;
use crate::serial::handle::PortStats;
use crate::timing::LatencyModel;
use starc_time::Stamp;
use std::collections::VecDeque;
use std::time::Duration;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::sync::{mpsc, oneshot, watch};
use tokio::time::Instant;
use tokio_serial::{SerialPort, SerialStream};
use tracing::{debug, warn};

pub(crate) enum Request {
    /// Send a MIP command and wait for its ACK/NACK (with retries).
    Mip { command: MipCommand, reply: oneshot::Sender<Result<MipReply>> },
    /// Write raw bytes (WitMotion config writes).
    Write { bytes: Vec<u8>, reply: oneshot::Sender<Result<()>> },
    /// Change the local port's baud rate (and the latency model's).
    SetBaud { baud: u32, reply: oneshot::Sender<Result<()>> },
}

struct Pending {
    command: MipCommand,
    bytes: Vec<u8>,
    sends: u32,
    deadline: Instant,
    reply: oneshot::Sender<Result<MipReply>>,
}

pub(crate) struct Task {
    pub port: SerialStream,
    pub name: String,
    pub decoder: ImuDecoder,
    pub latency: LatencyModel,
    pub events: mpsc::Sender<ImuEvent>,
    pub requests: mpsc::Receiver<Request>,
    pub stats: watch::Sender<PortStats>,
    pub command_timeout: Duration,
    pub command_tries: u32,
}

impl Task {
    pub async fn run(mut self) -> Result<()> {
        let mut buf = vec![0u8; 4096];
        let mut out: Vec<ImuEvent> = Vec::with_capacity(64);
        let mut pending: Option<Pending> = None;
        let mut queue: VecDeque<(MipCommand, oneshot::Sender<Result<MipReply>>)> = VecDeque::new();
        let mut stats = PortStats::default();
        let mut last_publish = Instant::now();
        // Counters go out at least this often, also when nothing arrives.
        let mut publish = tokio::time::interval(Duration::from_millis(50));
        loop {
            if pending.is_none() {
                if let Some((command, reply)) = queue.pop_front() {
                    pending = self.send_command(command, reply, &mut stats).await;
                }
            }
            let deadline = pending.as_ref().map(|p| p.deadline);
            tokio::select! {
                read = self.port.read(&mut buf) => {
                    let n = match read {
                        Ok(0) => return Err(ImuError::io(format!("reading {}", self.name), std::io::ErrorKind::UnexpectedEof.into())),
                        Ok(n) => n,
                        Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
                        Err(e) => return Err(ImuError::io(format!("reading {}", self.name), e)),
                    };
                    let now = Stamp::host_now();
                    self.decoder.push(buf.get(..n).unwrap_or_default(), now, &mut out);
                    for event in out.drain(..) {
                        if let ImuEvent::MipReply(r) = &event {
                            if pending.as_ref().is_some_and(|p| r.answers(&p.command)) {
                                if let Some(p) = pending.take() {
                                    debug!(port = %self.name, command = p.command.name(), code = r.code, "MIP reply");
                                    let _ = p.reply.send(Ok(r.clone()));
                                }
                            }
                        }
                        if self.events.try_send(event).is_err() {
                            stats.events_dropped += 1;
                        }
                    }
                }
                request = self.requests.recv() => match request {
                    None => return Ok(()),
                    Some(Request::Mip { command, reply }) => queue.push_back((command, reply)),
                    Some(Request::Write { bytes, reply }) => {
                        let r = self.write(&bytes, &mut stats).await;
                        let _ = reply.send(r);
                    }
                    Some(Request::SetBaud { baud, reply }) => {
                        let r = self.port.set_baud_rate(baud).map_err(|source| ImuError::Serial { port: self.name.clone(), source });
                        if r.is_ok() {
                            self.latency.baud = baud;
                            self.decoder.timestamper_mut().set_latency(self.latency);
                        }
                        let _ = reply.send(r);
                    }
                },
                _ = publish.tick() => {
                    stats.decoder = self.decoder.stats();
                    self.stats.send_replace(stats);
                    last_publish = Instant::now();
                }
                _ = sleep_until(deadline) => {
                    if let Some(p) = pending.take() {
                        pending = self.retry(p, &mut stats).await;
                    }
                }
            }
            stats.decoder = self.decoder.stats();
            if last_publish.elapsed() >= Duration::from_millis(20) {
                self.stats.send_replace(stats);
                last_publish = Instant::now();
            }
        }
    }

    async fn write(&mut self, bytes: &[u8], stats: &mut PortStats) -> Result<()> {
        // No flush: on a tty it is tcdrain, which would block the runtime until sent.
        self.port.write_all(bytes).await.map_err(|e| ImuError::io(format!("writing {}", self.name), e))?;
        stats.bytes_written += bytes.len() as u64;
        Ok(())
    }

    async fn send_command(
        &mut self,
        command: MipCommand,
        reply: oneshot::Sender<Result<MipReply>>,
        stats: &mut PortStats,
    ) -> Option<Pending> {
        let bytes = match command.to_bytes() {
            Ok(b) => b,
            Err(e) => {
                let _ = reply.send(Err(e));
                return None;
            }
        };
        if let Err(e) = self.write(&bytes, stats).await {
            let _ = reply.send(Err(e));
            return None;
        }
        stats.commands_sent += 1;
        Some(Pending { command, bytes, sends: 1, deadline: Instant::now() + self.command_timeout, reply })
    }

    async fn retry(&mut self, mut p: Pending, stats: &mut PortStats) -> Option<Pending> {
        if p.sends >= self.command_tries {
            stats.command_timeouts += 1;
            warn!(port = %self.name, command = p.command.name(), sends = p.sends, "no MIP reply");
            let what = format!("MIP {} on {}", p.command.name(), self.name);
            let _ = p.reply.send(Err(ImuError::Timeout { what, tries: p.sends }));
            return None;
        }
        let bytes = std::mem::take(&mut p.bytes);
        if let Err(e) = self.write(&bytes, stats).await {
            let _ = p.reply.send(Err(e));
            return None;
        }
        p.bytes = bytes;
        p.sends += 1;
        stats.command_retries += 1;
        p.deadline = Instant::now() + self.command_timeout;
        Some(p)
    }
}

async fn sleep_until(deadline: Option<Instant>) {
    match deadline {
        Some(d) => tokio::time::sleep_until(d).await,
        None => std::future::pending().await,
    }
}
