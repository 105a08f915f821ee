//! The tokio loop around [`Base`]: a control tick (polled first, so nothing starves it),
//! operator requests, the bus, and adapter status polls. Every send has a time-out that latches a
//! fault; the halt frames go out when the loop stops, and, from a drop guard, when it is torn
//! down by a panic or an abort. Received frames are re-stamped on a monotonic clock anchored to the host
//! realtime clock at start, so watchdog and time-outs never see NTP steps.

use crate::config::CanConfig;
use crate::controller::{Base, BaseEvent, BaseStatus};
use crate::error::{BaseError, Result};
use crate::kinematics::Twist;
use crate::safety::{ClearRefused, Fault};
use starc_can::slcan::SlcanSerial;
use starc_can::socketcan::SocketCanBus;
use starc_can::{AnyBus, BusEvent, BusStats, CanBus, CanFrame};
use starc_time::Stamp;
use std::future::Future;
use std::task::{Context, Poll, Waker};
use std::time::Duration;
use tokio::sync::{mpsc, oneshot, watch};
use tokio::task::JoinHandle;
use tokio::time::{Instant, MissedTickBehavior};

/// Host time that only moves forward: the realtime clock at start plus a monotonic elapsed time.
#[derive(Clone, Copy, Debug)]
pub struct MonotonicHost {
    anchor: Stamp,
    start: Instant,
}

impl MonotonicHost {
    pub fn new() -> Self {
        Self { anchor: Stamp::host_now(), start: Instant::now() }
    }

    pub fn now(&self) -> Stamp {
        let ns = i64::try_from(self.start.elapsed().as_nanos()).unwrap_or(i64::MAX);
        self.anchor.offset_by(ns)
    }
}

impl Default for MonotonicHost {
    fn default() -> Self {
        Self::new()
    }
}

enum Request {
    Command(Twist),
    Estop(bool),
    Clear(oneshot::Sender<std::result::Result<Vec<Fault>, ClearRefused>>),
}

/// What a run ends with.
#[derive(Clone, Copy, Debug, Default, serde::Serialize)]
pub struct RunSummary {
    pub bus: BusStats,
    pub ticks: u64,
    pub events_dropped: u64,
    /// Batches cut short by the send time-out (each latched [`Fault::SendTimeout`]).
    pub send_timeouts: u64,
}

/// Talks to a running base.
pub struct BaseHandle {
    requests: mpsc::Sender<Request>,
    status: watch::Receiver<BaseStatus>,
    stop: Option<oneshot::Sender<()>>,
    task: JoinHandle<Result<RunSummary>>,
}

/// Options of the loop.
#[derive(Clone, Copy, Debug)]
pub struct RunnerOptions {
    /// Poll the adapter's status this often (slcan `F`); `None` = never.
    pub status_poll: Option<Duration>,
}

/// Opens the transport a config names, with the runner options that suit it.
pub async fn open_bus(config: &CanConfig) -> Result<(AnyBus, RunnerOptions)> {
    Ok(match config {
        CanConfig::Socketcan { interface } => {
            (AnyBus::SocketCan(SocketCanBus::open(interface)?), RunnerOptions { status_poll: None })
        }
        CanConfig::Slcan { port, slcan, status_poll_ms } => {
            let poll = (*status_poll_ms > 0).then(|| Duration::from_millis(*status_poll_ms));
            (AnyBus::Slcan(SlcanSerial::open_serial(port, slcan).await?), RunnerOptions { status_poll: poll })
        }
    })
}

/// Starts the loop; events arrive on the returned receiver (dropped, and counted, when it is full).
pub fn spawn<B: CanBus + 'static>(
    bus: B,
    base: Base,
    options: RunnerOptions,
) -> (BaseHandle, mpsc::Receiver<BaseEvent>) {
    let (req_tx, req_rx) = mpsc::channel(64);
    let (status_tx, status_rx) = watch::channel(base.status());
    let (event_tx, event_rx) = mpsc::channel(256);
    let (stop_tx, stop_rx) = oneshot::channel();
    let task = tokio::spawn(run(bus, base, options, req_rx, status_tx, event_tx, stop_rx));
    (BaseHandle { requests: req_tx, status: status_rx, stop: Some(stop_tx), task }, event_rx)
}

impl BaseHandle {
    /// A velocity command; send one at least every watchdog period.
    pub async fn command(&self, twist: Twist) -> Result<()> {
        self.requests.send(Request::Command(twist)).await.map_err(|_| BaseError::Stopped)
    }

    pub async fn set_estop(&self, pressed: bool) -> Result<()> {
        self.requests.send(Request::Estop(pressed)).await.map_err(|_| BaseError::Stopped)
    }

    /// Operator clear; the inner error says why it was refused.
    pub async fn clear(&self) -> Result<std::result::Result<Vec<Fault>, ClearRefused>> {
        let (tx, rx) = oneshot::channel();
        self.requests.send(Request::Clear(tx)).await.map_err(|_| BaseError::Stopped)?;
        rx.await.map_err(|_| BaseError::Stopped)
    }

    pub fn status(&self) -> BaseStatus {
        self.status.borrow().clone()
    }

    pub fn watch_status(&self) -> watch::Receiver<BaseStatus> {
        self.status.clone()
    }

    /// Whether the loop has ended (bus closed or failed).
    pub fn is_finished(&self) -> bool {
        self.task.is_finished()
    }

    /// Halts the motors, stops the loop and returns its counters.
    pub async fn stop(mut self) -> Result<RunSummary> {
        if let Some(stop) = self.stop.take() {
            let _ = stop.send(());
        }
        self.task.await.map_err(|e| BaseError::Io { context: "base task".into(), source: std::io::Error::other(e) })?
    }
}

