//! Opening a port and talking to the device through its task.

use crate::config::ImuConfig;
use crate::decoder::ImuDecoder;
use crate::error::{ImuError, Result};
use crate::mip::data::{FIELD_ACCEL, FIELD_GYRO};
use crate::mip::{FormatEntry, Function, MipCommand, MipReply, ReplyData};
use crate::sample::{ImuEvent, Protocol};
use crate::serial::task::{Request, Task};
use crate::stats::DecoderStats;
use crate::timing::Timestamper;
use crate::witmotion::ConfigWrite;
use serde::Serialize;
use std::sync::Arc;
use std::time::Duration;
use tokio::sync::{mpsc, oneshot, watch};
use tokio::task::JoinHandle;
use tokio::time::Instant;
use tokio_serial::{SerialPortBuilderExt, SerialStream};

/// Counters of a port: its decoder's and the transport's.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct PortStats {
    pub decoder: DecoderStats,
    pub bytes_written: u64,
    pub commands_sent: u64,
    pub command_retries: u64,
    pub command_timeouts: u64,
    /// Events the consumer was too slow for.
    pub events_dropped: u64,
}

/// Opens serial IMUs.
pub struct ImuPort;

impl ImuPort {
    /// Opens `config.port` at `config.baud` (8N1, no flow control) and starts its task; must be
    /// called inside a tokio runtime. Does not configure the device: see [`ImuHandle::configure`].
    pub fn open(config: &ImuConfig) -> Result<(ImuHandle, mpsc::Receiver<ImuEvent>)> {
        config.validate()?;
        let port = tokio_serial::new(&config.port, config.baud)
            .timeout(Duration::from_millis(100))
            .open_native_async()
            .map_err(|source| ImuError::Serial { port: config.port.clone(), source })?;
        Self::from_stream(port, config)
    }

    /// Runs the task on a port opened elsewhere (e.g. the master side of a pty); `config.port`
    /// only names it.
    pub fn from_stream(port: SerialStream, config: &ImuConfig) -> Result<(ImuHandle, mpsc::Receiver<ImuEvent>)> {
        config.validate()?;
        let mut timestamper = Timestamper::new(config.latency());
        if let Some(map) = config.clock_map {
            timestamper = timestamper.with_map(Arc::new(map));
        }
        let (events_tx, events) = mpsc::channel(config.channel_capacity);
        let (requests_tx, requests) = mpsc::channel(16);
        let (stats_tx, stats) = watch::channel(PortStats::default());
        let task = Task {
            port,
            name: config.port.clone(),
            decoder: ImuDecoder::new(config.protocol, timestamper),
            latency: config.latency(),
            events: events_tx,
            requests,
            stats: stats_tx,
            command_timeout: Duration::from_millis(config.command_timeout_ms),
            command_tries: config.command_tries,
        };
        let task = tokio::spawn(task.run());
        let handle = ImuHandle {
            protocol: config.protocol,
            port: config.port.clone(),
            verify_window: Duration::from_millis(config.verify_window_ms),
            requests: requests_tx,
            stats,
            task: Some(task),
        };
        Ok((handle, events))
    }
}

/// Commands to a running port. Dropping it stops the task.
pub struct ImuHandle {
    protocol: Protocol,
    port: String,
    verify_window: Duration,
    requests: mpsc::Sender<Request>,
    stats: watch::Receiver<PortStats>,
    task: Option<JoinHandle<Result<()>>>,
}

impl Drop for ImuHandle {
    fn drop(&mut self) {
        if let Some(t) = self.task.take() {
            t.abort();
        }
    }
}

/// WitMotion devices miss writes that come too fast (PyPI `witmotion` waits 100 ms too).
const WIT_WRITE_GAP: Duration = Duration::from_millis(100);
/// Frames at the old rate still in flight after a rate change.
const WIT_SETTLE: Duration = Duration::from_millis(300);
/// Tolerance of the observed rate after a WitMotion rate change.
const WIT_RATE_TOLERANCE: f64 = 0.15;

impl ImuHandle {
    pub fn protocol(&self) -> Protocol {
        self.protocol
    }

