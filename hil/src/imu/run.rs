//! The tokio transport of a mock serial IMU: a pty around [`ImuDevice`].
//!
//! ```no_run
//! # async fn demo() -> starc_hil::Result<()> {
//! use starc_hil::imu::{MockImu, MockImuConfig};
//! use starc_imu::Protocol;
//! let mut config = MockImuConfig::new(Protocol::Mip);
//! config.port = Some("/tmp/starc-imu".into());
//! let mock = MockImu::spawn_still(config)?;
//! println!("open {} (-> {})", mock.port().display(), mock.tty().display());
//! // ... a host reads the port ...
//! let stats = mock.stop().await?;
//! println!("{} samples sent", stats.device.sent);
//! # Ok(()) }
//! ```
//!
//! The task wakes every `tick_us` (1 ms), sends every sample due (stamped from the device clock,
//! not the wake-up), and answers what the host writes. Bytes the host does not read wait in a
//! 64 KiB queue; beyond that they are dropped and counted, as a USB-serial adapter would.

use crate::error::{HilError, Result};
use crate::imu::device::{DeviceConfig, DeviceStats, ImuDevice};
use crate::imu::faults::ImuFaultConfig;
use crate::imu::pty::Pty;
use crate::imu::sensor::SensorModel;
use crate::imu::source::{ImuSource, Motion, Still};
use serde::{Deserialize, Serialize};
use starc_imu::mip::data::{FIELD_ACCEL, FIELD_EULER, FIELD_GPS_TIME, FIELD_GYRO, FIELD_MAG, FIELD_QUATERNION};
use starc_imu::witmotion::frame as witframe;
use starc_imu::Protocol;
use std::collections::VecDeque;
use std::path::{Path, PathBuf};
use std::time::Duration;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::sync::{oneshot, watch};
use tokio::task::JoinHandle;
use tokio::time::{Instant, MissedTickBehavior};

/// Bytes queued for a host that does not read, at most.
const MAX_QUEUED: usize = 64 * 1024;

/// What a device sends (MIP 0x80 fields, WitMotion frame types).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Output {
    Accel,
    Gyro,
    Mag,
    Quaternion,
    Euler,
    /// MIP: GPS time (0x12); WitMotion: the time frame (0x50).
    Time,
}

impl Output {
    fn mip(self) -> u8 {
        match self {
            Output::Accel => FIELD_ACCEL,
            Output::Gyro => FIELD_GYRO,
            Output::Mag => FIELD_MAG,
            Output::Quaternion => FIELD_QUATERNION,
            Output::Euler => FIELD_EULER,
            Output::Time => FIELD_GPS_TIME,
        }
    }

    fn wit(self) -> u8 {
        match self {
            Output::Accel => witframe::TYPE_ACCEL,
            Output::Gyro => witframe::TYPE_GYRO,
            Output::Mag => witframe::TYPE_MAG,
            Output::Quaternion => witframe::TYPE_QUATERNION,
            Output::Euler => witframe::TYPE_ANGLE,
            Output::Time => witframe::TYPE_TIME,
        }
    }
}

/// A mock serial IMU; TOML-ready (unknown keys refused, missing ones default).
///
/// ```toml
/// protocol = "mip"
/// port = "/tmp/starc-imu"
/// rate_hz = 200.0
/// outputs = ["accel", "gyro", "time"]
/// [faults]
/// garbage = 0.01
/// ```
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MockImuConfig {
    pub protocol: Protocol,
    /// A symlink to create at this path, pointing at the pty slave.
    pub port: Option<PathBuf>,
    /// Output rate at power-on.
    pub rate_hz: f64,
    /// Baud rate at power-on: paces the output (the pty itself has no speed).
    pub baud: u32,
    /// MIP IMU base rate.
    pub mip_base_rate_hz: u16,
    /// What streams [default MIP: accel, gyro, time; WitMotion: accel, gyro, euler (angle)].
    pub outputs: Option<Vec<Output>>,
    pub seed: u64,
    /// Unix ns at power-on (GPS time, WitMotion clock); the host clock when absent.
    pub epoch_ns: Option<u64>,
    /// Wake-up period in microseconds (100..=20000).
    pub tick_us: u64,
    pub sensor: SensorModel,
    pub faults: ImuFaultConfig,
}