/// How a batch of frames went out.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Sent {
    All,
    /// The transport did not take a frame within the send time-out; the rest were dropped.
    TimedOut,
}

/// Sends `frames` in order, each within `timeout`. A transport that blocks (an adapter that
/// stopped reading, a full queue) must not hold the loop: the watchdog, the status and the
/// operator's stop all run on it. A send cut short may leave half an slcan line behind, which
/// the adapter refuses (and reports) like any other garbage.
async fn send_all<B: CanBus>(bus: &mut B, frames: &mut Vec<CanFrame>, timeout: Duration) -> Result<Sent> {
    for f in frames.drain(..) {
        match tokio::time::timeout(timeout, bus.send(&f)).await {
            Ok(sent) => sent?,
            Err(_elapsed) => return Ok(Sent::TimedOut),
        }
    }
    Ok(Sent::All)
}

/// Tries to send `frame` without waiting: polls the send once. For a drop guard, which cannot
/// await; a transport with room in its queue (the usual case) takes the frame at once.
fn send_now<B: CanBus>(bus: &mut B, frame: &CanFrame) -> bool {
    let mut cx = Context::from_waker(Waker::noop());
    let mut send = std::pin::pin!(bus.send(frame));
    matches!(send.as_mut().poll(&mut cx), Poll::Ready(Ok(())))
}

/// The bus and the controller, owned for as long as the loop runs. When the loop does not end
/// in order (a panic unwinds through it, the task is aborted, the runtime shuts down under
/// it), dropping the guard still sends the halt frames, best effort: an ending process must
/// not leave the motors on their last command.
struct HaltGuard<B: CanBus> {
    bus: B,
    base: Base,
    /// The halt frames went out in order; nothing left to do on drop.
    halted: bool,
}

impl<B: CanBus> Drop for HaltGuard<B> {
    fn drop(&mut self) {
        if self.halted {
            return;
        }
        let frames = self.base.halt_frames();
        let sent = frames.iter().filter(|f| send_now(&mut self.bus, f)).count();
        tracing::warn!("the base loop ended without an orderly halt: {sent} of {} halt frames sent", frames.len());
    }
}

async fn run<B: CanBus>(
    bus: B,
    base: Base,
    options: RunnerOptions,
    mut requests: mpsc::Receiver<Request>,
    status: watch::Sender<BaseStatus>,
    events: mpsc::Sender<BaseEvent>,
    mut stop: oneshot::Receiver<()>,
) -> Result<RunSummary> {
    let clock = MonotonicHost::new();
    let period = Duration::from_millis(base.config().control_period_ms);
    let send_timeout_ms = base.config().send_timeout_ms;
    let send_timeout = Duration::from_millis(send_timeout_ms);
    let mut g = HaltGuard { bus, base, halted: false };
    let mut tick = tokio::time::interval(period);
    tick.set_missed_tick_behavior(MissedTickBehavior::Skip);
    let poll_every = options.status_poll.unwrap_or(Duration::from_secs(3600));
    let mut poll = tokio::time::interval_at(Instant::now() + poll_every, poll_every);
    let mut summary = RunSummary::default();
    let mut frames = Vec::new();
    let outcome: Result<()> = loop {
        tokio::select! {
            biased;
            _ = &mut stop => break Ok(()),
            // The tick before the bus: a flood of received frames must never starve the
            // command watchdog, the host heartbeat or the time-outs.
            _ = tick.tick() => {
                g.base.tick(clock.now(), &mut frames);
                summary.ticks += 1;
                match send_all(&mut g.bus, &mut frames, send_timeout).await {
                    Ok(Sent::All) => {}
                    Ok(Sent::TimedOut) => {
                        summary.send_timeouts += 1;
                        g.base.send_timed_out(send_timeout_ms, clock.now());
                    }
                    Err(e) => break Err(e),
                }
                status.send_replace(g.base.status());
            }
            // Then the operator's requests (at most a channel's worth: they cannot flood), so
            // that a busy bus cannot delay a stop, an e-stop or a clear.
            request = requests.recv() => match request {
                Some(Request::Command(t)) => g.base.command(t, clock.now()),
                Some(Request::Estop(p)) => g.base.set_estop(p, clock.now()),
                Some(Request::Clear(reply)) => {
                    let _ = reply.send(g.base.clear_faults(clock.now()));
                }
                None => break Ok(()),
            },
            received = g.bus.recv() => match received {
                Ok(BusEvent::Frame(mut rx)) => {
                    rx.host = clock.now();
                    g.base.handle(&BusEvent::Frame(rx));
                }
                Ok(BusEvent::Fault { fault, .. }) => g.base.handle(&BusEvent::Fault { fault, host: clock.now() }),
                Err(e) => break Err(e.into()),
            },
            _ = poll.tick(), if options.status_poll.is_some() => {
                if let Err(e) = g.bus.request_status().await {
                    break Err(e.into());
                }
            }
        }
        for e in g.base.drain_events() {
            if events.try_send(e).is_err() {
                summary.events_dropped += 1;
            }
        }
    };
    let mut halt = g.base.halt_frames();
    let halted = send_all(&mut g.bus, &mut halt, send_timeout).await;
    // Only an orderly halt disarms the guard; otherwise it tries once more, without waiting.
    g.halted = matches!(halted, Ok(Sent::All));
    status.send_replace(g.base.status());
    summary.bus = g.bus.stats();
    outcome?;
    if halted? == Sent::TimedOut {
        return Err(BaseError::Io {
            context: "halting the motors".into(),
            source: std::io::Error::new(std::io::ErrorKind::TimedOut, "the CAN transport did not take the halt frames"),
        });
    }
    Ok(summary)
}

#[cfg(test)]
mod tests;