    pub fn port(&self) -> &str {
        &self.port
    }

    /// The latest counters (at most 50 ms old).
    pub fn stats(&self) -> PortStats {
        *self.stats.borrow()
    }

    /// Stops the task and returns its counters; an error if the task had failed.
    pub async fn stop(mut self) -> Result<PortStats> {
        let stats = self.stats();
        if let Some(t) = self.task.take() {
            if t.is_finished() {
                t.await.map_err(|e| ImuError::io("port task", std::io::Error::other(e.to_string())))??;
            } else {
                t.abort();
            }
        }
        Ok(stats)
    }

    async fn request<T>(&self, make: impl FnOnce(oneshot::Sender<Result<T>>) -> Request) -> Result<T> {
        let (tx, rx) = oneshot::channel();
        self.requests.send(make(tx)).await.map_err(|_| ImuError::Closed)?;
        rx.await.map_err(|_| ImuError::Closed)?
    }

    /// Sends a MIP command and waits for its reply (retrying on timeout); a NACK is an error.
    pub async fn mip_command(&self, command: MipCommand) -> Result<MipReply> {
        self.request(|reply| Request::Mip { command, reply }).await?.into_result()
    }

    /// Writes raw bytes to the device.
    pub async fn write(&self, bytes: Vec<u8>) -> Result<()> {
        self.request(|reply| Request::Write { bytes, reply }).await
    }

    /// Changes the local port's baud rate (not the device's).
    pub async fn set_local_baud(&self, baud: u32) -> Result<()> {
        self.request(|reply| Request::SetBaud { baud, reply }).await
    }

    pub async fn mip_ping(&self) -> Result<()> {
        self.mip_command(MipCommand::Ping).await.map(|_| ())
    }

    pub async fn mip_idle(&self) -> Result<()> {
        self.mip_command(MipCommand::SetIdle).await.map(|_| ())
    }

    pub async fn mip_resume(&self) -> Result<()> {
        self.mip_command(MipCommand::Resume).await.map(|_| ())
    }

    /// The IMU base rate in Hz.
    pub async fn mip_base_rate(&self) -> Result<u16> {
        match self.mip_command(MipCommand::GetImuBaseRate).await?.data {
            Some(ReplyData::ImuBaseRate(r)) if r > 0 => Ok(r),
            other => Err(ImuError::BadValue {
                field: "MIP IMU base rate reply",
                value: match other {
                    Some(ReplyData::ImuBaseRate(r)) => u64::from(r),
                    _ => 0,
                },
            }),
        }
    }

    /// The current IMU message format (0x80 fields and their decimations).
    pub async fn mip_format(&self) -> Result<Vec<FormatEntry>> {
        match self.mip_command(MipCommand::ImuMessageFormat(Function::Read)).await?.data {
            Some(ReplyData::ImuMessageFormat(entries)) => Ok(entries),
            _ => Err(ImuError::BadValue { field: "MIP message format reply", value: 0 }),
        }
    }

    /// Streams the current fields (accel + gyro when none or unreadable) at `rate_hz`, rounded to
    /// base rate / decimation; returns the rate set.
    pub async fn set_mip_rate(&self, rate_hz: f64) -> Result<f64> {
        let base = self.mip_base_rate().await?;
        let decimation = mip_decimation(base, rate_hz)?;
        let mut descriptors: Vec<u8> =
            self.mip_format().await.unwrap_or_default().iter().map(|e| e.descriptor).collect();
        if descriptors.is_empty() {
            descriptors = vec![FIELD_ACCEL, FIELD_GYRO];
        }
        let entries = descriptors.into_iter().map(|descriptor| FormatEntry { descriptor, decimation }).collect();
        self.mip_command(MipCommand::ImuMessageFormat(Function::Apply(entries))).await?;
        Ok(f64::from(base) / f64::from(decimation))
    }

    /// Moves the device and then the port to `baud` (the ACK comes at the old rate).
    pub async fn set_mip_baud(&self, baud: u32) -> Result<()> {
        self.mip_command(MipCommand::UartBaudRate(Function::Apply(baud))).await?;
        self.set_local_baud(baud).await
    }