impl Default for MockImuConfig {
    fn default() -> Self {
        Self::new(Protocol::Mip)
    }
}

impl MockImuConfig {
    pub fn new(protocol: Protocol) -> Self {
        Self {
            protocol,
            port: None,
            rate_hz: 100.0,
            baud: 115_200,
            mip_base_rate_hz: 1000,
            outputs: None,
            seed: 0,
            epoch_ns: None,
            tick_us: 1000,
            sensor: SensorModel::default(),
            faults: ImuFaultConfig::default(),
        }
    }

    pub fn validate(&self) -> Result<()> {
        self.faults.validate()?;
        if !(100..=20_000).contains(&self.tick_us) {
            return Err(HilError::config("tick_us", format!("{} is outside 100..=20000", self.tick_us)));
        }
        if self.baud == 0 {
            return Err(HilError::config("baud", "0"));
        }
        if self.mip_base_rate_hz == 0 {
            return Err(HilError::config("mip_base_rate_hz", "0"));
        }
        match self.protocol {
            Protocol::Mip if !(self.rate_hz > 0.0 && self.rate_hz <= f64::from(self.mip_base_rate_hz)) => {
                Err(HilError::config("rate_hz", format!("{} is not in (0, {}]", self.rate_hz, self.mip_base_rate_hz)))
            }
            Protocol::WitMotion if starc_imu::witmotion::config::rate_code(self.rate_hz).is_err() => {
                Err(HilError::config(
                    "rate_hz",
                    format!("{} Hz is not a WitMotion rate (0.2 0.5 1 2 5 10 20 50 100 125 200)", self.rate_hz),
                ))
            }
            _ => Ok(()),
        }
    }

    /// The sans-IO device's configuration; `epoch_ns` is used when the config has none.
    pub fn device_config(&self, epoch_ns: u64) -> DeviceConfig {
        let mut d = DeviceConfig::new(self.protocol);
        d.rate_hz = self.rate_hz;
        d.baud = self.baud;
        d.mip_base_rate_hz = self.mip_base_rate_hz;
        if let Some(outputs) = &self.outputs {
            d.mip_fields = outputs.iter().map(|o| o.mip()).collect();
            d.wit_frames = outputs.iter().map(|o| o.wit()).collect();
        }
        d.epoch_ns = self.epoch_ns.unwrap_or(epoch_ns);
        d.sensor = self.sensor;
        d.faults = self.faults.clone();
        d.seed = self.seed;
        d
    }

    /// The still device this protocol's hardware would be lying flat: MicroStrain z down,
    /// WitMotion z up.
    pub fn still_source(&self) -> Still {
        Still(Motion::still(self.protocol == Protocol::WitMotion))
    }
}

/// Counters of a running mock.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct MockImuStats {
    pub device: DeviceStats,
    /// Bytes written to the pty.
    pub bytes_written: u64,
    /// Bytes dropped because the host did not read them.
    pub bytes_dropped: u64,
    /// Bytes the host wrote.
    pub host_bytes: u64,
}

/// A running mock IMU. Dropping it ends the task and removes its link.
pub struct MockImu {
    tty: PathBuf,
    port: PathBuf,
    stats: watch::Receiver<MockImuStats>,
    stop: Option<oneshot::Sender<()>>,
    task: Option<JoinHandle<Result<()>>>,
}

impl MockImu {
    /// A mock at rest (see [`MockImuConfig::still_source`]).
    pub fn spawn_still(config: MockImuConfig) -> Result<Self> {
        let source = config.still_source();
        Self::spawn(config, Box::new(source))
    }

    /// Opens the pty (and link) and starts the mock; must be called inside a tokio runtime.
    pub fn spawn(config: MockImuConfig, source: Box<dyn ImuSource>) -> Result<Self> {
        config.validate()?;
        let (pty, master) = Pty::open(config.port.as_deref())?;
        let (tty, port) = (pty.tty().to_path_buf(), pty.port().to_path_buf());
        let epoch_ns = starc_time::Stamp::host_now().ns;
        let device = ImuDevice::new(config.device_config(epoch_ns), source);
        let (stats_tx, stats) = watch::channel(MockImuStats::default());
        let (stop_tx, stop_rx) = oneshot::channel();
        let tick = Duration::from_micros(config.tick_us);
        let task = tokio::spawn(run(pty, master, device, tick, stats_tx, stop_rx));
        Ok(Self { tty, port, stats, stop: Some(stop_tx), task: Some(task) })
    }

