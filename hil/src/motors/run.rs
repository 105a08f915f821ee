//! The tokio transport of the mock motors: a pty whose slave is linked at `port`, the device
//! ticking every millisecond.
//!
//! ```no_run
//! # async fn demo() -> starc_hil::Result<()> {
//! use starc_hil::motors::{MockMotors, MockMotorsConfig, MockProtocol};
//! let config = MockMotorsConfig { protocol: MockProtocol::Cia402, port: "/tmp/can-mock".into(), ..Default::default() };
//! let mock = MockMotors::spawn(config).await?;
//! // ... open /tmp/can-mock as an slcan adapter ...
//! let stats = mock.stop().await?;
//! # Ok(()) }
//! ```

use crate::error::{HilError, Result};
use crate::motors::device::{DeviceSettings, MockProtocol, MotorsDevice, MotorsStats};
use crate::motors::faults::MotorFaultConfig;
use crate::motors::pty::PtyDevice;
use serde::{Deserialize, Serialize};
use std::path::PathBuf;
use std::time::Duration;
use tokio::sync::{oneshot, watch};
use tokio::task::JoinHandle;
use tokio::time::{Instant, MissedTickBehavior};

/// Everything a mock motor bus needs; TOML-ready.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MockMotorsConfig {
    pub protocol: MockProtocol,
    /// Where the pty's slave is linked (the "serial port" clients open).
    pub port: PathBuf,
    /// ESC ids (C620, 1-8) or node ids (CiA 402).
    pub ids: Vec<u8>,
    /// C620 feedback rate per ESC (the real one is 1 kHz).
    pub feedback_hz: f64,
    /// Motor time constant.
    pub tau_s: f64,
    pub seed: u64,
    pub faults: MotorFaultConfig,
}

impl Default for MockMotorsConfig {
    fn default() -> Self {
        Self {
            protocol: MockProtocol::C620,
            port: PathBuf::from("/tmp/starc-can"),
            ids: vec![1, 2, 3],
            feedback_hz: 1000.0,
            tau_s: 0.05,
            seed: 0,
            faults: MotorFaultConfig::default(),
        }
    }
}

impl MockMotorsConfig {
    pub fn validate(&self) -> Result<()> {
        self.faults.validate()?;
        if self.ids.is_empty() {
            return Err(HilError::config("ids", "at least one motor"));
        }
        let ok = match self.protocol {
            MockProtocol::C620 => self.ids.iter().all(|id| (1..=8).contains(id)),
            MockProtocol::Cia402 => self.ids.iter().all(|id| (1..=127).contains(id)),
        };
        if !ok {
            return Err(HilError::config("ids", format!("{:?} out of range for {:?}", self.ids, self.protocol)));
        }
        if !(self.feedback_hz.is_finite() && self.feedback_hz > 0.0 && self.feedback_hz <= 1000.0) {
            return Err(HilError::config("feedback_hz", "must be in (0, 1000]"));
        }
        if !(self.tau_s.is_finite() && self.tau_s > 0.0) {
            return Err(HilError::config("tau_s", "must be > 0"));
        }
        Ok(())
    }
}

/// A running mock.
pub struct MockMotors {
    stop: Option<oneshot::Sender<()>>,
    live: watch::Receiver<MotorsStats>,
    task: JoinHandle<Result<MotorsStats>>,
    port: PathBuf,
}

impl MockMotors {
    /// Creates the pty and link, then runs until [`MockMotors::stop`].
    pub async fn spawn(config: MockMotorsConfig) -> Result<Self> {
        config.validate()?;
        let pty = PtyDevice::open(&config.port)?;
        tracing::info!(
            "mock {:?} motors {:?}: {} -> {}",
            config.protocol,
            config.ids,
            config.port.display(),
            pty.slave_path().display()
        );
        let settings = DeviceSettings {
            protocol: config.protocol,
            ids: config.ids.clone(),
            feedback_hz: config.feedback_hz,
            tau_s: config.tau_s,
            seed: config.seed,
            faults: config.faults.clone(),
        };
        let (stop_tx, stop_rx) = oneshot::channel();
        let device = MotorsDevice::new(&settings);
        let (live_tx, live) = watch::channel(device.stats());
        let task = tokio::spawn(run(pty, device, stop_rx, live_tx));
        Ok(Self { stop: Some(stop_tx), live, task, port: config.port })
    }