    /// Sets the WitMotion output rate and verifies it by the rate observed over the verify
    /// window (the device sends no ACK); returns the observed rate. Writes are repeated up to
    /// `tries` times.
    pub async fn set_witmotion_rate(&self, rate_hz: f64, tries: u32) -> Result<f64> {
        let write = ConfigWrite::rate(rate_hz)?;
        let mut observed_hz = 0.0;
        for _ in 0..tries.max(1) {
            for bytes in write.unlocked() {
                self.write(bytes.to_vec()).await?;
                tokio::time::sleep(WIT_WRITE_GAP).await;
            }
            tokio::time::sleep(WIT_SETTLE).await;
            observed_hz = self.observed_rate_hz(self.verify_window).await;
            if (observed_hz - rate_hz).abs() <= WIT_RATE_TOLERANCE * rate_hz {
                return Ok(observed_hz);
            }
        }
        Err(ImuError::NotVerified { expected_hz: rate_hz, observed_hz })
    }

    /// Moves a WitMotion device to `baud`, then the port, and waits for good frames at the new
    /// rate (the device sends no ACK).
    pub async fn set_witmotion_baud(&self, baud: u32, timeout: Duration) -> Result<()> {
        let write = ConfigWrite::baud(baud)?;
        for bytes in write.unlocked() {
            self.write(bytes.to_vec()).await?;
            tokio::time::sleep(WIT_WRITE_GAP).await;
        }
        self.set_local_baud(baud).await?;
        let before = self.stats().decoder.frames;
        let deadline = Instant::now() + timeout;
        while Instant::now() < deadline {
            tokio::time::sleep(Duration::from_millis(50)).await;
            if self.stats().decoder.frames >= before + 10 {
                return Ok(());
            }
        }
        Err(ImuError::Timeout { what: format!("WitMotion frames at {baud} baud on {}", self.port), tries: 1 })
    }

    /// Saves the WitMotion configuration to flash.
    pub async fn save_witmotion(&self) -> Result<()> {
        for bytes in ConfigWrite::save().unlocked() {
            self.write(bytes.to_vec()).await?;
            tokio::time::sleep(WIT_WRITE_GAP).await;
        }
        Ok(())
    }

    /// Samples per second decoded over `window`.
    pub async fn observed_rate_hz(&self, window: Duration) -> f64 {
        let (t0, n0) = (Instant::now(), self.stats().decoder.samples);
        tokio::time::sleep(window).await;
        let (t1, n1) = (Instant::now(), self.stats().decoder.samples);
        let dt = (t1 - t0).as_secs_f64();
        if dt > 0.0 {
            n1.saturating_sub(n0) as f64 / dt
        } else {
            0.0
        }
    }

    /// Applies `config.switch_baud` and `config.rate_hz`; returns the output rate set, if any.
    pub async fn configure(&self, config: &ImuConfig) -> Result<Option<f64>> {
        match (self.protocol, config.switch_baud) {
            (_, None) => {}
            (Protocol::Mip, Some(b)) => self.set_mip_baud(b).await?,
            (Protocol::WitMotion, Some(b)) => self.set_witmotion_baud(b, Duration::from_secs(2)).await?,
        }
        let Some(rate) = config.rate_hz else { return Ok(None) };
        Ok(Some(match self.protocol {
            Protocol::Mip => {
                self.mip_ping().await?;
                self.set_mip_rate(rate).await?
            }
            Protocol::WitMotion => self.set_witmotion_rate(rate, config.command_tries).await?,
        }))
    }
}

/// The decimation of `base_hz` nearest to `rate_hz`; refuses rates above the base rate.
pub fn mip_decimation(base_hz: u16, rate_hz: f64) -> Result<u16> {
    if !rate_hz.is_finite() || rate_hz <= 0.0 || rate_hz > f64::from(base_hz) {
        return Err(ImuError::config("rate_hz", format!("{rate_hz} Hz is not in (0, base rate {base_hz} Hz]")));
    }
    Ok((f64::from(base_hz) / rate_hz).round().clamp(1.0, f64::from(u16::MAX)) as u16)
}