    /// The pty slave (`/dev/pts/N`).
    pub fn tty(&self) -> &Path {
        &self.tty
    }

    /// Where a host opens the port (the link if configured).
    pub fn port(&self) -> &Path {
        &self.port
    }

    pub fn stats(&self) -> MockImuStats {
        *self.stats.borrow()
    }

    /// Stops the mock and returns its final counters.
    pub async fn stop(mut self) -> Result<MockImuStats> {
        if let Some(s) = self.stop.take() {
            let _ = s.send(());
        }
        if let Some(t) = self.task.take() {
            t.await.map_err(|e| HilError::Task(e.to_string()))??;
        }
        Ok(*self.stats.borrow())
    }
}

impl Drop for MockImu {
    fn drop(&mut self) {
        if let Some(t) = self.task.take() {
            t.abort();
        }
    }
}

async fn run(
    pty: Pty,
    master: tokio_serial::SerialStream,
    mut device: ImuDevice<Box<dyn ImuSource>>,
    tick: Duration,
    stats_tx: watch::Sender<MockImuStats>,
    mut stop: oneshot::Receiver<()>,
) -> Result<()> {
    let name = pty.tty().display().to_string();
    let io_err = |what: &str, e: std::io::Error| HilError::Io { context: format!("{what} {name}"), source: e };
    // Through AsyncRead/AsyncWrite: tokio-serial's try_read/try_write never clear readiness.
    let (mut reader, mut writer) = tokio::io::split(master);
    let start = Instant::now();
    let mut ticker = tokio::time::interval(tick);
    ticker.set_missed_tick_behavior(MissedTickBehavior::Delay);
    let mut queue: VecDeque<u8> = VecDeque::with_capacity(MAX_QUEUED);
    // The bytes of the write in progress (the queue changes while it waits).
    let mut inflight: Vec<u8> = Vec::with_capacity(4096);
    let mut out = Vec::with_capacity(4096);
    let mut buf = vec![0u8; 4096];
    let mut stats = MockImuStats::default();
    let mut last_publish = Instant::now();
    // A full pty (no host reading) takes 0 bytes yet polls writable: wait for the next tick.
    let mut full = false;
    loop {
        if inflight.is_empty() {
            let n = queue.len().min(4096);
            inflight.extend(queue.drain(..n));
        }
        let want_write = !inflight.is_empty() && !full;
        tokio::select! {
            _ = ticker.tick() => {
                full = false;
                let now_ns = start.elapsed().as_nanos() as u64;
                device.poll(now_ns, &mut out);
            }
            r = reader.read(&mut buf) => match r {
                Ok(0) => return Err(io_err("reading", std::io::ErrorKind::UnexpectedEof.into())),
                Ok(n) => {
                    stats.host_bytes += n as u64;
                    let now_ns = start.elapsed().as_nanos() as u64;
                    device.receive(buf.get(..n).unwrap_or_default(), now_ns, &mut out);
                }
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) => return Err(io_err("reading", e)),
            },
            r = writer.write(&inflight), if want_write => match r {
                Ok(0) => full = true,
                Ok(n) => {
                    inflight.drain(..n.min(inflight.len()));
                    stats.bytes_written += n as u64;
                }
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) => return Err(io_err("writing", e)),
            },
            _ = &mut stop => break,
        }
        let room = MAX_QUEUED.saturating_sub(queue.len() + inflight.len());
        let take = out.len().min(room);
        queue.extend(out.drain(..take));
        stats.bytes_dropped += out.len() as u64;
        out.clear();
        if last_publish.elapsed() >= Duration::from_millis(20) {
            stats.device = device.stats();
            stats_tx.send_replace(stats);
            last_publish = Instant::now();
        }
    }
    stats.device = device.stats();
    stats_tx.send_replace(stats);
    drop(pty);
    Ok(())
}