    pub fn port(&self) -> &std::path::Path {
        &self.port
    }

    /// The counters as of the last 10 ms, while the mock runs (drive states, host heartbeats).
    pub fn stats_now(&self) -> MotorsStats {
        self.live.borrow().clone()
    }

    /// Stops the mock, removes the link, returns the counters.
    pub async fn stop(mut self) -> Result<MotorsStats> {
        if let Some(s) = self.stop.take() {
            let _ = s.send(());
        }
        (&mut self.task).await.map_err(|e| HilError::Task(e.to_string()))?
    }
}

impl Drop for MockMotors {
    fn drop(&mut self) {
        self.task.abort();
    }
}

/// Bytes a client that reads slowly has not taken yet, at most this many: beyond it whole lines
/// are dropped (a full USB buffer), never a part of one.
const MAX_PENDING_BYTES: usize = 16 * 1024;

/// What is waiting to go to the client, and whether the last byte that went ended a line.
#[derive(Default)]
struct Pending {
    bytes: Vec<u8>,
    mid_line: bool,
}

impl Pending {
    fn is_empty(&self) -> bool {
        self.bytes.is_empty()
    }
}

/// Sends what fits of `pending` and then `out` (moved into it); what does not fit waits for
/// the next call. A slcan client parses lines: a line cut short and followed by the next one
/// reads as garbage (python-can raises on it), so only whole lines are ever dropped: the
/// line already started is finished first. Returns the bytes dropped.
fn send_lines(pty: &PtyDevice, pending: &mut Pending, out: &mut Vec<u8>) -> usize {
    pending.bytes.append(out);
    let left = pty.write_now(&pending.bytes);
    let written = pending.bytes.len() - left;
    if written > 0 {
        pending.mid_line = !matches!(pending.bytes.get(written - 1), Some(b'\r' | 0x07));
    }
    pending.bytes.drain(..written);
    if pending.bytes.len() <= MAX_PENDING_BYTES {
        return 0;
    }
    // Keep the rest of a started line, drop every whole line after it.
    let keep = if pending.mid_line {
        pending.bytes.iter().position(|b| matches!(b, b'\r' | 0x07)).map_or(pending.bytes.len(), |i| i + 1)
    } else {
        0
    };
    let dropped = pending.bytes.len() - keep;
    pending.bytes.truncate(keep);
    dropped
}

async fn run(
    pty: PtyDevice,
    mut device: MotorsDevice,
    mut stop: oneshot::Receiver<()>,
    live: watch::Sender<MotorsStats>,
) -> Result<MotorsStats> {
    let start = Instant::now();
    let now_ns = || u64::try_from(start.elapsed().as_nanos()).unwrap_or(u64::MAX);
    let mut tick = tokio::time::interval(Duration::from_millis(1));
    tick.set_missed_tick_behavior(MissedTickBehavior::Skip);
    let mut buf = vec![0u8; 4096];
    let mut out = Vec::with_capacity(4096);
    let mut overflow = 0u64;
    let mut pending = Pending::default();
    let mut ticks = 0u64;
    loop {
        tokio::select! {
            biased;
            _ = &mut stop => break,
            read = pty.read(&mut buf) => {
                let n = read?;
                device.on_host_bytes(buf.get(..n).unwrap_or(&[]), now_ns(), &mut out);
            }
            _ = tick.tick() => {
                device.poll(now_ns(), &mut out);
                ticks += 1;
                if ticks.is_multiple_of(10) {
                    live.send_replace(device.stats());
                }
            }
        }
        if !out.is_empty() || !pending.is_empty() {
            overflow += send_lines(&pty, &mut pending, &mut out) as u64;
        }
    }
    let mut stats = device.stats();
    stats.overflow_bytes = overflow;
    Ok(stats)
}
